"""Which way the map lets a picture face: never into a surface just in front of it, and never away
from the target's own face, which stereo maps a little nearer than it is. Real rendered stereo pairs
of a generated room go through the real matcher and occupancy map."""

from __future__ import annotations

import itertools
import math
from dataclasses import replace

import numpy as np
import pytest

from offboard.perception.occupancy import OccupancyGrid
from offboard.perception.stereo import StereoMatcher
from offboard.perception.voxel_grid import VoxelGrid
from offboard.planning.belief import TargetBelief
from offboard.search.loop import SearchConfig, fold_in_map
from onboard.sim.render import StereoRenderer
from onboard.sim.world import load_world
from shared.geometry import HeadMount, Intrinsics, Pose2D

K = Intrinsics.from_fov(640, 480, 66.0)
MOUNT = HeadMount()


@pytest.fixture(scope="module")
def mapped_target():
    """A dev room's map after three looks straight at the target's picture, from 1.2 m to 3 m."""
    world = load_world("dev/room-1000-1")
    target, config = world.target, SearchConfig()
    renderer, matcher = StereoRenderer(world, K, MOUNT), StereoMatcher(config.stereo)
    occupancy = OccupancyGrid(VoxelGrid(world.room.size_m, config.resolution_m), config.occupancy)
    centre, facing = target.center_m(), target.facing()
    for distance in (1.2, 2.0, 3.0):
        x, y = centre[:2] + distance * facing[:2]
        pose = Pose2D(x, y, math.radians(target.yaw_deg) + math.pi)
        tilt = -math.atan2(MOUNT.height_m - centre[2], distance)
        frame = renderer.render(pose, 0.0, tilt)
        occupancy.integrate_disparity(matcher.disparity(frame.left, frame.right), K, MOUNT.baseline_m,
                                      MOUNT.camera_in_world(pose, 0.0, tilt))
    return world, occupancy


def _shares(world, occupancy, config: SearchConfig, points_m: np.ndarray) -> np.ndarray:
    """Each facing's mass at each of ``points_m`` (..., 3) after the map is folded into a uniform
    belief, over that point's most: (..., facings)."""
    belief = TargetBelief(occupancy.grid, config.facing_sectors)
    fold_in_map(belief, occupancy, replace(config, empty_factor=1.0), world.target.size_m[0])
    mass = belief.mass_by_facing()[tuple(np.moveaxis(occupancy.grid.index_of(points_m), -1, 0))]
    return mass / mass.max(axis=-1, keepdims=True)


def _own_sector(world, config: SearchConfig) -> int:
    """The facing sector the target's picture points into."""
    return round(world.target.yaw_deg % 360 / (360 / config.facing_sectors)) % config.facing_sectors


def test_the_picture_keeps_its_own_facing_and_a_facing_into_it_is_blocked(mapped_target):
    world, occupancy = mapped_target
    config, target = SearchConfig(), world.target
    own = _own_sector(world, config)
    back = (own + config.facing_sectors // 2) % config.facing_sectors
    assert _shares(world, occupancy, config, target.center_m())[own] == 1.0
    in_front = target.center_m() + 0.45 * target.facing()  # the picture 0.34 m ahead when facing back
    assert _shares(world, occupancy, config, in_front)[back] == pytest.approx(config.blocked_facing_factor)


def test_without_the_gap_stereo_s_own_face_would_block_the_picture_s_facing(mapped_target):
    world, occupancy = mapped_target
    config = replace(SearchConfig(), blocked_facing_gap_m=0.0)
    assert _shares(world, occupancy, config, world.target.center_m())[_own_sector(world, config)] < 1.0


def test_no_cube_round_the_picture_s_centre_loses_its_own_facing(mapped_target):
    """The target's centre may lie anywhere in its cube, so the 26 cubes round it must keep the
    picture's facing too; with a gap of 0.1 m stereo's own face blocked it in six of them here."""
    world, occupancy = mapped_target

    def own_shares(config: SearchConfig) -> np.ndarray:
        steps = np.array(list(itertools.product((-1, 0, 1), repeat=3)))
        around = world.target.center_m() + steps * config.resolution_m
        return _shares(world, occupancy, config, around)[:, _own_sector(world, config)]

    assert min(own_shares(SearchConfig())) == 1.0
    assert min(own_shares(replace(SearchConfig(), blocked_facing_gap_m=0.1))) < 1.0

"""The occupancy grid (eq. 5-8) on frames whose answer is known."""

import math

import numpy as np
import pytest

from offboard.perception.occupancy import FREE, OCCUPIED, UNKNOWN, OccupancyConfig, OccupancyGrid
from offboard.perception.voxel_grid import VoxelGrid
from shared.geometry import HeadMount, Intrinsics, Pose2D

K = Intrinsics.from_fov(640, 480, 66.0)
MOUNT = HeadMount(1.2, 0.0, 0.12)
ROOM = VoxelGrid((6.0, 4.0, 2.5), 0.05)


def _wall_disparity(depth_m: float) -> np.ndarray:
    """A fronto-parallel wall ``depth_m`` ahead fills the image."""
    return np.full((K.height_px, K.width_px), K.fx_px * MOUNT.baseline_m / depth_m, np.float32)


def _facing_east(x=1.0, y=2.0):
    return MOUNT.camera_in_world(Pose2D(x, y, 0.0), 0.0, 0.0)


def test_a_wall_is_occupied_the_space_before_it_free_and_behind_it_unknown():
    occ = OccupancyGrid(ROOM)
    cam = _facing_east()
    occ.integrate_disparity(_wall_disparity(3.0), K, MOUNT.baseline_m, cam)
    wall_x = cam.translation[0] + 3.0  # 4.0 m
    j, k = int(2.0 / 0.05), int(1.2 / 0.05)
    state = occ.state()
    column = state[:, j, k]
    i_wall = int(wall_x / 0.05)
    assert OCCUPIED in column[i_wall - 2:i_wall + 2]
    assert (column[int(1.3 / 0.05):i_wall - 4] == FREE).all()
    assert (column[i_wall + 4:] == UNKNOWN).all()
    assert state[:, :, :].max() == OCCUPIED


def test_eq7_a_far_point_weighs_less_per_cube_than_a_near_one():
    near, far = OccupancyGrid(ROOM), OccupancyGrid(ROOM)
    for occ, depth in ((near, 1.0), (far, 4.0)):
        one_point = np.full((K.height_px, K.width_px), np.nan, np.float32)
        one_point[242, 322] = K.fx_px * MOUNT.baseline_m / depth
        occ.integrate_disparity(one_point, K, MOUNT.baseline_m, _facing_east())
    assert near.log_odds.max() > far.log_odds.max() > 0
    assert (far.log_odds > 0).sum() > (near.log_odds > 0).sum()  # |C| grows with distance
    assert far.log_odds[far.log_odds > 0].sum() == pytest.approx(1.0, rel=0.3)  # 1/|C| over C


def test_each_cube_is_updated_once_per_frame():
    occ = OccupancyGrid(ROOM, OccupancyConfig(point_stride_px=1))
    occ.integrate_disparity(_wall_disparity(2.0), K, MOUNT.baseline_m, _facing_east())
    assert occ.log_odds.min() >= -0.4 - 1e-6  # one miss at most, though many rays cross each cube
    assert occ.log_odds.max() <= 1.0 + 1e-6


def test_a_ghost_fades_when_later_frames_see_through_it():
    occ = OccupancyGrid(ROOM)
    cam = _facing_east()
    ghost = np.full((K.height_px, K.width_px), np.nan, np.float32)
    ghost[200:280, 280:360] = K.fx_px * MOUNT.baseline_m / 1.5  # one noisy frame: something 1.5 m ahead
    occ.integrate_disparity(ghost, K, MOUNT.baseline_m, cam)
    probe = np.array([[cam.translation[0] + 1.5, 2.0, 1.2]])
    assert occ.state()[tuple(ROOM.index_of(probe)[0])] == OCCUPIED
    for _ in range(4):
        occ.integrate_disparity(_wall_disparity(3.0), K, MOUNT.baseline_m, cam)
    assert occ.state()[tuple(ROOM.index_of(probe)[0])] == FREE


def test_ray_casting_stops_at_the_first_occupied_cube_and_passes_unknown_space():
    occ = OccupancyGrid(ROOM)
    cam = _facing_east()
    occ.integrate_disparity(_wall_disparity(3.0), K, MOUNT.baseline_m, cam)
    rays = occ.cast_rays(cam.translation, np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 0, 1.0]]), 10.0)
    assert rays.distance_m[0] == pytest.approx(3.0, abs=0.1) and rays.hit[0]
    # never observed behind or above: the rays cross that space to the room's west wall and ceiling
    assert rays.distance_m[1] == pytest.approx(1.0, abs=0.05) and rays.hit[1]
    assert rays.distance_m[2] == pytest.approx(ROOM.size_m[2] - cam.translation[2], abs=0.05) and rays.hit[2]
    short = occ.cast_rays(cam.translation, np.array([[1.0, 0, 0]]), 1.0)
    assert not short.hit[0] and short.distance_m[0] == pytest.approx(1.0)


def test_rays_from_many_origins_each_follow_their_own_direction_or_are_refused():
    occ = OccupancyGrid(ROOM)
    occ.integrate_disparity(_wall_disparity(3.0), K, MOUNT.baseline_m, _facing_east())  # a wall at x = 4 m
    origins = np.array([[1.0, 2.0, 1.2], [2.0, 2.0, 1.2], [3.0, 2.0, 1.2]])
    rays = occ.cast_rays(origins, np.array([1.0, 0.0, 0.0]), 10.0)  # one direction for all three
    assert rays.distance_m == pytest.approx([3.0, 2.0, 1.0], abs=0.1) and rays.hit.all()
    with pytest.raises(ValueError, match="one origin or one per direction"):  # the kernel read past the end
        occ.cast_rays(origins, np.array([[1.0, 0, 0], [0, 1.0, 0]]), 10.0)
    with pytest.raises(ValueError, match="zero vector"):  # it walked NaN to max range, unsaid
        occ.cast_rays(origins[0], np.zeros(3), 10.0)


@pytest.mark.parametrize("baseline_m", [0.0, -0.12])
def test_a_frame_without_a_positive_baseline_is_refused(baseline_m):
    """At 0 every point fell on the camera's own cube; negative, stereo carved free space behind it."""
    with pytest.raises(ValueError, match="positive baseline"):
        OccupancyGrid(ROOM).integrate_disparity(_wall_disparity(3.0), K, baseline_m, _facing_east())


@pytest.mark.parametrize("changes", [{"clamp_max": 0.3}, {"free_log_odds": -0.1, "occupied_log_odds": -0.2},
                                     {"clamp_min": -0.2}])
def test_thresholds_the_clamps_make_unreachable_are_refused(changes):
    """A clamp under the occupied threshold left a wall seen twenty times unoccupied."""
    with pytest.raises(ValueError, match="clamp_min <= free_log_odds < occupied_log_odds <= clamp_max"):
        OccupancyConfig(**changes)


def test_a_robot_of_no_radius_blocks_what_is_occupied_and_the_walls_add_nothing():
    occ = OccupancyGrid(ROOM)
    occ.integrate_disparity(_wall_disparity(2.0), K, MOUNT.baseline_m, _facing_east())
    fm = occ.floor_map(robot_radius_m=0.0, robot_height_m=1.35)
    assert fm.blocked.shape == fm.occupied.shape and np.array_equal(fm.blocked, fm.occupied)


def test_floor_map_blocks_obstacles_in_the_robot_band_inflated_by_its_radius():
    occ = OccupancyGrid(ROOM)
    occ.integrate_disparity(_wall_disparity(2.0), K, MOUNT.baseline_m, _facing_east())
    fm = occ.floor_map(robot_radius_m=0.26, robot_height_m=1.35)
    i_wall, j = int(3.0 / 0.05), int(2.0 / 0.05)
    assert fm.occupied[i_wall - 1:i_wall + 2, j].any()
    assert fm.blocked[i_wall - 5, j] and not fm.blocked[i_wall - 8, j]  # 0.26 m = 5.2 cells
    assert fm.blocked[0, j] and fm.blocked[:, 0].all()  # near the room's walls
    assert not fm.unknown[int(2.0 / 0.05), j] and fm.unknown[-1, j]


def test_tilted_views_place_points_in_the_right_world_cubes():
    occ = OccupancyGrid(ROOM)
    cam = MOUNT.camera_in_world(Pose2D(1.0, 2.0, 0.0), 0.0, math.radians(-30))
    # the floor: a ray through pixel (u, v) hits z = 0 at depth z_cam; give each pixel that disparity
    rays = cam.rotation @ K.pixel_rays().reshape(-1, 3).T
    t = -cam.translation[2] / rays[2]
    disparity = np.where(t > 0, K.fx_px * MOUNT.baseline_m / np.where(t > 0, t, 1), np.nan).reshape(480, 640)
    occ.integrate_disparity(disparity.astype(np.float32), K, MOUNT.baseline_m, cam)
    occupied_z = ROOM.centers()[occ.occupied()][:, 2]
    assert occupied_z.size > 0 and np.percentile(occupied_z, 95) < 0.15


def test_a_coarsened_map_keeps_obstacles_and_what_was_observed():
    occ = OccupancyGrid(ROOM)
    occ.integrate_disparity(_wall_disparity(2.0), K, MOUNT.baseline_m, _facing_east())
    coarse = occ.coarsened(4)
    assert coarse.grid.resolution_m == pytest.approx(0.2) and coarse.grid.shape == (30, 20, 13)
    occupied_fine = ROOM.centers()[occ.occupied()]
    assert coarse.occupied()[tuple(coarse.grid.index_of(occupied_fine).T)].all()
    assert coarse.observed.sum() < occ.observed.sum() and (coarse.state() == FREE).any()
    rays = coarse.cast_rays(_facing_east().translation, np.array([[1.0, 0, 0]]), 10.0)
    assert rays.distance_m[0] == pytest.approx(2.0, abs=0.25)


def _pooled(occ: OccupancyGrid, factor: int) -> tuple[np.ndarray, np.ndarray]:
    """coarsened() from its definition, in numpy: per block, the largest observed log-odds (0 where
    no cube is observed) and whether any cube is observed."""
    pad = [(0, -n % factor) for n in occ.grid.shape]
    values = np.pad(np.where(occ.observed, occ.log_odds, -np.inf), pad, constant_values=-np.inf)
    blocks = [n // factor for n in values.shape]
    shape = (blocks[0], factor, blocks[1], factor, blocks[2], factor)
    observed = np.pad(occ.observed, pad).reshape(shape).any(axis=(1, 3, 5))
    return np.where(observed, values.reshape(shape).max(axis=(1, 3, 5)), 0).astype(np.float32), observed


def test_a_coarsened_map_follows_frames_and_direct_writes_between_calls():
    rng = np.random.default_rng(7)
    occ = OccupancyGrid(ROOM)
    rows, cols = np.mgrid[0:K.height_px, 0:K.width_px]
    for step in range(12):
        if step % 4 == 3:  # written directly, as the navigator marks a contact: in the last frame's view
            ahead = cam.translation + cam.rotation[:, 2]
            region = ROOM.box_slices(ahead - 0.2, ahead + 0.2)
            with occ.edit() as (log_odds, observed):
                if step % 8 == 3:
                    log_odds[region] = rng.uniform(-2.0, 3.5)
                else:
                    observed[region] = ~observed[region]
        else:  # a frame of a wavy surface 1-4 m ahead, from anywhere in the room
            pose = Pose2D(*rng.uniform((0.5, 0.5, -math.pi), (5.5, 3.5, math.pi)))
            cam = MOUNT.camera_in_world(pose, rng.uniform(-0.6, 0.6), rng.uniform(-0.5, 0.2))
            waves = np.sin(cols / rng.uniform(20, 150)) * np.cos(rows / rng.uniform(20, 150))
            depth = rng.uniform(1.0, 4.0) + 0.5 * waves
            occ.integrate_disparity((K.fx_px * MOUNT.baseline_m / depth).astype(np.float32), K, MOUNT.baseline_m, cam)
        for factor in (2, 3):
            coarse = occ.coarsened(factor)
            log_odds, observed = _pooled(occ, factor)
            assert np.array_equal(coarse.log_odds, log_odds) and np.array_equal(coarse.observed, observed)
    with pytest.raises(ValueError, match="read-only"):  # written through edit() only: coarsened() must know
        occ.log_odds[0, 0, 0] = 1.0


def test_seen_empty_keeps_a_margin_around_surfaces_unknown_space_and_the_room():
    occ = OccupancyGrid(ROOM)
    cam = _facing_east()
    occ.integrate_disparity(_wall_disparity(3.0), K, MOUNT.baseline_m, cam)
    occ.integrate_disparity(_wall_disparity(3.0), K, MOUNT.baseline_m, cam)  # twice: log-odds -0.8 before the wall
    j, k = int(2.0 / 0.05), int(1.2 / 0.05)
    i_wall = int(np.argmax(occ.occupied()[:, j, k]))
    plain = occ.seen_empty(-0.8)
    kept = occ.seen_empty(-0.8, margin_cubes=3)
    assert plain[i_wall - 3, j, k] and not kept[i_wall - 3, j, k]  # next to the wall: kept
    assert kept[i_wall - 10, j, k]  # open air in front of it: empty
    assert not kept[:, :, :3].any() and not kept[:3].any()  # the floor, the room's boundary
    assert not (kept & ~plain).any()  # a margin only ever keeps more
    with occ.edit() as (_, observed):
        observed[i_wall - 10, j + 2, k] = False  # unknown space two cubes beside it: kept
    assert not occ.seen_empty(-0.8, margin_cubes=3)[i_wall - 10, j, k]

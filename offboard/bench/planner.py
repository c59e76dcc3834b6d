"""``syt-offboard bench planner --json``: what one decision and one Bayes update cost, as medians.

The room is the report's (9 × 5 × 2.5 m; its candidate positions × 17 settings are `actions`), and
once a hall of 20 × 14 × 3 m (6.7 million cubes at 5 cm), larger than any generated room. The
map holds what a few stereo frames of walls and furniture would put there, the belief a hints
prior, so that sensed spheres are not all empty. A decision includes the navigation distances to
the candidates, the sensed spheres at all of them, and scoring every action. It is repeated from one
pose, as the looks from one spot are, so the geometry of the looks here is computed once.

What is timed is what the search runs: its planning blocks (:func:`planning_block_factor`), the
SIFT table shipped for the bundled target, and an update that reads the frame's disparity.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from offboard.navigation import grid_planner
from offboard.navigation.navigator import NavigatorConfig
from offboard.planning.belief import TargetBelief
from offboard.perception.detection.detector import shipped_table
from offboard.planning.detection_function import look_footprint, visible_depth
from offboard.perception.occupancy import OccupancyGrid
from offboard.planning.planner import PlannerConfig, SearchPlanner
from offboard.planning.priors import HintBox, hints
from offboard.planning.time_model import TimeModel
from offboard.search.loop import SearchConfig, planning_block_factor
from offboard.perception.voxel_grid import VoxelGrid
from shared.timing import median_ms
from shared.geometry import HeadMount, Intrinsics, Pose2D
from shared.limits import BaseLimits, CameraTiming, PanTiltLimits

log = logging.getLogger(__name__)

ROOM_M = (9.0, 5.0, 2.5)
HALL_M = (20.0, 14.0, 3.0)
K = Intrinsics.from_fov(640, 480, 66.0)
MOUNT = HeadMount()
BASE = BaseLimits()
TABLES = (HintBox((1.0, 4.3, 0.75), (2.4, 5.0, 1.05), 0.45), HintBox((3.9, 2.27, 0.75), (5.1, 2.73, 1.05), 0.45))


def _wall(depth_m: float) -> np.ndarray:
    """The disparity of a wall ``depth_m`` ahead, filling the frame."""
    return np.full((K.height_px, K.width_px), K.fx_px * MOUNT.baseline_m / depth_m, np.float32)


def _scenario(resolution_m: float, room_m: tuple[float, float, float] = ROOM_M) -> tuple[SearchPlanner, OccupancyGrid]:
    grid = VoxelGrid(room_m, resolution_m)
    occupancy = OccupancyGrid(grid)
    for x, y, heading, depth in ((4.5, 0.6, 90, 1.7), (4.5, 0.6, 0, 4.0), (4.5, 0.6, 180, 4.0), (2.0, 2.5, 90, 2.0)):
        cam = MOUNT.camera_in_world(Pose2D(x, y, math.radians(heading)), 0.0, 0.0)
        occupancy.integrate_disparity(_wall(depth), K, MOUNT.baseline_m, cam)
    config = SearchConfig(room_m=room_m, resolution_m=resolution_m)
    belief = TargetBelief(grid, coarse_factor=planning_block_factor(config))
    belief.set_prior(hints(grid, TABLES), prob_outside=config.prob_outside)
    time_model = TimeModel(BASE, PanTiltLimits(), CameraTiming())
    planner = SearchPlanner(belief, config.planner, shipped_table("sift").for_sectors(belief.facing_sectors), time_model,
                            K, MOUNT)
    return planner, occupancy


def _decide(planner: SearchPlanner, occupancy: OccupancyGrid, pose: Pose2D):
    """One decision as the search makes it: candidates planned, paths to them, the choice. A search
    writes a frame before each decision; here the whole map counts as written, the worst case for
    :meth:`~OccupancyGrid.coarsened`."""
    with occupancy.edit():
        pass
    clearance = NavigatorConfig().clearance_m(BASE)
    floor = occupancy.floor_map(clearance, BASE.height_m)
    planner.plan_positions(pose, floor, clearance)
    paths = grid_planner.path_lengths(floor, (pose.x_m, pose.y_m), planner.positions)
    return planner.decide(pose, 0.0, 0.0, 0.0, occupancy, paths)


def _update(planner: SearchPlanner, occupancy: OccupancyGrid, pose: Pose2D) -> None:
    cam = MOUNT.camera_in_world(pose, 0.0, 0.0)
    depth = visible_depth(_wall(1.7), occupancy, cam, K, MOUNT.baseline_m, 16, planner.table.range_m[1])
    fp = look_footprint(occupancy.grid, cam, K, depth, 16, planner.table, planner.belief.facing_azimuths_rad, 0.15)
    planner.belief.update_after_miss(fp.cube_index, fp.detection_prob)


def run(repeats: int = 15) -> dict:
    pose = Pose2D(4.5, 0.6, math.pi / 2)
    figures: dict[str, float | int] = {}
    for resolution, room, key in ((0.05, ROOM_M, "decision_ms"), (0.10, ROOM_M, "decision_ms_10cm"),
                                  (0.025, ROOM_M, "decision_ms_2_5cm"), (0.05, HALL_M, "decision_ms_20x14m")):
        log.info("planner at %g cm in a %g × %g × %g m room", resolution * 100, *room)
        planner, occupancy = _scenario(resolution, room)
        figures[key] = median_ms(lambda: _decide(planner, occupancy, pose), repeats)
        if key == "decision_ms":
            figures["update_ms"] = median_ms(lambda: _update(planner, occupancy, pose), repeats)
            figures["actions"] = planner.action_count
            figures["cubes"] = occupancy.grid.num_cubes
    return figures

"""Numba's on-disk cache of the offboard kernels, filled before any search needs it.

Numba compiles a kernel lazily, at its first call, for the types of that call's arguments (dtype,
number of dimensions, layout, whether an array is read-only); with ``cache=True`` it keeps the
machine code under the module's ``__pycache__`` (or ``NUMBA_CACHE_DIR``), where every later process
loads it from. A fresh checkout has none, so each process that searches compiles all the kernels of
``offboard`` first (about half a minute), and the test suite's parallel search processes each pay
that again.

:func:`compile_kernels` calls every kernel once through the code a search runs, on a small scene in
the bundled paper lab with the default configuration: a look (stereo into the map, the look's
footprint, Bayes), a decision, a navigation step (TangentBug, the global path, a scan match), a
checkpoint written and read back, and the experimenter's any-angle path lengths (SPL's
yardstick). Its arguments are then of the types a search passes, so the specialisations it caches
are the ones a search loads. ``syt-offboard compile`` runs it, and ``make`` once after installing.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numba.core import event

from offboard.navigation import grid_planner
from offboard.navigation.localization import PoseTracker, ScanMatcher, map_field, scan_from_disparity
from offboard.navigation.navigator import NavigatorConfig
from offboard.navigation.tangent_bug import TangentBug
from offboard.perception.detectability import DetectabilityTable
from offboard.perception.detection.detector import shipped_table
from offboard.perception.occupancy import FloorMap, OccupancyGrid
from offboard.perception.voxel_grid import VoxelGrid
from offboard.planning.belief import TargetBelief
from offboard.planning.detection_function import look_footprint, visible_depth
from offboard.planning.planner import SearchPlanner
from offboard.planning.time_model import TimeModel
from offboard.search import checkpoint
from offboard.search.loop import SearchConfig, build_prior, fold_in_map, starting_maps
from shared.geometry import HeadMount, Intrinsics, Pose2D
from shared.limits import BaseLimits, CameraTiming, PanTiltLimits
from shared.world import load_world

log = logging.getLogger(__name__)

WORLD = "paper-lab"
K = Intrinsics.from_fov(640, 480, 66.0)  # the simulated Bumblebee's, as in the benchmarks
MOUNT = HeadMount()
BASE = BaseLimits()
BLOCK_PX = 16  # the search's blocks of visible depth (Search._interpret)
WALL_M = 2.0  # the synthetic frame: a wall this far ahead


class _Compiled(event.Listener):
    """The offboard kernels numba compiles while installed, one name a specialisation; a kernel
    loaded from the cache is not compiled, so it is not named."""

    def __init__(self) -> None:
        self.names: list[str] = []

    def on_start(self, ev: event.Event) -> None:
        function = ev.data["dispatcher"].py_func
        if function.__module__.startswith("offboard."):
            self.names.append(f"{function.__module__}.{function.__qualname__}")

    def on_end(self, ev: event.Event) -> None:
        pass


@dataclass(frozen=True)
class _Scene:
    """What a search holds at its start (:class:`~offboard.search.loop.Search`)."""

    config: SearchConfig
    table: DetectabilityTable
    occupancy: OccupancyGrid
    belief: TargetBelief
    planner: SearchPlanner
    pose: Pose2D
    target_depth_m: float


def compile_kernels() -> list[str]:
    """Call every numba kernel of ``offboard`` once, as a search does, so that each is compiled into
    numba's on-disk cache (or loaded from it). Returns the kernels compiled here, one name a
    specialisation: none once the cache holds them all."""
    compiled = _Compiled()
    with event.install_listener("numba:compile", compiled), tempfile.TemporaryDirectory() as folder:
        scene = _scene()
        _checkpoint(scene, Path(folder))  # before the look: fresh maps code both with and without a palette
        disparity = _wall(WALL_M)
        _look(scene, disparity)
        _decide(scene)
        _navigate(scene, disparity)
        _yardstick(scene)
    log.info("numba kernels: %d specialisations compiled, the others loaded from the cache", len(compiled.names))
    for name in sorted(set(compiled.names)):
        log.debug("compiled %s", name)
    return compiled.names


def _scene() -> _Scene:
    """The search's maps, belief and planner in the paper lab, with the default configuration and a
    uniform prior, the robot at the world's start."""
    world = load_world(WORLD)
    config = dataclasses.replace(SearchConfig(), room_m=world.room.size_m)
    table = shipped_table(config.detector).for_sectors(config.facing_sectors)
    prior = build_prior(VoxelGrid(config.room_m, config.resolution_m), ["uniform"])
    depth_m = world.target.size_m[0]  # along the picture's normal, as the search is given it
    occupancy, belief = starting_maps(config, prior, depth_m)
    planner = SearchPlanner(belief, config.planner, table, TimeModel(BASE, PanTiltLimits(), CameraTiming()), K, MOUNT)
    return _Scene(config, table, occupancy, belief, planner, world.start, depth_m)


def _wall(depth_m: float) -> np.ndarray:
    """A disparity image (float32, as the stereo matcher's) of a wall ``depth_m`` ahead."""
    return np.full((K.height_px, K.width_px), K.fx_px * MOUNT.baseline_m / depth_m, np.float32)


def _look(scene: _Scene, disparity: np.ndarray) -> None:
    """A look that misses: its frame into the map, what it could have seen, Bayes (eq. 4), then what
    the map says about the target (:func:`~offboard.search.loop.fold_in_map`)."""
    camera = MOUNT.camera_in_world(scene.pose, 0.0, 0.0)
    scene.occupancy.integrate_disparity(disparity, K, MOUNT.baseline_m, camera)
    depth = visible_depth(disparity, scene.occupancy, camera, K, MOUNT.baseline_m, BLOCK_PX, scene.table.range_m[1])
    footprint = look_footprint(scene.occupancy.grid, camera, K, depth, BLOCK_PX, scene.table,
                               scene.belief.facing_azimuths_rad, scene.config.planner.behind_surface_m)
    scene.belief.update_after_miss(footprint.cube_index, footprint.detection_prob)
    fold_in_map(scene.belief, scene.occupancy, scene.config, scene.target_depth_m)


def _decide(scene: _Scene) -> None:
    """A decision (``Search._choose_on``): the candidates, their path lengths on the navigator's
    floor map, every action scored on the coarsened map and belief."""
    floor = _floor(scene)
    here = (scene.pose.x_m, scene.pose.y_m)
    scene.planner.plan_positions(scene.pose, floor, NavigatorConfig().clearance_m(BASE))
    paths = grid_planner.path_lengths(floor, here, scene.planner.positions)
    scene.planner.decide(scene.pose, 0.0, 0.0, 0.0, scene.occupancy, paths)


def _navigate(scene: _Scene, disparity: np.ndarray) -> None:
    """A navigator's step to the room's centre: TangentBug's virtual scan guided by the path lengths
    to the goal, the global path and its line-of-sight shortcuts, then a scan match of the look
    toward the motion (its likelihood field read at the matched points)."""
    config = NavigatorConfig()
    floor = _floor(scene)
    here = (scene.pose.x_m, scene.pose.y_m)
    goal = (scene.config.room_m[0] / 2, scene.config.room_m[1] / 2)
    to_goal = grid_planner.distance_field(floor, goal)
    TangentBug(goal, config.bug).step(floor, here, lambda points: grid_planner.distances_at(floor, to_goal, points))
    grid_planner.shortest_path(floor, here, goal)
    scan = scan_from_disparity(disparity, K, MOUNT, 0.0, math.radians(config.look_tilt_deg), config.match)
    tracker = PoseTracker(scene.pose)
    ScanMatcher(config.match).match(scan, tracker.pose, map_field(scene.occupancy, config.match), tracker.covariance)


def _yardstick(scene: _Scene) -> None:
    """The experimenter's any-angle path lengths, SPL's shortest path and the oracle's viewpoint
    (:func:`~offboard.experiments.world_facts.viewpoint`): not the search's, but every sweep's."""
    grid_planner.any_angle_field(_floor(scene), (scene.pose.x_m, scene.pose.y_m))


def _floor(scene: _Scene) -> FloorMap:
    """The navigator's floor map (on its bare radius, as when it squeezes: the kernels see the same)."""
    return scene.occupancy.floor_map(BASE.radius_m, BASE.height_m)


def _checkpoint(scene: _Scene, folder: Path) -> None:
    """A checkpoint of the maps written and read back, as a search writes one after every action and
    ``--resume`` reads it. As a search starts them, the log-odds (all zero) are coded without a
    palette, after trying both sizes of it, and the belief's masses with one; read back, the stored
    arrays are read-only views of the file, which numba compiles for apart."""
    header, arrays = checkpoint.encode_maps(scene.belief.state(), scene.occupancy.log_odds, scene.occupancy.observed)
    header.update({key: None for key in checkpoint.HEADER_KEYS if key not in header})  # the plain parts reach no kernel
    checkpoint.write_file(folder / checkpoint.FILE_NAME, header, arrays)
    checkpoint.decode_maps(checkpoint.read(folder))

"""``syt-offboard bench navigation --json``: how well the navigator drives a simulated robot.

Real agent subprocesses (:func:`shared.launch.onboard_agent`), real Zenoh, the navigator with stereo,
scan matching and TangentBug, exactly as in a search. Four figures:

- ``path_length_ratio``: mean over fixed start/goal pairs of the distance driven over the shortest
  collision-free path on the *true* world geometry (boxes inflated by the robot's radius, computed
  on a 2 cm grid and line-of-sight shortened);
- ``success_rate``: the share of those (reachable) goals reached, the true pose within
  ``_SUCCESS_M`` of the goal;
- ``pose_error_m_odometry`` / ``pose_error_m_corrected``: after a ~30 m route with the simulator's
  default odometry noise, the distance from the true position (``sim_truth``, used for scoring only)
  to the robot's raw odometry and to the navigator's corrected pose.

The true geometry is read from the world file itself (TOML data, not the simulator's code), so the
planner side stays independent of ``onboard``.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

from offboard.navigation.grid_planner import Point, path_length_m, shortest_path
from offboard.navigation.navigator import NavigationResult, Navigator, retry_busy
from offboard.perception.occupancy import FloorMap, OccupancyGrid
from offboard.robot.robot_client import RobotClient, RobotUnavailable
from offboard.perception.voxel_grid import VoxelGrid
from shared.codec import ProtocolError
from shared.launch import onboard_agent
from shared.limits import BaseLimits
from shared.transport import TransportConfig
from shared.world import load_world

log = logging.getLogger(__name__)

_SUCCESS_M = 0.25  # the true position this close to the goal counts as arrived
_TRUTH_RES_M = 0.02  # grid of the true shortest paths

# (world, start x, y, heading°, goal x, y): every goal reachable with 0.5 m to spare, most behind an obstacle
PAIRS: tuple[tuple[str, float, float, float, float, float], ...] = (
    ("paper-lab", 1.5, 1.0, 0.0, 7.5, 3.0),
    ("paper-lab", 4.5, 1.5, 90.0, 4.5, 3.8),
    ("paper-lab", 1.2, 2.5, 0.0, 8.0, 2.2),
    ("paper-lab", 7.5, 1.6, 180.0, 1.8, 3.6),
    ("paper-lab", 2.0, 3.7, -90.0, 5.8, 1.2),
    ("office", 5.5, 1.0, 135.0, 1.0, 3.8),
    ("office", 6.0, 3.0, 90.0, 3.0, 4.5),
    ("office", 1.5, 4.5, 0.0, 4.3, 1.2),
    ("high-shelf", 1.5, 3.2, 0.0, 6.5, 5.2),
    ("high-shelf", 7.0, 2.0, 180.0, 1.0, 2.5),
    ("high-shelf", 3.2, 0.6, 90.0, 0.6, 3.0),
)
# a ~30 m tour of the paper lab from its start pose (4.5, 0.6, 90°)
ROUTE: tuple[Point, ...] = ((1.5, 1.0), (1.8, 3.6), (6.0, 3.8), (8.0, 1.4), (4.5, 1.5), (2.0, 2.5),
                            (7.5, 3.0), (4.5, 4.0), (1.5, 1.0))


def run(seed: int = 0) -> dict[str, float | None]:
    """Run every pair and the long route (odometry noise drawn with ``seed``); the four figures."""
    started = time.monotonic()
    ratios, successes = _pairs(seed)
    odometry_error, corrected_error = _route(seed)
    figures = {
        "path_length_ratio": round(float(np.mean(ratios)), 3) if ratios else None,  # None: nothing arrived
        "success_rate": round(float(np.mean(successes)), 3),
        "pose_error_m_odometry": round(odometry_error, 3),
        "pose_error_m_corrected": round(corrected_error, 3),
    }
    log.info("navigation bench done in %.0f s: %s", time.monotonic() - started, figures)
    return figures


# --- the figures -----------------------------------------------------------------------------------

def _pairs(seed: int) -> tuple[list[float], list[bool]]:
    ratios, successes = [], []
    for world_name in sorted({p[0] for p in PAIRS}):
        world = load_geometry(world_name)
        with _robot(world_name, seed) as robot:
            for _, sx, sy, heading, gx, gy in (p for p in PAIRS if p[0] == world_name):
                shortest = path_length_m(shortest_path(world, (sx, sy), (gx, gy)))
                retry_busy(robot.sim_teleport, sx, sy, heading)
                result = _navigate(robot, world_name, [(gx, gy)])[0]
                truth = robot.sim_truth()
                arrived = result.status == "reached" and math.dist((truth.x_m, truth.y_m), (gx, gy)) <= _SUCCESS_M
                ratios.append(result.distance_m / shortest if arrived else math.nan)
                successes.append(arrived)
                log.info("%s (%.1f, %.1f) -> (%.1f, %.1f): %s, driven %.2f m, shortest %.2f m", world_name, sx, sy,
                         gx, gy, result.status, result.distance_m, shortest)
    return [r for r in ratios if math.isfinite(r)], successes


def _route(seed: int) -> tuple[float, float]:
    with _robot("paper-lab", seed) as robot:
        results = _navigate(robot, "paper-lab", list(ROUTE))
        truth = robot.sim_truth()
    final = results[-1]
    driven = sum(r.distance_m for r in results)
    odometry = math.dist((final.odometry.x_m, final.odometry.y_m), (truth.x_m, truth.y_m))
    corrected = math.dist((final.pose.x_m, final.pose.y_m), (truth.x_m, truth.y_m))
    log.info("route of %.1f m (%s): final error %.3f m by odometry, %.3f m corrected", driven,
             ", ".join(r.status for r in results), odometry, corrected)
    return odometry, corrected


def _navigate(robot: RobotClient, world_name: str, goals: list[Point]) -> list[NavigationResult]:
    """A fresh map and navigator from where the robot stands (which it is told), a look round, then
    each goal in turn."""
    size = load_geometry_size(world_name)
    occupancy = OccupancyGrid(VoxelGrid(size, 0.05))
    navigator = Navigator(robot, occupancy)
    navigator.survey()
    return [navigator.go_to(goal) for goal in goals]


@contextmanager
def _robot(world_name: str, seed: int) -> Iterator[RobotClient]:
    args = ["--backend", "sim", "--world", world_name, "--robot", "bench-nav", "--seed", str(seed)]
    with onboard_agent(args) as agent:
        transport = TransportConfig(robot_id="bench-nav", connect=(agent.endpoint,), multicast_scouting=False)
        with transport.open() as session, RobotClient(session, transport.robot_id) as robot:
            agent.wait_ready(session, transport.robot_id)
            robot.wait_for_robot()
            _warm_up(robot)
            yield robot


def _warm_up(robot: RobotClient, attempts: int = 3) -> None:
    """A fresh agent compiles its renderer on the first capture, which on a busy machine can outlast
    the capture's timeout (surfacing as a ProtocolError on Zenoh's "Timeout" reply): retry it."""
    for attempt in range(1, attempts + 1):
        try:
            robot.capture()
            return
        except (ProtocolError, RobotUnavailable) as exc:
            if attempt == attempts:
                raise
            log.warning("warm-up capture %d failed (%s); retrying", attempt, exc)


# --- the true geometry -----------------------------------------------------------------------------

def load_geometry_size(world_name: str) -> tuple[float, float, float]:
    return load_world(world_name).room.size_m


def load_geometry(world_name: str, limits: BaseLimits = BaseLimits()) -> FloorMap:
    """The true configuration space on a fine grid: cells whose centre lies within the base's radius
    of a wall or of what it runs into, the target included (the simulator's collision test exactly)."""
    world = load_world(world_name)
    return _configuration_space(list(world.room.size_m[:2]),
                                [(b.min_m, b.max_m) for b in world.base_blockers(limits.height_m)], limits.radius_m)


def _configuration_space(room_xy: list[float], boxes: list[tuple[list[float], list[float]]], radius_m: float,
                         resolution_m: float = _TRUTH_RES_M) -> FloorMap:
    nx, ny = (int(math.ceil(s / resolution_m - 1e-9)) for s in room_xy)
    x, y = np.meshgrid((np.arange(nx) + 0.5) * resolution_m, (np.arange(ny) + 0.5) * resolution_m, indexing="ij")
    blocked = (x < radius_m) | (y < radius_m) | (x > room_xy[0] - radius_m) | (y > room_xy[1] - radius_m)
    occupied = np.zeros_like(blocked)
    for lo, hi in boxes:
        dx = np.maximum(np.maximum(lo[0] - x, x - hi[0]), 0.0)
        dy = np.maximum(np.maximum(lo[1] - y, y - hi[1]), 0.0)
        blocked |= dx * dx + dy * dy < radius_m * radius_m
        occupied |= (dx == 0.0) & (dy == 0.0)
    return FloorMap(resolution_m, occupied, blocked, np.zeros_like(blocked))

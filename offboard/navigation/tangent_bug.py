"""TangentBug (Kamon, Rivlin & Rimon 1998): goal-directed motion with a range sensor, on a floor map.

The robot is a point in the configuration space of the :class:`~offboard.perception.occupancy.FloorMap`
(``blocked``: obstacles inflated by the robot's radius, walls included). Its range sensor is a
*virtual* 360° scan: rays cast from the robot over the blocked cells of the map built so far,
up to ``sensor_range_m``. The algorithm alternates two behaviours:

- **motion-to-goal**: if the straight line to the goal (or to the sensor's range along it) is free,
  go straight. Otherwise move toward the endpoint O_i of the local tangent graph (the edges of the
  sensed obstacle boundaries: discontinuities of the range profile) minimising the heuristic
  ``d(x, O_i) + d(O_i, goal)``. When that heuristic stops decreasing (or, with discrete steps, the
  robot comes back to where it already was in this phase) the robot sits in a local minimum of the
  distance to the goal, and switches to
- **boundary following**: keep the blocking obstacle on one side at ``follow_clearance_m``, going
  the way the robot was already turning. Record ``d_followed``, the least distance to the goal of any
  point reached-in-sight so far; leave as soon as the goal itself is in sight or ``d_reach`` (the
  distance to the goal of the closest free point in line of sight) beats ``d_followed`` by
  ``progress_m``. Every leave point is closer than the previous one, which is what makes the
  algorithm globally convergent.

The straight-line ``d(O_i, goal)`` can be replaced by any cost-to-goal, e.g. a global planner's path
lengths (what :mod:`offboard.navigation.navigator` does).

A goal is declared unreachable when boundary following closes a loop (it retraces its own trail,
within ``loop_radius_m`` and going the same way: it has gone once round the obstacle) or exceeds
``max_follow_m``: the robot never circles forever. :class:`TangentBug` is pure: it proposes one
bounded straight move per call and never does I/O; the caller executes it and calls again.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numba
import numpy as np

from offboard.navigation.grid_planner import Point, cell_center, is_free, nearest_free_cell, segment_is_free
from offboard.perception.occupancy import FloorMap

log = logging.getLogger(__name__)

CostToGoal = Callable[[np.ndarray], np.ndarray]


@dataclass(frozen=True)
class BugConfig:
    sensor_range_m: float = 3.0  # what stereo maps reliably around the robot
    num_rays: int = 360  # 1° rays: 5 cm apart at 3 m, one floor cell
    step_m: float = 0.5  # longest straight move per call (the caller re-senses in between)
    follow_step_m: float = 0.3  # shorter along a boundary, so convex corners stay in sight
    min_step_m: float = 0.1  # never crawl: tiny steps near a tangent point waste commands
    goal_tolerance_m: float = 0.05
    follow_clearance_m: float = 0.15  # distance kept from the blocked region while following
    edge_clearance_m: float = 0.1  # pass tangent endpoints this far from the obstacle's edge
    discontinuity_m: float = 0.4  # a range jump this large separates two pieces of boundary
    hysteresis_m: float = 0.05  # the heuristic must rise this much to count as a local minimum
    progress_m: float = 0.05  # d_reach must beat d_followed by this to leave (no dithering)
    loop_radius_m: float = 0.3  # back this close to the trail followed, going the same way: a loop
    max_follow_m: float = 60.0  # a boundary longer than this is declared endless


@dataclass(frozen=True)
class Scan:
    """A virtual range scan: rays from ``origin`` to the first blocked cell (or the sensor's range)."""

    origin: Point
    angles: np.ndarray  # (n,) radians, world frame, evenly spaced from 0
    ranges: np.ndarray  # (n,) metres
    hit: np.ndarray  # (n,) bool: stopped by a blocked cell (or the room's edge), not by max range


@dataclass(frozen=True)
class BugStep:
    """One proposal: ``move`` to ``waypoint`` (straight, collision-free on the map), or stop."""

    status: Literal["move", "reached", "unreachable"]
    waypoint: Point | None
    mode: Literal["to_goal", "follow", "escape", "path", "done"]  # "path": a caller's global-path step
    reason: str = ""


def virtual_scan(floor_map: FloorMap, origin: Point, num_rays: int, max_range_m: float) -> Scan:
    """Cast ``num_rays`` rays over the blocked cells; the room's edge stops a ray like an obstacle."""
    angles = np.arange(num_rays) * (2.0 * math.pi / num_rays)
    res = floor_map.resolution_m
    ranges, hit = _cast(np.ascontiguousarray(floor_map.blocked), origin[0] / res, origin[1] / res,
                        angles, max_range_m / res)
    return Scan(origin, angles, ranges * res, hit)


class TangentBug:
    """The TangentBug state machine for one goal; call :meth:`step` after every executed move."""

    def __init__(self, goal: Point, config: BugConfig = BugConfig()):
        self.goal = goal
        self.config = config
        self.mode: Literal["to_goal", "follow"] = "to_goal"
        self._h_min = math.inf  # least heuristic since motion-to-goal began
        self._visited: list[Point] = []  # positions since motion-to-goal began (revisits = plateau)
        self._last_heading = 0.0  # direction of the last proposed move
        self._leave_bound = math.inf  # d_reach at the last leave: each leave must do better
        self._follow_side = 1  # +1: obstacle on the right (going counter-clockwise around it)
        self._followed_m = 0.0
        self._d_followed = math.inf
        self._trail: list[tuple[Point, float, float]] = []  # followed so far: (point, heading, metres)
        self._cost: CostToGoal = self._euclidean

    def retarget(self, goal: Point) -> None:
        """Aim at a new goal (a caller's moving sub-goal): progress records of the old one are void."""
        self.goal = goal
        self.mode, self._h_min, self._visited, self._leave_bound = "to_goal", math.inf, [], math.inf

    def step(self, floor_map: FloorMap, position: Point, cost_to_goal: CostToGoal | None = None) -> BugStep:
        """Propose the next move from ``position``. ``cost_to_goal`` (points (N, 2) -> metres) replaces
        the straight-line ``d(O_i, goal)`` of the heuristic, e.g. by a global planner's path lengths."""
        c = self.config
        self._cost = cost_to_goal if cost_to_goal is not None else self._euclidean
        if math.dist(position, self.goal) <= c.goal_tolerance_m:
            return BugStep("reached", None, "done", "at the goal")
        if not is_free(floor_map, position):
            return self._escape(floor_map, position)
        scan = virtual_scan(floor_map, position, c.num_rays, c.sensor_range_m)
        if self.mode == "follow":
            return self._follow(floor_map, scan)
        return self._to_goal(floor_map, scan)

    # --- motion-to-goal ----------------------------------------------------------------------------

    def _to_goal(self, floor_map: FloorMap, scan: Scan) -> BugStep:
        c, x = self.config, scan.origin
        d_goal = math.dist(x, self.goal)
        if self._goal_in_sight(floor_map, x):
            self._h_min = min(self._h_min, d_goal)
            return self._move(floor_map, x, _bearing(x, self.goal), min(c.step_m, d_goal), "to_goal")
        endpoints = tangent_endpoints(scan, c.discontinuity_m, c.edge_clearance_m)
        if not endpoints:
            return self._start_follow(floor_map, scan, "no tangent endpoint in sight")
        costs = np.hypot(*(np.array(endpoints) - x).T) + self._cost(np.array(endpoints))
        best = int(np.argmin(costs))
        if not math.isfinite(costs[best]):
            return self._start_follow(floor_map, scan, "no tangent endpoint leads to the goal")
        if costs[best] > self._h_min + c.hysteresis_m:
            return self._start_follow(floor_map, scan, f"local minimum (h {costs[best]:.2f} > {self._h_min:.2f})")
        self._h_min = min(self._h_min, costs[best])
        o = endpoints[best]
        step = self._move(floor_map, x, _bearing(x, o), min(c.step_m, max(math.dist(x, o), c.min_step_m)), "to_goal")
        if step.status == "move" and self._revisits(x, step.waypoint):
            return self._start_follow(floor_map, scan, "motion-to-goal is going round in circles")
        return step

    def _revisits(self, x: Point, waypoint: Point) -> bool:
        """Would this move return to a place of the current motion-to-goal phase? Discrete steps can
        cycle on a plateau of the heuristic (within its hysteresis): that is a local minimum too."""
        near = any(math.dist(waypoint, p) < 0.75 * self.config.min_step_m for p in self._visited)
        self._visited.append(x)
        return near

    def _goal_in_sight(self, floor_map: FloorMap, x: Point) -> bool:
        d = math.dist(x, self.goal)
        reach = min(d, self.config.sensor_range_m)
        end = (x[0] + (self.goal[0] - x[0]) * reach / d, x[1] + (self.goal[1] - x[1]) * reach / d)
        return segment_is_free(floor_map, x, end)

    def _euclidean(self, points: np.ndarray) -> np.ndarray:
        return np.hypot(points[:, 0] - self.goal[0], points[:, 1] - self.goal[1])

    # --- boundary following ------------------------------------------------------------------------

    def _start_follow(self, floor_map: FloorMap, scan: Scan, why: str) -> BugStep:
        if not scan.hit.any():
            return BugStep("unreachable", None, "done", f"{why}, and no obstacle to follow")
        nearest = _nearest_hit(scan)
        toward_obstacle = scan.angles[nearest]
        self._follow_side = 1 if math.sin(self._last_heading - toward_obstacle) >= 0 else -1
        self.mode = "follow"
        self._followed_m = 0.0
        self._trail = []
        self._d_followed = d_reach(scan, self.goal)
        log.debug("boundary following from (%.2f, %.2f), side %+d: %s", *scan.origin, self._follow_side, why)
        return self._follow(floor_map, scan)

    def _follow(self, floor_map: FloorMap, scan: Scan) -> BugStep:
        c, x = self.config, scan.origin
        goal_visible = math.dist(x, self.goal) <= c.sensor_range_m and segment_is_free(floor_map, x, self.goal)
        reach = 0.0 if goal_visible else d_reach(scan, self.goal)
        if goal_visible or reach < min(self._d_followed, self._leave_bound) - c.progress_m:
            self._leave_bound, self.mode, self._h_min, self._visited = reach, "to_goal", math.inf, []
            log.debug("leaving the boundary at (%.2f, %.2f): d_reach %.2f, d_followed %.2f", *x, reach,
                      self._d_followed)
            return self._to_goal(floor_map, scan)
        self._d_followed = min(self._d_followed, reach)
        if not scan.hit.any():  # the obstacle fell out of range: nothing to follow, head for the goal
            self.mode, self._h_min, self._visited = "to_goal", math.inf, []
            return self._to_goal(floor_map, scan)
        heading, distance = self._follow_heading(scan)
        if distance <= 0.0:
            return BugStep("unreachable", None, "done", "boundary following is boxed in")
        step = self._move(floor_map, x, heading, distance, "follow")
        return self._check_loop(x, step)

    def _follow_heading(self, scan: Scan) -> tuple[float, float]:
        """Tangent to the nearest boundary point, steered to keep the clearance, turned away from
        the obstacle until the way ahead is free (concave corners)."""
        c, s = self.config, self._follow_side
        nearest = _nearest_hit(scan)
        r_n = float(scan.ranges[nearest])
        steer = float(np.clip(math.atan2(r_n - c.follow_clearance_m, c.follow_step_m), -1.0, 1.0))
        heading = scan.angles[nearest] + s * (math.pi / 2.0) - s * steer
        n = scan.angles.shape[0]
        k0 = int(round(heading / (2.0 * math.pi / n))) % n
        for turn in range(n // 2):  # turn away from the obstacle, one ray at a time
            k = (k0 + s * turn) % n
            free = float(scan.ranges[k]) - c.edge_clearance_m
            if free >= c.min_step_m or (not scan.hit[k] and free > 0.0):
                return float(scan.angles[k]), min(c.follow_step_m, free)
        return 0.0, 0.0

    def _check_loop(self, x: Point, step: BugStep) -> BugStep:
        """Boundary following is deterministic: once it retraces its own trail, going the same way,
        it goes round for ever, and the goal is unreachable. (Passing the trail the other way, as on
        the far side of a narrow corridor, is no loop.)"""
        c = self.config
        if step.status != "move":
            return step
        heading = _bearing(x, step.waypoint)
        for point, past_heading, at_m in self._trail:
            if (at_m < self._followed_m - 4.0 * c.loop_radius_m and math.cos(heading - past_heading) > 0.5
                    and _segment_point_distance(x, step.waypoint, point) < c.loop_radius_m):
                return BugStep("unreachable", None, "done", "boundary following closed a loop around the obstacle")
        self._trail.append((x, heading, self._followed_m))
        self._followed_m += math.dist(x, step.waypoint)
        if self._followed_m > c.max_follow_m:
            return BugStep("unreachable", None, "done", f"followed a boundary for over {c.max_follow_m:g} m")
        return step

    # --- moves -------------------------------------------------------------------------------------

    def _move(self, floor_map: FloorMap, x: Point, heading: float, distance: float, mode: str) -> BugStep:
        """A straight move, shortened until it is free on the map (never through blocked cells)."""
        for _ in range(8):
            end = (x[0] + distance * math.cos(heading), x[1] + distance * math.sin(heading))
            if segment_is_free(floor_map, x, end):
                self._last_heading = heading
                return BugStep("move", end, mode)  # type: ignore[arg-type]
            distance *= 0.5
        return BugStep("unreachable", None, "done", "no free move in the chosen direction")

    def _escape(self, floor_map: FloorMap, position: Point) -> BugStep:
        """The robot stands in blocked space (map noise, a fresh obstacle): back to the nearest free cell."""
        cell = nearest_free_cell(floor_map, position)
        if cell is None:
            return BugStep("unreachable", None, "done", "no free cell in the map")
        return BugStep("move", cell_center(floor_map, cell), "escape", "leaving blocked space")


# --- scan geometry ---------------------------------------------------------------------------------

def tangent_endpoints(scan: Scan, jump_m: float, clearance_m: float) -> list[Point]:
    """Nodes O_i of the local tangent graph: at each discontinuity of the range profile, a point at the
    near ray's range just past the obstacle's edge, turned ``clearance_m`` into the free side."""
    n = scan.ranges.shape[0]
    dtheta = 2.0 * math.pi / n
    r, hit = scan.ranges, scan.hit
    nxt = np.roll(np.arange(n), -1)
    jumps = np.nonzero((hit != hit[nxt]) | (np.abs(r - r[nxt]) > jump_m))[0]
    out = []
    for i in jumps:
        near, side = (i, 1) if r[i] < r[nxt[i]] else (nxt[i], -1)
        r_near = max(float(r[near]), 1e-3)
        turn = max(1, math.ceil(math.atan2(clearance_m, r_near) / dtheta))
        rays = (near + side * np.arange(1, turn + 1)) % n
        if np.all(r[rays] >= r_near):  # the free side is wide enough to pass the edge
            angle = scan.angles[rays[-1]]
            out.append((scan.origin[0] + r_near * math.cos(angle), scan.origin[1] + r_near * math.sin(angle)))
    return out


def d_reach(scan: Scan, goal: Point) -> float:
    """Distance to the goal of the closest free point in line of sight (on some ray, before its end)."""
    u = np.stack([np.cos(scan.angles), np.sin(scan.angles)], axis=1)
    g = np.array(goal) - np.array(scan.origin)
    t = np.clip(u @ g, 0.0, scan.ranges)
    return float(np.min(np.hypot(g[0] - t * u[:, 0], g[1] - t * u[:, 1])))


def _nearest_hit(scan: Scan) -> int:
    return int(np.argmin(np.where(scan.hit, scan.ranges, np.inf)))


def _bearing(a: Point, b: Point) -> float:
    return math.atan2(b[1] - a[1], b[0] - a[0])


def _segment_point_distance(a: Point, b: Point, p: Point) -> float:
    ab = np.subtract(b, a)
    t = float(np.clip(np.dot(np.subtract(p, a), ab) / max(float(ab @ ab), 1e-12), 0.0, 1.0))
    return math.dist(p, (a[0] + t * ab[0], a[1] + t * ab[1]))


@numba.njit(cache=True)
def _cast(blocked, x0, y0, angles, max_range):
    """DDA ray casting in cell units: distance to the first blocked cell entered, or ``max_range``."""
    nx, ny = blocked.shape
    n = angles.shape[0]
    ranges = np.empty(n)
    hit = np.zeros(n, np.bool_)
    for r in range(n):
        dx, dy = math.cos(angles[r]), math.sin(angles[r])
        i, j = int(math.floor(x0)), int(math.floor(y0))
        si = 1 if dx > 0 else -1
        sj = 1 if dy > 0 else -1
        ti = ((i + 1 - x0) / dx if dx > 0 else (x0 - i) / -dx) if abs(dx) > 1e-12 else np.inf
        tj = ((j + 1 - y0) / dy if dy > 0 else (y0 - j) / -dy) if abs(dy) > 1e-12 else np.inf
        di = abs(1.0 / dx) if abs(dx) > 1e-12 else np.inf
        dj = abs(1.0 / dy) if abs(dy) > 1e-12 else np.inf
        t = 0.0
        ranges[r] = max_range
        while t < max_range:
            if i < 0 or i >= nx or j < 0 or j >= ny or blocked[i, j]:
                ranges[r] = t
                hit[r] = True
                break
            if ti < tj:
                t = ti
                i += si
                ti += di
            else:
                t = tj
                j += sj
                tj += dj
    return ranges, hit

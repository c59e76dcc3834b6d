"""Baseline search policies for the experiments: the same robot and scenarios, other choices.

Each baseline implements the :class:`~offboard.search.loop.Policy` protocol and returns the planner's own
:class:`~offboard.planning.planner.Decision` objects, so :class:`~offboard.search.loop.Search` drives it exactly as
it drives SYT:

- ``exhaustive``: look around here, then every candidate position, nearest (by path) first;
- ``random``: look around here, then a random reachable candidate (seeded), and so on;
- ``frontier``: the nearest candidate next to unknown floor, else the nearest unvisited one;
- ``oracle``: drive to the closest floor position from which the detector finds the target almost
  surely (its measured table), with room to stop a little off, and look straight at it (it is given
  the truth); should that look miss, the closest such position at least 1 m from it. Where it
  starts in view of the target, it looks from there first.

"Look around" takes every camera setting of the planner once, quickest to reach first. A weak
detection needs a second look before the search ends; once a detection has collapsed the belief onto
one spot every baseline, the oracle too, lets the SYT planner choose that look, so confirming is not
what the comparison measures. (Until session 56 the oracle looked again from where it stood, at the
same angles: the same image, which the search then counted as a second detection.)

Registry: :data:`BASELINES` maps a name to a maker taking the run's :class:`BaselineContext` (seed,
truth) and returning the factory ``(planner) -> Policy`` that :func:`offboard.search.run.run_search`
takes.

The oracle drives by :func:`offboard.experiments.world_facts.viewpoint`, the same seeing geometry (the
detector's table, the tilt limits, occlusion) the harness measures SPL's shortest path with; it asks for
a higher rate and a margin around the spot, so that it is a yardstick that does not fail.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from offboard.navigation import grid_planner
from offboard.experiments.world_facts import (ARRIVAL_MARGIN_M, DRIVE_CLEARANCE_M, SeeingCriteria, Truth,
                                              seeing_cells, true_floor_map, viewpoint)
from offboard.perception.occupancy import OccupancyGrid
from offboard.planning.planner import Decision, SearchPlanner, Views
from offboard.search.loop import Policy
from shared.geometry import Pose2D
from shared.strict import bounds

PolicyFactory = Callable[[SearchPlanner], Policy]


# --- the policies ----------------------------------------------------------------------------------

@dataclass(frozen=True)
class BaselineConfig:
    # a detection collapsed the belief: a coarse block holds this much of it, and this many times what any
    # block held at the start (a prior as sharp as the shipped suites' tables, 0.05 at most, leaves room)
    collapsed_mass: float = field(default=0.1, metadata=bounds(0.0, 1.0))
    collapsed_gain: float = field(default=2.0, metadata=bounds(1.0, 1e6))
    frontier_radius_m: float = field(default=0.75, metadata=bounds(0.05, 10.0))  # "adjacent" to unknown floor
    oracle_moves: int = field(default=2, metadata=bounds(1, 100))  # moves to the viewpoint that gain no ground
    oracle_headway_m: float = field(default=0.1, metadata=bounds(0.01, 5.0))  # ... less than this
    # viewpoints to try, each at least oracle_retry_m from those tried: another view, not the same one a step off
    oracle_viewpoints: int = field(default=2, metadata=bounds(1, 100))
    oracle_retry_m: float = field(default=1.0, metadata=bounds(0.0, 10.0))
    arrived_m: float = field(default=ARRIVAL_MARGIN_M, metadata=bounds(0.0, 5.0))  # near enough to the viewpoint
    # where the oracle looks from: a higher rate than SPL's "sees the target" (0.8), on the floor the navigator
    # drives; should no spot qualify (with ``arrived_m`` around it), SPL's own criteria
    oracle_view: SeeingCriteria = field(default_factory=lambda: SeeingCriteria(min_rate=0.9,
                                                                               robot_radius_m=DRIVE_CLEARANCE_M))


@dataclass(frozen=True)
class BaselineContext:
    """What a run gives its baseline: the run's seed, and the truth (the oracle's only)."""

    seed: int = 0
    truth: Truth | None = None
    config: BaselineConfig = BaselineConfig()


class Confirming:
    """SYT's choice while a detection waits to be confirmed, for a baseline built on ``planner`` before
    its first look. The belief has collapsed onto a detection once one coarse block holds
    ``collapsed_mass`` of it and ``collapsed_gain`` times the most any block held at the start, or half
    the way from that to all of it, whichever is less: a sharp prior (``tables`` with one small
    surface) must not read as a detection from the first decision, and one whose block holds half the
    belief must still let a detection through."""

    def __init__(self, planner: SearchPlanner, config: BaselineConfig):
        self.planner = planner
        start = _peak_block(planner)
        self.gate = max(config.collapsed_mass, min(config.collapsed_gain * start, (1.0 + start) / 2))

    def __call__(self, *decide_args) -> Decision | None:
        if _peak_block(self.planner) < self.gate:
            return None
        decision = self.planner.decide(*decide_args)
        return None if decision.kind == "stop" else decision


def _peak_block(planner: SearchPlanner) -> float:
    return float(planner.belief.coarse_mass().sum(axis=-1).max())


def _within_budget(planner: SearchPlanner, decision: Decision, elapsed_s: float) -> Decision:
    if decision.kind != "stop" and elapsed_s + decision.time_s > planner.config.budget_s:
        return Decision("stop", f"the next action ({decision.time_s:.1f} s) would exceed the budget "
                                f"K = {planner.config.budget_s:g} s", status="budget")
    return decision


class _Tour:
    """Look around (every setting once, quickest first), then move where :meth:`_choose` says.

    A tour's memory is where it has looked from (``visited``): it does not go back there, so it reads
    only this stay's ``taken``, and so does SYT's choice when the tour asks it to confirm a detection."""

    name = "tour"

    def __init__(self, planner: SearchPlanner, config: BaselineConfig):
        self.planner, self.config = planner, config
        self._confirming = Confirming(planner, config)
        self.visited = np.zeros(len(planner.positions), bool)
        self.goal: int | None = None  # the position of the last move

    def decide(self, pose: Pose2D, pan_rad: float, tilt_rad: float, elapsed_s: float, occupancy: OccupancyGrid,
               path_lengths_m: np.ndarray, taken: frozenset[int] = frozenset(),
               views: Views = ()) -> Decision:
        decision = (self._confirming(pose, pan_rad, tilt_rad, elapsed_s, occupancy, path_lengths_m, taken)
                    or self._look_around(pose, pan_rad, tilt_rad, taken)
                    or self._next_position(pose, occupancy, np.asarray(path_lengths_m, float)))
        return _within_budget(self.planner, decision, elapsed_s)

    def _look_around(self, pose: Pose2D, pan_rad: float, tilt_rad: float, taken: frozenset[int]) -> Decision | None:
        here = np.hypot(*(self.planner.positions - (pose.x_m, pose.y_m)).T) <= self.planner.config.same_position_m
        self.visited |= here
        settings = self.planner.settings
        left = np.array([s for s in range(len(settings)) if s not in taken], int)
        if len(left) == 0:
            return None
        times = self.planner.time_model.look_times_s(pose.heading_rad, pan_rad, tilt_rad,
                                                     settings.azimuth_rad[left], settings.tilt_rad[left])
        k = int(np.argmin(times))
        s = int(left[k])
        return Decision("look", f"{self.name}: look around, {len(left) - 1} settings left here",
                        float(settings.azimuth_rad[s]), float(settings.tilt_rad[s]), time_s=float(times[k]), setting=s)

    def _next_position(self, pose: Pose2D, occupancy: OccupancyGrid, paths: np.ndarray) -> Decision:
        """The next position to look around from. A position is visited on arrival (:meth:`_look_around`),
        so a move that a detection on the way stopped short goes on to its goal, if it is still reachable."""
        if self.goal is not None and not self.visited[self.goal] and np.isfinite(paths[self.goal]):
            return self._move_to(pose, self.goal, paths, "on to")
        available = np.isfinite(paths) & ~self.visited
        if not available.any():
            return Decision("stop", f"{self.name}: every reachable position has been looked around",
                            status="exhausted")
        self.goal, why = self._choose(pose, occupancy, paths, available)
        return self._move_to(pose, self.goal, paths, why)

    def _choose(self, pose: Pose2D, occupancy: OccupancyGrid, paths: np.ndarray,
                available: np.ndarray) -> tuple[int, str]:
        return _nearest(paths, available), "the nearest unvisited position"

    def _move_to(self, pose: Pose2D, j: int, paths: np.ndarray, why: str) -> Decision:
        """To candidate ``j``, its first look the quickest one on arrival, timed as SYT times a move."""
        x, y = (float(v) for v in self.planner.positions[j])
        times = self.planner.candidate_times(pose, paths)[j]
        s = int(np.argmin(times))
        settings = self.planner.settings
        return Decision("move", f"{self.name}: {why} ({x:g}, {y:g}), {paths[j]:.1f} m away",
                        float(settings.azimuth_rad[s]), float(settings.tilt_rad[s]), (x, y),
                        time_s=float(times[s]), setting=s)


def _nearest(paths: np.ndarray, available: np.ndarray) -> int:
    return int(np.argmin(np.where(available, paths, np.inf)))


class Exhaustive(_Tour):
    name = "exhaustive"


class RandomTour(_Tour):
    name = "random"

    def __init__(self, planner: SearchPlanner, config: BaselineConfig, seed: int):
        super().__init__(planner, config)
        self.rng = np.random.default_rng(seed)

    def _choose(self, pose: Pose2D, occupancy: OccupancyGrid, paths: np.ndarray,
                available: np.ndarray) -> tuple[int, str]:
        return int(self.rng.choice(np.flatnonzero(available))), "a random reachable position"


class Frontier(_Tour):
    name = "frontier"

    def _choose(self, pose: Pose2D, occupancy: OccupancyGrid, paths: np.ndarray,
                available: np.ndarray) -> tuple[int, str]:
        near_unknown = available & self._near_frontier(occupancy)
        if near_unknown.any():
            return _nearest(paths, near_unknown), "the nearest position next to unknown floor"
        return _nearest(paths, available), "no frontier left: the nearest unvisited position"

    def _near_frontier(self, occupancy: OccupancyGrid) -> np.ndarray:
        """Candidates within ``frontier_radius_m`` of a frontier cell (known free floor beside unknown)."""
        base = self.planner.time_model.base
        floor = occupancy.floor_map(base.radius_m, base.height_m)
        unknown = floor.unknown.astype(np.uint8)
        beside_unknown = cv2.dilate(unknown, np.ones((3, 3), np.uint8)).astype(bool)
        frontier = beside_unknown & ~floor.unknown & ~floor.blocked
        if not frontier.any():
            return np.zeros(len(self.planner.positions), bool)
        to_frontier = cv2.distanceTransform((~frontier).astype(np.uint8), cv2.DIST_L2, 5) * floor.resolution_m
        cells = floor.cells_of(self.planner.positions)
        return to_frontier[cells[:, 0], cells[:, 1]] <= self.config.frontier_radius_m


class Oracle:
    """Knows where the target is: drives to the closest position that sees it and looks at it. Where
    it starts in view of the target (as SPL counts seeing, whose shortest path is then nil), it looks
    from there first: driving to its own stricter viewpoint would cost SPL for nothing."""

    def __init__(self, planner: SearchPlanner, truth: Truth, config: BaselineConfig):
        self.planner, self.truth, self.config = planner, truth, config
        self._confirming = Confirming(planner, config)
        self.goal: tuple[float, float] | None = None
        self._from_start: bool | None = None  # looking from where it started (None: not yet asked)
        self.tried: tuple[tuple[float, float], ...] = ()  # viewpoints whose looks did not find it
        self.moves = 0  # moves to this viewpoint that gained no ground
        self.looked = False  # from this viewpoint
        self._sent_from_m: float | None = None  # how far from its viewpoint the last move began

    def decide(self, pose: Pose2D, pan_rad: float, tilt_rad: float, elapsed_s: float, occupancy: OccupancyGrid,
               path_lengths_m: np.ndarray, taken: frozenset[int] = frozenset(),
               views: Views = ()) -> Decision:
        # another view, as the tours confirm: the same one again would show the same image
        if confirm := self._confirming(pose, pan_rad, tilt_rad, elapsed_s, occupancy, path_lengths_m, taken, views):
            self._sent_from_m = None  # SYT's move, not one toward the viewpoint
            return _within_budget(self.planner, confirm, elapsed_s)
        if self._from_start is None:
            self._from_start = self._seen_from((pose.x_m, pose.y_m))
            self.goal = (pose.x_m, pose.y_m) if self._from_start else None
        if self.looked:  # its look from here missed, and another from the same pose would show the same image
            if self._from_start:  # SPL's view missed: its own viewpoints are still all to try
                self._from_start = False
            elif self.goal not in self.tried:  # asked again after stopping (the search's squeeze retry)
                self.tried += (self.goal,)
            if len(self.tried) >= self.config.oracle_viewpoints:
                return Decision("stop", f"oracle: a look from each of {len(self.tried)} viewpoints did not find it",
                                status="exhausted")
            self.goal, self.moves, self.looked = None, 0, False
        if self.goal is None:
            self.goal = self._viewpoint((pose.x_m, pose.y_m))
        if self.goal is None:
            return Decision("stop", "oracle: no reachable position sees the target", status="exhausted")
        to_goal_m = pose.distance_to(*self.goal)
        if self._sent_from_m is not None and to_goal_m > self._sent_from_m - self.config.oracle_headway_m:
            self.moves += 1  # a failed try; one that gained ground was stopped by a detection on the way
        self._sent_from_m = None
        if to_goal_m > self.config.arrived_m and self.moves < self.config.oracle_moves:
            self._sent_from_m = to_goal_m
            return _within_budget(self.planner, self._move(pose), elapsed_s)
        self.looked = True
        return _within_budget(self.planner, self._look_from(pose, pan_rad, tilt_rad, 0.0), elapsed_s)

    def _viewpoint(self, start_xy: tuple[float, float]) -> tuple[float, float] | None:
        """Its own strict view with room to stop a little off; else SPL's closest seeing position; away
        from the viewpoints already tried."""
        strict, avoid = self.config.oracle_view, dict(avoid=self.tried, avoid_m=self.config.oracle_retry_m)
        goal, _ = viewpoint(self.truth, start_xy, strict, self.config.arrived_m, **avoid)
        if goal is None:
            goal, _ = viewpoint(self.truth, start_xy, replace(self._spl_view, robot_radius_m=strict.robot_radius_m),
                                **avoid)
        return goal

    @property
    def _spl_view(self) -> SeeingCriteria:
        return SeeingCriteria(table=self.config.oracle_view.table)

    def _seen_from(self, xy: tuple[float, float]) -> bool:
        """Does the target lie in view from ``xy``, as SPL's shortest path counts seeing?"""
        floor = true_floor_map(self.truth, self._spl_view)
        return bool(seeing_cells(self.truth, floor, self._spl_view)[grid_planner.cell_of(floor, xy)])

    def _move(self, pose: Pose2D) -> Decision:
        gx, gy = self.goal
        floor = true_floor_map(self.truth, self.config.oracle_view)
        path = float(grid_planner.path_lengths(floor, (pose.x_m, pose.y_m), np.array([self.goal]))[0])
        travel = self.planner.time_model.travel_s(path, pose.bearing_to(gx, gy))
        look = self._look_from(Pose2D(gx, gy, math.atan2(gy - pose.y_m, gx - pose.x_m)), 0.0, 0.0, travel)
        return Decision("move", f"oracle: to the viewpoint ({gx:.2f}, {gy:.2f}), {path:.1f} m",
                        look.azimuth_rad, look.tilt_rad, (gx, gy), time_s=look.time_s, setting=look.setting)

    def _look_from(self, pose: Pose2D, pan_rad: float, tilt_rad: float, travel_s: float) -> Decision:
        """Straight at the nearest picture's centre from ``pose`` (the tilt within its limits); the setting
        recorded is the nearest one."""
        tx, ty, tz = min((self.truth.face_centre(n) for n in self.truth.face_normals()),
                         key=lambda face: math.hypot(face[0] - pose.x_m, face[1] - pose.y_m))
        azimuth = math.atan2(ty - pose.y_m, tx - pose.x_m)
        limits = self.planner.time_model.pantilt
        tilt = math.atan2(tz - self.planner.mount.height_m, math.hypot(tx - pose.x_m, ty - pose.y_m))
        tilt = min(max(tilt, math.radians(limits.tilt_min_deg)), math.radians(limits.tilt_max_deg))
        plan = self.planner.time_model.look(pose.heading_rad, pan_rad, tilt_rad, azimuth, tilt)
        settings = self.planner.settings
        gap = np.abs(np.angle(np.exp(1j * (settings.azimuth_rad - azimuth)))) + np.abs(settings.tilt_rad - tilt)
        return Decision("look", "oracle: straight at the target", azimuth, tilt, time_s=travel_s + plan.time_s,
                        setting=int(np.argmin(gap)))


# --- the registry ----------------------------------------------------------------------------------

def _exhaustive(context: BaselineContext) -> PolicyFactory:
    return lambda planner: Exhaustive(planner, context.config)


def _random(context: BaselineContext) -> PolicyFactory:
    return lambda planner: RandomTour(planner, context.config, context.seed)


def _frontier(context: BaselineContext) -> PolicyFactory:
    return lambda planner: Frontier(planner, context.config)


def _oracle(context: BaselineContext) -> PolicyFactory:
    if context.truth is None:
        raise ValueError("the oracle baseline needs the truth (the target's real position)")
    return lambda planner: Oracle(planner, context.truth, context.config)


BASELINES: dict[str, Callable[[BaselineContext], PolicyFactory]] = {
    "exhaustive": _exhaustive, "random": _random, "frontier": _frontier, "oracle": _oracle,
}

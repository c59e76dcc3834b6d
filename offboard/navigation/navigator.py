"""Drive a robot to a floor goal: TangentBug motion, global Dijkstra guidance, fresh stereo each step.

The report's navigation (§4.2): the robot moves with TangentBug (:mod:`offboard.navigation.tangent_bug`) while
the global planner (:mod:`offboard.navigation.grid_planner`) answers whether the goal is reachable at all and
how far it is. The two meet in TangentBug's heuristic: the tangent-graph node O_i it heads for
minimises ``d(x, O_i) + D(O_i)``, where D is the Dijkstra path length to the goal on the map built
so far (unknown space counted free), instead of the straight-line ``d(O_i, goal)``. D is a navigation
function, without local minima, so motion-to-goal alone follows near-shortest paths and boundary
following is never needed; the bug is reset every step. Where D is infinite the goal is unreachable.

Each step is one bounded straight move (``bug.step_m``). Before it the head looks toward the motion
and a stereo pair updates, in turn, the pose (scan matching, :mod:`offboard.navigation.localization`, against
the map of *earlier* frames) and then the shared :class:`~offboard.perception.occupancy.OccupancyGrid` (placed
with the corrected pose). Motions are planned in the corrected world frame and sent as odometry-frame
waypoints through the :class:`~offboard.navigation.localization.PoseTracker`. Driving into unmapped
space, the look toward the motion has nothing to match: if the pose is then unsure, the head turns to
where the map (the room's walls at least) holds the most structure in range, and looks there, before
the look toward the motion is mapped with the pose it corrected; so it does on arrival, before the
search looks from the new pose. A stall (the base touched
something stereo missed) marks the obstacle in the map and backs off. A goal the map shows blocked is
approached until seen from close by (far obstacles are mapped thick).

Stereo ghosts can close a passage on the map. With no route, the robot first looks all round; then,
if a route exists past weakly seen obstacles only, it looks closely along it (a ghost fades when seen
through) and drives as far as the map allows, never into blocked space. Coming back to where an
earlier step ended (the map flickering near a narrow gap) also earns a look all round. A run ends
``reached``, ``unreachable`` (no route even so), ``stalled_out`` or ``budget``; all are bounded. A caller
may also see each look toward the motion once it is mapped (``observe``): the search runs its detector
on it, and a run it asks to stop ends ``interrupted`` where the robot stands.
Where TangentBug's step gets no closer on D, the step goes toward the first corner of the global path
instead: at a gap narrower than its edge clearance the tangent graph offers no node that does, or none
at all, and the bug turns to boundary following.
"""

from __future__ import annotations

import copy
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Literal, TypeVar

import numpy as np

from offboard.navigation.grid_planner import (Point, cell_center, distance_field, distances_at, is_free, nearest_free_cell,
                                   segment_is_free, shortest_path)
from offboard.navigation.localization import (MatchConfig, PoseTracker, ScanMatcher, map_field, scan_from_disparity,
                                              structure_in_view)
from offboard.perception.occupancy import FloorMap, OccupancyGrid
from offboard.robot.robot_client import CommandError, RobotClient
from offboard.perception.stereo import StereoConfig, StereoMatcher
from offboard.navigation.tangent_bug import BugConfig, BugStep, TangentBug
from shared.geometry import Pose2D
from shared.limits import BaseLimits
from shared.messages import Capture

log = logging.getLogger(__name__)

Status = Literal["reached", "unreachable", "stalled_out", "budget", "interrupted"]
T = TypeVar("T")
# Sees a look toward the motion (the capture, the corrected pose it was taken from, its disparity) once
# it is mapped; returns a reason to stop the run there, or "" to drive on.
FrameObserver = Callable[[Capture, Pose2D, np.ndarray], str]


@dataclass(frozen=True)
class NavigatorConfig:
    margin_m: float = 0.05  # clearance beyond the robot's radius (odometry and map errors)
    goal_tolerance_m: float = 0.1
    look_tilt_deg: float = -25.0  # the floor from ~1 m ahead up to the horizon is in view
    survey_pans_deg: tuple[float, ...] = (-150.0, -100.0, -50.0, 0.0, 50.0, 100.0, 150.0)
    backoff_m: float = 0.15  # after a stall: room to turn away
    max_stalls: int = 4
    max_surveys: int = 3  # looks all round per run: before giving up, or when going back and forth
    revisit_radius_m: float = 0.2  # ending a step this close to an earlier one is going back and forth
    confident_log_odds: float = 2.5  # with no route, obstacles this sure (seen in ~3 frames) still count
    max_probes: int = 6  # close looks per run at weakly seen obstacles that close the way
    probe_tilt_deg: float = -35.0  # a close look: the floor from 0.6 m ahead
    max_steps: int = 150
    max_distance_m: float = 60.0
    localize: bool = True  # correct odometry by scan matching (off: dead reckoning only)
    # a pose this unsure (PoseTracker.target_shift_m at relocalize_range_m) after the look toward
    # the motion earns a look at mapped structure: driving into unmapped space, that look saw nothing
    # to match, and a heading error moves a target seen at the detector's range the farthest
    relocalize_shift_m: float = 0.15
    relocalize_range_m: float = 3.0
    max_relocalizations: int = 4  # such looks per run
    # the bug's "sensor" is the whole map (ranges across the room); one step is about the blind zone
    # ahead of the tilted head, so each move ends where the last look reached the floor
    bug: BugConfig = field(default_factory=lambda: BugConfig(sensor_range_m=12.0, step_m=0.6))
    match: MatchConfig = MatchConfig()

    def clearance_m(self, base: BaseLimits, squeeze: bool = False) -> float:
        """How far the base's centre keeps from a mapped obstacle: its radius and ``margin_m``, or with
        ``squeeze`` its bare radius."""
        return base.radius_m + (0.0 if squeeze else self.margin_m)


@dataclass(frozen=True)
class NavigationResult:
    status: Status
    reason: str
    pose: Pose2D  # corrected world pose at the end
    odometry: Pose2D  # the robot's own odometry pose at the end
    distance_m: float  # driven (back-offs included)
    robot_time_s: float  # robot clock from start to end
    processing_s: float  # wall clock not spent waiting for the robot: stereo, localisation, mapping, routing
    steps: int
    stalls: int
    matches_accepted: int  # scan matches fused into the pose during the run
    matches_tried: int


@dataclass(frozen=True)
class _Frame:
    """A stereo frame captured and localised, waiting to be mapped."""

    capture: Capture
    disparity: np.ndarray
    pan_rad: float
    tilt_rad: float
    robot_time_s: float  # robot clock at capture


@dataclass
class _Run:
    goal: Point
    start_time_s: float
    last_time_s: float
    matches: tuple[int, int]  # accepted, tried before the run
    wall_start_s: float  # wall clock at the start, and time spent waiting for the robot before it
    waiting_start_s: float
    squeeze: bool  # planned on the bare radius (Navigator.floor_map)
    observe: FrameObserver | None = None
    confident: bool = False  # planned past obstacles seen in one or two frames only (Navigator.floor_map)
    interrupted: str = ""  # why the observer stopped the run
    distance_m: float = 0.0
    steps: int = 0
    stalls: int = 0
    surveys: int = 0
    probes: int = 0
    relocalizations: int = 0
    pans_here: list[float] = field(default_factory=list)  # pans looked at since the last motion (degrees)
    visited: list[Point] = field(default_factory=list)  # where each step ended


class Navigator:
    """Owns a :class:`PoseTracker`; shares the :class:`OccupancyGrid` it is given."""

    def __init__(self, robot: RobotClient, occupancy: OccupancyGrid, tracker: PoseTracker | None = None,
                 config: NavigatorConfig = NavigatorConfig(), stereo: StereoConfig = StereoConfig()):
        if any(occupancy.grid.origin_m[:2]):
            raise ValueError("floor maps are indexed from the world origin: the grid must start at x = y = 0")
        self.robot, self.occupancy, self.config = robot, occupancy, config
        info = robot.info()
        self._base, self._pantilt, self._capture_s = info.base, info.pantilt, info.camera.capture_s
        self._intrinsics, self._mount = info.intrinsics.to_intrinsics(), info.mount.to_mount()
        self._odom = robot.state().pose.to_pose()
        self.tracker = tracker if tracker is not None else PoseTracker(self._odom)
        self._stereo = StereoMatcher(stereo)  # the search's own: one map, one kind of depth
        self._matcher = ScanMatcher(config.match)
        self.matches_tried = self.matches_accepted = 0
        self.waiting_s = 0.0  # wall clock spent in robot commands: the rest of a run is processing

    @property
    def pose(self) -> Pose2D:
        """Corrected world pose of the robot at its last known odometry."""
        return self.tracker.world_pose(self._odom)

    def nominal_s_per_m(self) -> float:
        """Robot time per metre of a run without stalls or surveys: each step drives ``bug.step_m``
        from rest to rest after one capture toward the motion (the planner's travel time until runs
        have been measured)."""
        step = self.config.bug.step_m
        return (float(self._base.drive_time_s(step)) + self._capture_s) / step

    def floor_map(self, squeeze: bool = False, confident: bool = False) -> FloorMap:
        """The columns the base may not enter: obstacles inflated by its radius and ``margin_m``, or with
        ``squeeze`` by its bare radius. Rounded up to whole cells, and with a mapped cube occupied by any
        part of an obstacle, the margin can shut on the map a corridor that is wide enough in truth: a
        robot so boxed in squeezes through on the bare radius. Rounded up (6 cubes of 5 cm for the
        Pioneer's 0.26 m) that still keeps 0.275 m from a mapped cube's near face; the margin for odometry
        error is what it gives up, and the bumper is the last line. ``confident``: obstacles seen in
        several frames only (``confident_log_odds``); a stereo ghost is seen once or twice, a real
        obstacle at every look toward it."""
        occupancy = self.occupancy
        if confident:  # a view of the shared grid, not a copy
            occupancy = copy.copy(self.occupancy)
            occupancy.config = replace(self.occupancy.config, occupied_log_odds=self.config.confident_log_odds)
        return occupancy.floor_map(self.clearance_m(squeeze), self._base.height_m)

    def clearance_m(self, squeeze: bool = False) -> float:
        """:meth:`NavigatorConfig.clearance_m` for this robot's base."""
        return self.config.clearance_m(self._base, squeeze)

    # --- sensing -----------------------------------------------------------------------------------

    def sense(self, pan_deg: float, tilt_deg: float | None = None) -> float:
        """Look, capture, localise against the map so far, then add the frame to the map; robot time."""
        frame = self._look(pan_deg, tilt_deg)
        self._map(frame)
        return frame.robot_time_s

    def _look(self, pan_deg: float, tilt_deg: float | None = None) -> _Frame:
        """Look, capture and localise against the map so far; the frame is not mapped yet."""
        tilt = self.config.look_tilt_deg if tilt_deg is None else tilt_deg
        pan = float(np.clip(pan_deg, self._pantilt.pan_min_deg, self._pantilt.pan_max_deg))
        self._command(self.robot.look, pan, tilt)
        capture = self._command(self.robot.capture)
        frame = _Frame(capture, self._stereo.disparity(capture.left, capture.right), math.radians(capture.pan_deg),
                       math.radians(capture.tilt_deg), capture.robot_time_s)
        self._odom = capture.pose.to_pose()
        self.tracker.predict(self._odom)
        if self.config.localize:
            self._localize(frame.disparity, frame.pan_rad, frame.tilt_rad)
        return frame

    def _map(self, frame: _Frame) -> None:
        """Add a frame to the map, placed with the pose as corrected now (the base has not moved since
        it was captured: only the head turns between looks)."""
        camera = self._mount.camera_in_world(self.pose, frame.pan_rad, frame.tilt_rad)
        self.occupancy.integrate_disparity(frame.disparity, self._intrinsics, self._mount.baseline_m, camera)

    def survey(self, tilt_deg: float | None = None) -> float:
        """Look all round (pan sweep) from where the robot stands; robot time at the end."""
        return max(self.sense(pan, tilt_deg) for pan in self.config.survey_pans_deg)

    def _localize(self, disparity: np.ndarray, pan_rad: float, tilt_rad: float) -> None:
        scan = scan_from_disparity(disparity, self._intrinsics, self._mount, pan_rad, tilt_rad, self.config.match)
        self.matches_tried += 1
        result = self._matcher.match(scan, self.tracker.pose, map_field(self.occupancy, self.config.match),
                                     self.tracker.covariance)
        if not result.accepted:
            log.debug("scan match not used: %s", result.reason)
            return
        if self.tracker.correct(self._odom, result.pose, result.covariance):
            self.matches_accepted += 1

    # --- driving -----------------------------------------------------------------------------------

    def go_to(self, goal: Point, squeeze: bool = False, observe: FrameObserver | None = None,
              confident: bool = False) -> NavigationResult:
        """Drive to ``goal`` (world frame, metres); never raises for an unreachable goal. ``squeeze``:
        plan the whole run on the bare radius, and ``confident`` past obstacles seen in one or two
        frames only (:meth:`floor_map`). ``observe`` sees every look toward the motion and may stop the
        run (``interrupted``)."""
        state = self.robot.state()  # the robot may have been turned or moved since the last call
        self._odom = state.pose.to_pose()
        self.tracker.predict(self._odom)
        run = _Run(goal, state.robot_time_s, state.robot_time_s, (self.matches_accepted, self.matches_tried),
                   time.perf_counter(), self.waiting_s, squeeze, observe, confident)
        bug = TangentBug(goal, self.config.bug)
        while True:
            verdict = self._verdict(run)
            if verdict is not None and verdict[0] == "reached" and self._relocalize(run):
                continue  # the corrected pose may not have arrived after all
            if verdict is not None:
                return self._result(run, *verdict)
            waypoint, why = self._next_waypoint(run, bug)
            if run.interrupted:
                return self._result(run, "interrupted", run.interrupted)
            if waypoint is None and self._verdict(run) is not None:
                continue  # the look ahead's scan match put the robot at its goal after all
            if waypoint is None and why.startswith("no route") and (self._survey_once(run) or self._probe(run)):
                continue  # ghosts fade and gaps show: look again before giving up
            if waypoint is None:
                return self._result(run, "unreachable", why)
            self._drive(run, waypoint)
            if self._back_again(run):
                self._survey_once(run)  # the map flickers near a narrow gap: settle it with a good look

    def _survey_once(self, run: _Run) -> bool:
        """Look all round, at most ``max_surveys`` times a run; whether it did."""
        if run.surveys >= self.config.max_surveys:
            return False
        run.surveys += 1
        run.last_time_s = self.survey()
        return True

    def _probe(self, run: _Run) -> bool:
        """No route on the map: is there one past weakly seen obstacles only (stereo ghosts are seen
        once or twice, real obstacles at every look)? Then look closely along it, ghosts fade when seen
        through, and drive as far as the map allows. Whether it found such a route."""
        c = self.config
        here = (self.pose.x_m, self.pose.y_m)
        path = shortest_path(self.floor_map(run.squeeze, confident=True), here, run.goal)
        if path is None or run.probes >= c.max_probes:
            return False
        run.probes += 1
        run.last_time_s = self.sense(self._pan_toward(path[1]), c.probe_tilt_deg)
        waypoint = _free_prefix(self.floor_map(run.squeeze, run.confident), here, path, c.bug.step_m)
        if waypoint is not None and math.dist(here, waypoint) >= c.bug.min_step_m:
            log.debug("probing toward (%.2f, %.2f)", *waypoint)
            self._drive(run, waypoint)
        return True

    def _back_again(self, run: _Run) -> bool:
        """Has the robot come back to where an earlier step (not the last) ended?"""
        here = (self.pose.x_m, self.pose.y_m)
        back = any(math.dist(here, p) < self.config.revisit_radius_m for p in run.visited[:-1])
        run.visited.append(here)
        return back

    def _verdict(self, run: _Run) -> tuple[Status, str] | None:
        c = self.config
        if math.dist((self.pose.x_m, self.pose.y_m), run.goal) <= c.goal_tolerance_m:
            return "reached", "within tolerance of the goal"
        if run.stalls >= c.max_stalls:
            return "stalled_out", f"{run.stalls} stalls"
        if run.steps >= c.max_steps or run.distance_m >= c.max_distance_m:
            return "budget", f"{run.steps} steps, {run.distance_m:.1f} m driven"
        return None

    def _next_waypoint(self, run: _Run, bug: TangentBug) -> tuple[Point | None, str]:
        """Plan on the current map, look toward the motion (and for the map if the pose is still
        unsure), re-plan on the refreshed map."""
        planned = self._plan(run, bug)
        if planned[0] is not None:
            pan = self._pan_toward(planned[0])
            frame = self._look(pan)
            run.last_time_s = frame.robot_time_s
            run.pans_here.append(pan)
            self._relocalize(run)  # the look ahead, into unmapped space, may have had nothing to match
            self._map(frame)  # so it is mapped with the pose the look for the map corrected
            if run.observe is not None:
                run.interrupted = run.observe(frame.capture, self.pose, frame.disparity)
            if not run.interrupted:
                planned = self._plan(run, bug)
        return planned

    def _relocalize(self, run: _Run) -> bool:
        """If the pose is unsure, look where the map holds the most structure in range (the walls are
        always mapped, but may all be out of range in a large room), at a pan at least half the field
        of view from those this run has looked at since its last motion; whether it looked."""
        c = self.config
        shift_m = self.tracker.target_shift_m(c.relocalize_range_m)
        if not c.localize or run.relocalizations >= c.max_relocalizations or shift_m <= c.relocalize_shift_m:
            return False
        hfov = self._intrinsics.hfov_rad
        pans = np.array([p for p in c.survey_pans_deg if all(abs(p - q) > math.degrees(hfov) / 2 for q in run.pans_here)
                         and self._pantilt.pan_min_deg <= p <= self._pantilt.pan_max_deg])
        if pans.size == 0:
            return False
        counts = structure_in_view(map_field(self.occupancy, c.match), self.pose, np.radians(pans), hfov, c.match)
        if counts.max() == 0:
            return False  # nothing mapped in range to match a scan against: the look would be wasted
        pan = float(pans[int(np.argmax(counts))])
        log.debug("pose unsure (%.2f m at %.1f m): looking for the map at pan %.0f°", shift_m, c.relocalize_range_m,
                  pan)
        run.relocalizations += 1
        run.last_time_s = self.sense(pan)
        run.pans_here.append(pan)
        return True

    def _plan(self, run: _Run, bug: TangentBug) -> tuple[Point | None, str]:
        floor = self.floor_map(run.squeeze, run.confident)
        here = (self.pose.x_m, self.pose.y_m)
        nx, ny = floor.blocked.shape
        if not (0.0 <= run.goal[0] < nx * floor.resolution_m and 0.0 <= run.goal[1] < ny * floor.resolution_m):
            return None, "the goal lies outside the room"
        target = self._target(floor, run.goal, here)
        if target is None or (target != run.goal and math.dist(here, target) <= self.config.goal_tolerance_m):
            return None, f"no route: the goal is blocked (seen from {math.dist(here, run.goal):.1f} m)"
        to_target = distance_field(floor, target)
        start = nearest_free_cell(floor, here)  # where a robot hugging an obstacle escapes to
        if start is None or not math.isfinite(to_target[start]):
            return None, "no route to the goal on the map"
        # Path lengths on the map form a navigation function, which has no local minima: TangentBug's
        # motion-to-goal with it as heuristic needs no boundary following, so its memory is reset (the
        # bug still turns to following where it sees no tangent node: see below).
        bug.retarget(target)
        step = bug.step(floor, here, lambda points: distances_at(floor, to_target, points))
        # Every move but an escape from blocked space must get closer on the path lengths, boundary
        # following's too: with no tangent node in sight (a gap narrower than the edge clearance) the
        # bug still turns to following, and its loop and length bounds, reset with it every step,
        # never end a run going to and fro there.
        if step.status == "move" and step.mode != "escape":
            progress = to_target[start] - distances_at(floor, to_target, np.array([step.waypoint]))[0]
            if progress < 0.5 * math.dist(here, step.waypoint):
                step = self._along_path(floor, here, target)
        if step.status != "move":
            return None, f"TangentBug: {step.reason}"
        if step.mode != "escape" and not segment_is_free(floor, here, step.waypoint):
            return None, "TangentBug proposed a blocked move"  # cannot happen: its moves are checked
        log.debug("at (%.2f, %.2f): %s toward (%.2f, %.2f)", *here, step.mode, *step.waypoint)
        return step.waypoint, step.mode

    def _along_path(self, floor: FloorMap, here: Point, target: Point) -> BugStep:
        """Toward the first corner of the global path, which is in sight. The fallback when TangentBug's
        step gets no closer (a gap narrower than its edge clearance, where it offers no tangent node)."""
        path = shortest_path(floor, here, target)
        if path is None or len(path) < 2:
            return BugStep("unreachable", None, "done", "no global path")
        corner = path[1]
        hop = math.dist(here, corner)
        t = min(1.0, self.config.bug.step_m / hop) if hop > 0.0 else 0.0
        return BugStep("move", (here[0] + t * (corner[0] - here[0]), here[1] + t * (corner[1] - here[1])), "path")

    @staticmethod
    def _target(floor: FloorMap, goal: Point, here: Point) -> Point | None:
        """The goal, or if the map has it blocked the nearest free place reachable from ``here``:
        obstacles seen from afar are mapped thick (depth error grows as z²), so a goal is only given up
        once seen from close by. The nearest free place may be shut in (the floor inside a pen, or an
        object's unseen inside): then the nearest that a path reaches."""
        if is_free(floor, goal):
            return goal
        cell = nearest_free_cell(floor, goal)
        if cell is not None:
            from_here = distance_field(floor, here)
            if not math.isfinite(from_here[cell]):
                cell = nearest_free_cell(floor, goal, among=np.isfinite(from_here))
        return None if cell is None else cell_center(floor, cell)

    def _command(self, command: Callable[..., T], *args: float) -> T:
        """A robot command (:func:`retry_busy`), its wall time booked as waiting, not processing."""
        started = time.perf_counter()
        try:
            return retry_busy(command, *args)
        finally:
            self.waiting_s += time.perf_counter() - started

    def _pan_toward(self, point: Point) -> float:
        pose = self.pose
        return math.degrees(pose.bearing_to(*point))

    def _drive(self, run: _Run, waypoint: Point) -> None:
        odom_goal = self.tracker.odom_point(waypoint)
        result = self._command(self.robot.move_to, *odom_goal)
        run.steps += 1
        run.pans_here.clear()
        run.distance_m += result.distance_m
        run.last_time_s = result.robot_time_s
        self._odom = result.pose.to_pose()
        self.tracker.predict(self._odom)
        if result.status == "stalled":
            self._on_stall(run)

    def _on_stall(self, run: _Run) -> None:
        """Something stereo missed stopped the base: put it in the map, back off, re-plan."""
        run.stalls += 1
        pose = self.pose
        log.info("stalled at (%.2f, %.2f) heading %.0f°: marking the obstacle ahead", pose.x_m, pose.y_m,
                 math.degrees(pose.heading_rad))
        self._mark_contact(pose)
        back = self._command(self.robot.move, 0.0, -self.config.backoff_m)
        run.distance_m += back.distance_m
        run.last_time_s = back.robot_time_s
        self._odom = back.pose.to_pose()
        self.tracker.predict(self._odom)

    def _mark_contact(self, pose: Pose2D) -> None:
        """Occupy a strip as wide as the robot just beyond its front, from the floor to knee height."""
        grid, c = self.occupancy.grid, self.occupancy.config
        ahead = np.array([math.cos(pose.heading_rad), math.sin(pose.heading_rad)])
        across = np.array([-ahead[1], ahead[0]])
        centre = np.array([pose.x_m, pose.y_m]) + ahead * (self._base.radius_m + grid.resolution_m)
        half = grid.resolution_m / 2
        with self.occupancy.edit() as (log_odds, observed):
            for t in np.arange(-self._base.radius_m, self._base.radius_m + 1e-9, grid.resolution_m):
                x, y = centre + t * across
                region = grid.box_slices(np.array([x - half, y - half, 0.0]), np.array([x + half, y + half, 0.5]))
                log_odds[region] = c.clamp_max
                observed[region] = True

    def _result(self, run: _Run, status: Status, reason: str) -> NavigationResult:
        log.info("navigation to (%.2f, %.2f): %s (%s) after %d steps, %.2f m, %d looks for the map", *run.goal,
                 status, reason, run.steps, run.distance_m, run.relocalizations)
        processing_s = time.perf_counter() - run.wall_start_s - (self.waiting_s - run.waiting_start_s)
        return NavigationResult(status, reason, self.pose, self._odom, run.distance_m,
                                run.last_time_s - run.start_time_s, processing_s, run.steps, run.stalls,
                                self.matches_accepted - run.matches[0], self.matches_tried - run.matches[1])


def _free_prefix(floor: FloorMap, here: Point, path: list[Point], max_m: float) -> Point | None:
    """The farthest point along ``path`` (within ``max_m``) reachable from ``here`` in a straight free line."""
    best = None
    for p, q in zip(path[:-1], path[1:]):
        for t in np.linspace(0.0, 1.0, max(2, int(math.dist(p, q) / 0.05) + 1)):
            point = (p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1]))
            if math.dist(here, point) > max_m or not segment_is_free(floor, here, point):
                return best
            best = point
    return best


def retry_busy(command: Callable[..., T], *args: float, attempts: int = 20, wait_s: float = 0.02) -> T:
    """Send a command, again while the device says it is busy: the agent replies to a motion a moment
    before it marks the base free, so a command sent straight after a reply can be refused."""
    for _ in range(attempts - 1):
        try:
            return command(*args)
        except CommandError as exc:
            if exc.code != "busy":
                raise
            time.sleep(wait_s)
    return command(*args)

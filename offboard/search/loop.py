"""The search, end to end: capture → stereo → occupancy → detection → belief → decide → command.

One :class:`Search` drives one robot until the target is found — the belief puts at least
``found_prob`` (``located_found_prob`` for a confident detection with stereo depth) within
``found_radius_m`` of a detection (a detection is a Bayesian observation,
:mod:`offboard.planning.detection_model`, so a weak one is confirmed by another look) — the time
budget K is spent, or no reachable action is worth its time.

Time is honest: every action's motion (robot clock: driving, slewing, capture) and its processing
(wall clock: capture transfer, stereo, detection, mapping, the belief's update and the dynamic
priors', planning) are measured and reported apart; the planner's t(f) includes the mean processing
measured so far. On a robot whose clock is the wall clock (``Info.wall_clock``: hardware, a paced
simulator) processing passes on that clock too: motion is robot time less the processing within it,
and the budget K counts robot time alone.
The environment is unknown: the planner never reads a world file, only the room's boundary
(report §3.1: "we assume that boundaries of Ω are known exactly").

Between positions, every frame the navigator takes toward the motion is searched too (a *glance*: the
detector and Bayes, as for a look, but not chosen by the planner and not counted as an action); a
detection on the way stops the move.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from collections.abc import Callable
from typing import Literal, Protocol

import numpy as np

from offboard.navigation import grid_planner
from offboard.planning import priors
from offboard.planning.belief import TargetBelief
from offboard.perception.detectability import DetectabilityTable
from offboard.perception.detection.detector import Detector
from offboard.planning.detection_function import look_footprint, visible_depth
from offboard.planning.detection_model import depth_sigma_m, detection_likelihood, located_along_rays, located_at_point
from offboard.navigation.localization import PoseTracker
from offboard.navigation.navigator import Navigator
from offboard.perception.occupancy import OccupancyConfig, OccupancyGrid
from offboard.perception.observation import Observation, Perception
from offboard.planning.planner import Decision, PlannerConfig, SearchPlanner, Views
from offboard.search.recording import Recorder
from offboard.robot.robot_client import RobotClient
from offboard.perception.stereo import StereoConfig, StereoMatcher
from offboard.planning.time_model import TimeModel
from offboard.search.top_view import LookTrace, draw_top_view
from offboard.perception.voxel_grid import VoxelGrid
from shared.config import ConfigError, load_config
from shared.geometry import Pose2D, RigidTransform
from shared.messages import Capture, RobotState
from shared.strict import bounds
from shared.world import MAX_ROOM_SIDE_M

log = logging.getLogger(__name__)
_NOMINAL_DRIVE_M = 2.0  # the weight of the nominal driving rate: one short run moves the estimate halfway


ROOM_SIDE_M = (0.5, MAX_ROOM_SIDE_M)  # the search region's sides
MAX_CUBES = 20_000_000  # about 1 GB of belief, map and their caches: a 25 × 20 × 4 m hall in 5 cm cubes


@dataclass(frozen=True)
class SearchConfig:
    room_m: tuple[float, float, float] = (9.0, 5.0, 2.5)  # the search region's known boundary
    resolution_m: float = field(default=0.05, metadata=bounds(0.01, 0.5))  # cube edge (report: 5 cm)
    facing_sectors: int = field(default=8, metadata=bounds(1, 36))  # 1: the target faces the camera
    prob_outside: float = field(default=0.05, metadata=bounds(0.0, 0.99))  # p(c_out) at the start
    detector: Literal["sift", "ncc", "auto"] = "sift"
    found_prob: float = field(default=0.95, metadata=bounds(0.5, 1.0))  # belief near a detection to call it found
    # ... near a confident detection that stereo located: it seldom errs, and a second view of it cost a look
    # and metres for nothing (dev, session 56: 0.8 against 0.95, SPL +0.012 and 0.5 looks fewer)
    located_found_prob: float = field(default=0.8, metadata=bounds(0.5, 1.0))
    # ... within this of it: wider than a located detection's spread (3 σ of its depth: 0.35 m at 2.6 m),
    # or even decisive evidence falls short and the robot drives on to confirm; the harness's success radius
    found_radius_m: float = field(default=0.5, metadata=bounds(0.05, 2.0))
    # α of a confident detection: a floor below the calibration's bound (0 of 200 negatives, 3/200 at 95 %),
    # since no detector is infallible and a confident one errs less than any detection
    false_positive_rate: float = field(default=0.005, metadata=bounds(1e-6, 0.5))
    # α of a weak detection: the calibration's bound for any detection, 3/200 (rule of three: none in its
    # 200 views without the target); until session 56 a guess of 0.1, which let a weak detection at the
    # target gather 5 % of the belief, and the search drove on
    weak_false_positive_rate: float = field(default=0.015, metadata=bounds(1e-6, 0.9))
    detection_sigma_m: float = field(default=0.1, metadata=bounds(0.01, 2.0))  # located centre's error, near
    empty_log_odds: float = field(default=-0.8, metadata=bounds(-20.0, 0.0))  # seen empty: no target centre there
    empty_factor: float = field(default=0.05, metadata=bounds(0.0, 1.0))  # what such a cube keeps (stereo errs); 1: off
    # ... unless this near anything not seen empty: a target rests on something, so its centre is never
    # farther than its half size (0.115 m) from a surface; rounded up to a cube
    empty_margin_m: float = field(default=0.15, metadata=bounds(0.0, 1.0))
    # ... and it stands on a horizontal surface: only space just above one (a table, a shelf, the floor,
    # or unknown space) keeps it; False: space near a wall or the ceiling too (a target hung on a wall)
    resting_target: bool = True
    # a picture faces open space: a facing with a mapped surface just in front of it keeps this share of
    # its mass (the map errs); 1: off. "Just in front" starts blocked_facing_gap_m beyond the target's
    # own face (and a cube), since stereo maps that face nearer than it is: with a gap of 0.05 m the
    # picture's own facing was blocked in 4 of 8 dev rooms; with 0.1 m, at a cube next to its centre in
    # 14 of 32; with 0.15 m, nowhere. It reaches blocked_facing_reach_m further
    blocked_facing_factor: float = field(default=0.1, metadata=bounds(0.0, 1.0))
    blocked_facing_gap_m: float = field(default=0.15, metadata=bounds(0.0, 1.0))
    blocked_facing_reach_m: float = field(default=0.15, metadata=bounds(0.01, 1.0))
    # a guard against a runaway loop, not the budget: K (planner.budget_s) ends a search long before (a look
    # takes at least 0.7 s of it); 150 once stopped the baselines after 5 min of a 30 min budget
    max_actions: int = field(default=3000, metadata=bounds(1, 10_000))
    # 0: the planner's t(f) takes the processing measured so far (wall clock, so decisions depend on how
    # loaded the machine is); > 0: this processing per look and none along moves, so a run repeats exactly,
    # up to the budget: K counts the processing measured (elapsed_s), so where a run stops at K can vary
    planned_processing_s: float = field(default=0.0, metadata=bounds(0.0, 60.0))
    planning_block_m: float = field(default=0.2, metadata=bounds(0.05, 2.0))  # the planner reads the belief in blocks
    max_planning_blocks: int = field(default=16_000, metadata=bounds(100, 10_000_000))  # larger rooms: larger blocks
    planner: PlannerConfig = PlannerConfig()
    occupancy: OccupancyConfig = OccupancyConfig()
    stereo: StereoConfig = StereoConfig()

    def __post_init__(self) -> None:
        # here, not as field bounds: a request's room (--room, a world's) replaces the file's after loading
        lo, hi = ROOM_SIDE_M
        if not all(lo <= side <= hi for side in self.room_m):
            raise ConfigError("room_m", self.room_m, f"each side must be {lo:g} to {hi:g} m")
        cubes = math.prod(math.ceil(side / self.resolution_m) for side in self.room_m)
        if cubes > MAX_CUBES:
            raise ConfigError("room_m", self.room_m, f"{cubes:,} cubes of {self.resolution_m:g} m, more than "
                                                     f"{MAX_CUBES:,}: give a coarser resolution_m")


class Policy(Protocol):
    """What chooses the next action: the SYT planner, or a baseline built around it (experiments)."""

    def decide(self, pose: Pose2D, pan_rad: float, tilt_rad: float, elapsed_s: float, occupancy: OccupancyGrid,
               path_lengths_m: np.ndarray, taken: frozenset[int] = frozenset(),
               views: Views = ()) -> Decision: ...


@dataclass
class SearchState:
    """What has happened so far (the summary and the top view are made from it)."""

    status: str = "running"
    found: bool = False
    actions: int = 0
    positions: list[tuple[float, float]] = field(default_factory=list)
    distance_m: float = 0.0
    planning_ms: list[float] = field(default_factory=list)
    looks: list[LookTrace] = field(default_factory=list)
    trail: list[tuple[float, float]] = field(default_factory=list)
    estimate_m: np.ndarray | None = None
    unreachable: list[tuple[float, float]] = field(default_factory=list)  # goals the navigator could not reach
    taken: set[int] = field(default_factory=set)  # settings looked at since the robot last moved
    views: list[tuple[float, float, int]] = field(default_factory=list)  # (x, y, setting): not taken again there
    motion_s: float = 0.0  # robot clock: driving, slewing, capture
    processing_s: float = 0.0  # wall clock: capture transfer, stereo, detection, mapping, updates, planning
    driving_s: float = 0.0  # moves between positions: robot clock, and processing unless planned_processing_s is set
    look_log: list[dict] = field(default_factory=list)  # per look: expected and realised P, times
    glances: int = 0  # frames the navigator took toward the motion, searched on the way (not looks)
    widened: bool = False  # the planner added its fallback tilts (SearchPlanner.widen)

    def took(self, setting: int, at_m: tuple[float, float]) -> None:
        """Book a look at ``setting`` from ``at_m``, where the robot stands: it is not taken again from
        there, on this stay or a later one (``views``). A detection too is confirmed only from another
        view: the same image again (rendered exactly again, or captured again from the same pose) would
        repeat the detector's answer, right or wrong, and the update would count it as a second one."""
        self.taken.add(setting)
        self.views.append((at_m[0], at_m[1], setting))

    def moved(self) -> None:
        """Every setting is new again from a new position, except the ``views`` taken near it before."""
        self.taken.clear()


class Search:
    def __init__(self, robot: RobotClient, config: SearchConfig, detectors: dict[str, tuple[Detector, DetectabilityTable]],
                 prior: np.ndarray, dynamic: list, recorder: Recorder | None = None, target_depth_m: float = 0.23,
                 policy: Callable[[SearchPlanner], Policy] | None = None):
        self.robot = robot
        self.config = config
        # the belief's facing sectors stand for every facing in them (DetectabilityTable.for_sectors)
        self.detectors = {name: (detector, table.for_sectors(config.facing_sectors))
                          for name, (detector, table) in detectors.items()}
        self.dynamic_priors = dynamic
        self.recorder = recorder
        self.target_depth_m = target_depth_m
        info = robot.info()
        self.info = info
        self.mount = info.mount.to_mount()
        self.intrinsics = info.intrinsics.to_intrinsics()
        self.occupancy, self.belief = starting_maps(config, prior, target_depth_m)
        self.time_model = TimeModel(info.base, info.pantilt, info.camera)
        self.planner = SearchPlanner(self.belief, config.planner, self._planning_table(), self.time_model,
                                     self.intrinsics, self.mount)
        self.policy: Policy = policy(self.planner) if policy else self.planner
        self.perception = Perception(self.occupancy, StereoMatcher(config.stereo))
        start = robot.state()
        self._clock_start_s = start.robot_time_s
        self.tracker = PoseTracker(start.pose.to_pose())
        self.navigator = Navigator(robot, self.occupancy, self.tracker, stereo=config.stereo)
        self.state = SearchState()
        if config.planned_processing_s:
            self.planner.set_processing_s(config.planned_processing_s)
        self.measure_driving()
        self.last_footprint = None
        self._pan_tilt = head_rad(start)
        self._plans_positions = policy is None  # baselines keep the report's fixed grid
        self._pending_processing_s = 0.0  # planning done towards the coming look
        self._seen: list[RigidTransform] = []  # the camera poses of the looks and glances so far, in odometry
        self._glance_recording_s = 0.0  # wall time logging glances during the current move
        # a move chosen on the bare radius (_choose): its goal, and whether past obstacles seen once or twice
        self._squeeze_to: tuple[tuple[float, float], bool] | None = None
        self.on_action: Callable[[Search], None] | None = None  # after every action (the checkpoint)

    # --- the loop ------------------------------------------------------------------------------------

    def run(self) -> SearchState:
        started = time.monotonic()
        if not self.state.trail:  # a resumed search has its start already
            pose = self._pose()
            self.state.trail.append((pose.x_m, pose.y_m))
            self.state.positions.append((pose.x_m, pose.y_m))
        if self.recorder:
            self.recorder.log_setup(self.config.room_m, self.intrinsics, self.mount)
        self._warm_up()
        while self.state.status == "running":
            if self.state.actions >= self.config.max_actions:
                self.state.status = "max_actions"
                break
            decision = self._decide()
            if decision.kind == "stop":
                self.state.status = decision.status
                log.info("search stops: %s", decision.reason)
            elif decision.kind == "move":
                self._move(decision)
            else:
                self._look(decision)
            if self.on_action:
                self.on_action(self)
        # planning that no look followed: the decision to stop, a move that found the target on the way
        self.state.processing_s += self._pending_processing_s
        self._pending_processing_s = 0.0
        self.wall_time_s = time.monotonic() - started
        return self.state

    def robot_time_s(self) -> float:
        return self.robot.state().robot_time_s - self._clock_start_s

    def elapsed_s(self) -> float:
        """Time spent so far, as the budget K counts it: robot motion plus measured processing (on a
        robot whose clock is the wall clock, processing is already in its time)."""
        return self.robot_time_s() + (0.0 if self.info.wall_clock else self.state.processing_s)

    def _motion_s(self, robot_s: float, processing_s: float) -> float:
        """The motion in ``robot_s`` of robot time, ``processing_s`` of processing done within the same
        span: on a wall clock that processing passed on the robot's clock too."""
        return max(0.0, robot_s - processing_s) if self.info.wall_clock else robot_s

    def _pose(self) -> Pose2D:
        return self.tracker.world_pose(self.robot.state().pose.to_pose())

    def _warm_up(self) -> None:
        """Compile the planner's and the look's kernels (or load them from numba's cache) before the
        search starts, so that the first decision costs what every other one does."""
        started = time.perf_counter()
        self._choose_on(self._pose(), squeeze=False, policy=self.planner)  # a baseline's state is left alone
        camera = self.mount.camera_in_world(self._pose(), *self._pan_tilt)
        table = self._planning_table()
        depth = visible_depth(None, self.occupancy, camera, self.intrinsics, self.mount.baseline_m, 16, table.range_m[1])
        look_footprint(self.occupancy.grid, camera, self.intrinsics, depth, 16, table, self.belief.facing_azimuths_rad,
                       self.config.planner.behind_surface_m)
        log.info("planner ready in %.0f ms", (time.perf_counter() - started) * 1000.0)

    def _choose(self, pose: Pose2D) -> Decision:
        """The policy's next action from ``pose``, on the current maps. A policy that would stop for want
        of a reachable position chooses again on the navigator's bare radius (``squeeze``): the margin
        can shut on the map a way out that is open in truth, and the robot then squeezes through it.
        Its last resort, once nothing is left where it can go, is to choose past the obstacles seen in
        one or two frames only (``confident``): a stereo ghost in a narrow way out seals it on the map
        (a generated room's start pocket, session 60), and looks ahead on the way see a real one again."""
        decision = self._choose_on(pose, squeeze=False)
        if decision.kind == "stop" and decision.status == "exhausted":
            decision = self._squeezed(pose, confident=False)
        if decision.kind == "stop" and decision.status == "exhausted" and self._plans_positions and self.planner.widen():
            self.state.widened = True
            log.info("nothing is left worth a look at the usual tilts, with P = %.3f inside the room: adding tilts %s",
                     self.belief.prob_inside, list(self.config.planner.fallback_tilts_deg))
            return self._choose(pose)
        if decision.kind == "stop" and decision.status == "exhausted":
            decision = self._squeezed(pose, confident=True)
        return decision

    def _squeezed(self, pose: Pose2D, confident: bool) -> Decision:
        """:meth:`_choose_on` the bare radius (``confident``: past obstacles seen once or twice); a move
        chosen so is driven so."""
        decision = self._choose_on(pose, squeeze=True, confident=confident)
        if decision.kind == "move":
            log.info("boxed in by the navigator's margin: squeezing through on its bare radius%s",
                     ", past obstacles seen in one or two frames only" if confident else "")
            self._squeeze_to = (decision.position_m, confident)
        return decision

    def _choose_on(self, pose: Pose2D, squeeze: bool, policy: Policy | None = None,
                   confident: bool = False) -> Decision:
        floor = self.navigator.floor_map(squeeze, confident)  # the navigator's: a path here is one it drives
        if self._plans_positions:
            # the full clearance even when squeezing: the aimed viewpoints' geometry is cached per margin
            self.planner.plan_positions(pose, floor, self.navigator.clearance_m())
        paths = grid_planner.path_lengths(floor, (pose.x_m, pose.y_m), self.planner.positions)
        for goal in self.state.unreachable:
            paths[np.hypot(*(self.planner.positions - goal).T) < self.config.planner.same_position_m] = np.inf
        return (policy or self.policy).decide(pose, *self._pan_tilt, self.elapsed_s(), self.occupancy, paths,
                                              frozenset(self.state.taken), tuple(self.state.views))

    def _decide(self) -> Decision:
        pose = self._pose()
        started = time.perf_counter()
        decision = self._choose(pose)
        planning_s = time.perf_counter() - started
        self.state.planning_ms.append(planning_s * 1000.0)
        self._pending_processing_s += planning_s
        log.info("decision %d: %s — %s (P=%.3f, t=%.1f s)", len(self.state.planning_ms), decision.kind,
                 decision.reason, decision.find_prob, decision.time_s)
        if self.recorder and decision.values is not None:
            self.recorder.log_plan(decision.values, self.planner.positions, self.belief.grid)
        return decision

    def _move(self, decision: Decision) -> None:
        goal = decision.position_m
        before = self.robot_time_s()
        squeezed = self._squeeze_to is not None and self._squeeze_to[0] == goal
        result = self.navigator.go_to(goal, squeeze=squeezed, observe=self._glance,
                                      confident=squeezed and self._squeeze_to[1])
        self._squeeze_to = None
        processing_s, self._glance_recording_s = result.processing_s - self._glance_recording_s, 0.0
        motion_s = self._motion_s(self.robot_time_s() - before, result.processing_s)
        self.state.motion_s += motion_s
        self.state.processing_s += processing_s
        self.state.driving_s += motion_s + (0.0 if self.config.planned_processing_s else processing_s)
        went = result.distance_m >= self.config.planner.same_position_m
        if went:  # a move that went nowhere changes no view, and is no new position
            self.state.moved()
        self.state.distance_m += result.distance_m
        self.measure_driving()
        self.state.trail.append((result.pose.x_m, result.pose.y_m))
        self._pan_tilt = head_rad(self.robot.state())  # the navigator turned the head toward the motion
        if went and result.status in ("reached", "interrupted"):
            self.state.positions.append((result.pose.x_m, result.pose.y_m))
        if result.status == "reached":
            self._look(decision)  # the look the move was chosen for
        elif result.status == "interrupted":  # a glance saw the target: decide again from here
            log.info("move stopped after %.2f m (%.2f m driven in all): %s", result.distance_m, self.state.distance_m,
                     result.reason)
        else:
            self.state.unreachable.append(tuple(goal))
            log.warning("position (%.1f, %.1f) not reached: %s (%s)", goal[0], goal[1], result.status, result.reason)

    def measure_driving(self) -> None:
        """Give the planner the time per metre that moves have taken so far (robot time, and the
        navigator's processing unless ``planned_processing_s`` is set), starting from its nominal rate,
        which counts as ``_NOMINAL_DRIVE_M`` metres driven."""
        s = self.state
        nominal = self.navigator.nominal_s_per_m()
        self.planner.set_drive_s_per_m((nominal * _NOMINAL_DRIVE_M + s.driving_s) / (_NOMINAL_DRIVE_M + s.distance_m))

    def _look(self, decision: Decision) -> None:
        pose = self._pose()
        before = self.robot_time_s()
        plan = self.time_model.look(pose.heading_rad, *self._pan_tilt, decision.azimuth_rad, decision.tilt_rad)
        if abs(plan.base_turn_rad) > 1e-3:
            self.robot.move(turn_deg=math.degrees(plan.base_turn_rad))
        self.robot.look(math.degrees(plan.pan_rad), math.degrees(plan.tilt_rad))
        self._pan_tilt = (plan.pan_rad, plan.tilt_rad)
        started = time.perf_counter()
        capture = self.robot.capture()
        motion_s = self._motion_s(self.robot_time_s() - before, time.perf_counter() - started)  # the transfer
        name, (detector, table) = self._choose_detector(decision)
        new = self._new_view(capture)
        obs = self.perception.observe(capture, self.tracker.world_pose(capture.pose.to_pose()),
                                      detector if new else None, update_map=new)
        self.state.actions += 1
        self.state.took(decision.setting, at_m=(pose.x_m, pose.y_m))
        if new:
            realised, found = self._interpret(obs, table)
            for prior in self.dynamic_priors:  # looks only: a glance repeats much of the last one's view, and
                factor = prior(obs, self)  # saliency multiplies in whatever each image shows
                if factor is not None:
                    self.belief.reweight(factor)
        else:
            realised, found = 0.0, False
            log.info("look %d: the same view as an earlier image, which says nothing new", self.state.actions)
        processing_s = self._pending_processing_s + time.perf_counter() - started  # the wall clock's part
        self._account(decision, obs, realised, motion_s, processing_s)
        self.state.looks.append(LookTrace(obs.pose.x_m, obs.pose.y_m, decision.azimuth_rad,
                                          math.degrees(decision.tilt_rad), table.range_m[1], found))
        self._record(obs, table)

    def _glance(self, capture: Capture, pose: Pose2D, disparity: np.ndarray) -> str:
        """Search a frame the navigator took toward the motion, as a look is searched: the detector,
        then Bayes. The frame is there anyway (the navigator maps with it), and a target on the way is
        seen before the robot drives past it. A detection stops the move, so the search decides again
        from there: a look to confirm it, or the target is found already. A view already seen (a move
        begun again from where the last one stopped) is skipped (:meth:`_new_view`)."""
        if not self._new_view(capture):
            return ""
        detector, table = self._planning_detector()
        obs = self.perception.observe(capture, pose, detector, update_map=False, disparity=disparity)
        _, found = self._interpret(obs, table, "glance after look")
        self.state.glances += 1
        started = time.perf_counter()
        self._record(obs, table, look=False)
        self._glance_recording_s += time.perf_counter() - started  # logging is not the search's processing
        if obs.detection is None:
            return ""
        return "the target found on the way" if found else "a detection on the way"

    def _new_view(self, capture: Capture) -> bool:
        """Whether ``capture`` shows a view no look or glance has shown yet (and remember it). The same
        view again (a pose the robot returned to, or a look taken again where it stands) gives the
        same image, rendered exactly again or captured again: the detector would repeat its answer,
        right or wrong, and the update would count it as new evidence. Views are compared where
        odometry puts them: a scan match between two images moves the corrected pose, not the camera."""
        view = self.mount.camera_in_world(capture.pose.to_pose(), math.radians(capture.pan_deg),
                                          math.radians(capture.tilt_deg))
        if any(same_view(view, earlier) for earlier in self._seen):
            return False
        self._seen.append(view)
        return True

    def _account(self, decision: Decision, obs: Observation, realised: float, motion_s: float,
                 processing_s: float) -> None:
        """Book the look's times (the planner's t(f) takes the mean processing of a look from now on)
        and log what the planner expected of it beside what the exact update found."""
        s = self.state
        s.motion_s += motion_s
        s.processing_s += processing_s
        self._pending_processing_s = 0.0
        s.look_log.append({"action": s.actions, "expected_p": round(float(decision.find_prob), 6),
                           "realised_p": round(float(realised), 6), "detected": obs.detection is not None,
                           "processing_s": round(processing_s, 4), "motion_s": round(motion_s, 4),
                           "x_m": round(obs.pose.x_m, 3), "y_m": round(obs.pose.y_m, 3),
                           "heading_deg": round(math.degrees(obs.pose.heading_rad), 2), "setting": decision.setting,
                           "pan_deg": round(obs.capture.pan_deg, 2), "tilt_deg": round(obs.capture.tilt_deg, 2),
                           **{stage: round(ms, 1) for stage, ms in obs.timings_ms.items()}})
        if not self.config.planned_processing_s:
            self.planner.set_processing_s(float(np.mean([look["processing_s"] for look in s.look_log])))

    def _interpret(self, obs: Observation, table: DetectabilityTable, what: str = "look") -> tuple[float, bool]:
        """Bayes on what the look (or glance) saw: eq. 4 after a miss, the detection model after a
        detection. Returns the realised detection probability (eq. 1 over what it actually saw, before
        the update) and whether the target now counts as found."""
        near, far = table.range_m
        depth = visible_depth(obs.disparity, self.occupancy, obs.camera_in_world, obs.intrinsics,
                              obs.baseline_m, 16, far)
        footprint = look_footprint(self.occupancy.grid, obs.camera_in_world, obs.intrinsics, depth, 16, table,
                                   self.belief.facing_azimuths_rad, self.config.planner.behind_surface_m)
        self.last_footprint = footprint
        if obs.detection is None:
            realised = self.belief.update_after_miss(footprint.cube_index, footprint.detection_prob)
            log.info("%s %d: no target; it could have found it with probability %.3f; P[F] = %.3f",
                     what, self.state.actions, realised, self.belief.success_prob)
            found = False
        else:
            realised = self.belief.expected_detection(footprint.cube_index, footprint.detection_prob)
            found = self._detected(obs, table, footprint)
        fold_in_map(self.belief, self.occupancy, self.config, self.target_depth_m)
        return realised, found

    def _detected(self, obs: Observation, table: DetectabilityTable, footprint) -> bool:
        """Fold a detection into the belief; found once the belief is sure enough near it."""
        grid, confident = self.occupancy.grid, obs.detection.confident
        alpha = max(table.false_positive_rate, self.config.false_positive_rate if confident
                    else self.config.weak_false_positive_rate)
        if obs.target_m is not None:
            obs = self._to_target_centre(obs)
            distance = float(np.linalg.norm(obs.target_m - obs.camera_in_world.translation))
            sigma = depth_sigma_m(distance, obs.intrinsics, obs.baseline_m, self.config.detection_sigma_m)
            located = located_at_point(grid, footprint.cube_index, obs.target_m, sigma)
        else:
            located = located_along_rays(grid, footprint.cube_index, obs.detection.box_px, obs.camera_in_world,
                                         obs.intrinsics)
        self.belief.observe(footprint.cube_index, detection_likelihood(
            footprint.cube_index, footprint.detection_prob, located, alpha))
        estimate = obs.target_m
        if estimate is None:
            # the likeliest cube on its rays (where rays from two views cross), not anywhere in the room,
            # where a strong prior alone would make any detection a find
            on_rays = footprint.cube_index[located > 0]
            log.info("%s detection without stereo depth: the belief gathers along its rays (%d cubes)",
                     obs.detection.detector, len(on_rays))
            if not len(on_rays):  # a box no cube centre of the view projects into
                return False
            estimate = self._most_likely_m(on_rays)
        near = self.belief.mass_near(estimate, self.config.found_radius_m)
        self.state.estimate_m = estimate
        needed = self.config.located_found_prob if confident and obs.target_m is not None else self.config.found_prob
        if near >= needed:
            self.state.status, self.state.found = "found", True
            log.info("target found at %s (P within %.2f m: %.3f)", np.round(estimate, 2), self.config.found_radius_m, near)
            return True
        log.info("%s detection after %d looks and %.2f m, estimate %s: P within %.2f m is %.3f < %.2f; looking on",
                 "confident" if confident else "weak", self.state.actions, self.state.distance_m,
                 np.round(estimate, 2), self.config.found_radius_m, near, needed)
        return False

    def _most_likely_m(self, cubes: np.ndarray) -> np.ndarray:
        """Centre of the cube, among ``cubes`` (flat indices), the belief holds most likely to hold the
        target's centre."""
        p = self.belief.target_prob
        best = cubes[int(np.argmax(p.ravel()[cubes]))]
        return self.occupancy.grid.center_of(np.array(np.unravel_index(int(best), p.shape)))

    def _to_target_centre(self, obs: Observation) -> Observation:
        """The detection locates the pictured face; the target's centre is half its depth behind it,
        along the viewing ray (the face is seen roughly head-on when it is detected at all)."""
        ray = obs.target_m - obs.camera_in_world.translation
        ray[2] = 0.0
        norm = np.linalg.norm(ray)
        if norm < 1e-6:
            return obs
        centre = obs.target_m + ray / norm * (self.target_depth_m / 2.0)
        return dataclasses.replace(obs, target_m=centre)

    def _choose_detector(self, decision: Decision) -> tuple[str, tuple[Detector, DetectabilityTable]]:
        """``auto``: the detector with the best expected detection per second for this look
        (the report's future work); otherwise the configured one."""
        if self.config.detector != "auto":
            return self.config.detector, self.detectors[self.config.detector]
        best, best_value = None, -1.0
        for name, (detector, table) in self.detectors.items():
            scale = table.rate.max() / max(self.planner.table.rate.max(), 1e-9)
            value = decision.find_prob * scale / (decision.time_s + detector.cost_ms / 1000.0)
            if value > best_value:
                best, best_value = name, value
        return best, self.detectors[best]

    def _planning_detector(self) -> tuple[Detector, DetectabilityTable]:
        """The configured detector; under ``auto``, the one of longest range, which the planner plans with."""
        if self.config.detector != "auto":
            return self.detectors[self.config.detector]
        return max(self.detectors.values(), key=lambda pair: pair[1].range_m[1])

    def _planning_table(self) -> DetectabilityTable:
        return self._planning_detector()[1]

    def _record(self, obs: Observation, table: DetectabilityTable, look: bool = True) -> None:
        """Log what an image showed and the maps after it: a look on the ``action`` timeline, a glance
        on the robot's clock only (on the ``action`` timeline it would hide the look before it)."""
        if not self.recorder:
            return
        r = self.recorder
        r.set_time(self.state.actions if look else None, self.robot_time_s())
        r.log_pose(obs.pose, math.radians(obs.capture.pan_deg), math.radians(obs.capture.tilt_deg), self.mount)
        r.log_observation(obs, table.range_m[1])
        r.log_maps(self.belief, self.occupancy)
        r.log_stats(success_prob=self.belief.success_prob, prob_outside=self.belief.prob_outside,
                    planning_ms=self.state.planning_ms[-1] if self.state.planning_ms else 0.0,
                    distance_m=self.state.distance_m)
        if self.state.estimate_m is not None:
            r.log_target(self.state.estimate_m)

    # --- outputs -------------------------------------------------------------------------------------

    def summary(self) -> dict:
        s = self.state
        ms = np.array(s.planning_ms) if s.planning_ms else np.zeros(1)
        return {
            "found": s.found,
            "status": s.status,
            "actions": s.actions,
            "positions_visited": len(s.positions),
            "distance_m": round(s.distance_m, 3),
            "robot_time_s": round(self.robot_time_s(), 3),
            "motion_time_s": round(s.motion_s, 3),
            "processing_time_s": round(s.processing_s, 3),
            "wall_time_s": round(getattr(self, "wall_time_s", 0.0), 3),
            "planning_ms_p50": round(float(np.percentile(ms, 50)), 2),
            "planning_ms_p95": round(float(np.percentile(ms, 95)), 2),
            "target_estimate_m": None if s.estimate_m is None else [round(float(v), 3) for v in s.estimate_m],
            "prob_outside": round(float(self.belief.prob_outside), 6),
            "prob_inside": round(float(self.belief.prob_inside), 6),
            "success_prob": round(float(self.belief.success_prob), 6),
            "cost_function": self.config.planner.cost_function,
            "detector": self.config.detector,
            "decisions": len(s.planning_ms),
            "glances": s.glances,
        }

    def write_top_view(self, path: Path) -> None:
        s = self.state
        floor = self.occupancy.floor_map(self.info.base.radius_m, self.info.base.height_m)
        title = (f"{s.status}: {s.actions} looks, {len(s.positions)} positions, {s.distance_m:.1f} m, "
                 f"{self.robot_time_s() / 60:.1f} min robot time")
        draw_top_view(path, self.config.room_m, floor, s.trail, s.looks, self.intrinsics.hfov_rad, s.estimate_m, title)


def head_rad(state: RobotState) -> tuple[float, float]:
    """The pan and tilt a robot reports, in radians."""
    return math.radians(state.pan_deg), math.radians(state.tilt_deg)


def same_view(a: RigidTransform, b: RigidTransform, within_m: float = 0.05, within_deg: float = 3.0) -> bool:
    """Two camera poses close enough that their images show the same thing."""
    axes = a.rotation[:, 2] @ b.rotation[:, 2]  # the optical axes (camera z)
    return bool(np.linalg.norm(a.translation - b.translation) <= within_m
                and axes >= math.cos(math.radians(within_deg)))


def seen_empty(occupancy: OccupancyGrid, config: SearchConfig) -> np.ndarray:
    """The cubes whose target mass :meth:`TargetBelief.rule_out_empty` takes away: seen empty, and at
    least ``empty_margin_m`` from anything that is not or, for a ``resting_target``, from the top of
    anything it could stand on (see :meth:`OccupancyGrid.seen_empty`)."""
    return occupancy.seen_empty(config.empty_log_odds, round(config.empty_margin_m / config.resolution_m),
                                config.resting_target)


def starting_maps(config: SearchConfig, prior: np.ndarray, target_depth_m: float) -> tuple[OccupancyGrid, TargetBelief]:
    """A search's maps before its first look: nothing mapped, and the belief ``prior`` with no
    picture facing into a wall."""
    grid = VoxelGrid(config.room_m, config.resolution_m)
    belief = TargetBelief(grid, config.facing_sectors, config.prob_outside, coarse_factor=planning_block_factor(config))
    belief.set_prior(prior, config.prob_outside)
    belief.exclude_facings_into_walls(facing_clearance_m(target_depth_m, config))
    return OccupancyGrid(grid, config.occupancy), belief


def fold_in_map(belief: TargetBelief, occupancy: OccupancyGrid, config: SearchConfig, target_depth_m: float) -> None:
    """What the map says about the target after a look: no centre where stereo saw through, and no
    picture facing a surface it almost touches."""
    if config.empty_factor < 1.0:
        belief.rule_out_empty(seen_empty(occupancy, config), config.empty_factor)
    if config.blocked_facing_factor < 1.0:
        near = facing_clearance_m(target_depth_m, config) + config.blocked_facing_gap_m
        belief.rule_out_blocked_facings(occupancy.occupied(), near, near + config.blocked_facing_reach_m,
                                        config.blocked_facing_factor)


def facing_clearance_m(target_depth_m: float, config: SearchConfig) -> float:
    """How far in front of a cube's centre a picture centred there is clear of its own body: half
    the target's depth and a cube for the map's rounding."""
    return target_depth_m / 2 + config.resolution_m


def planning_block_factor(config: SearchConfig) -> int:
    """Cubes per edge of the blocks the planner reads (:meth:`TargetBelief.coarse_mass`): about
    ``planning_block_m``, larger in a room that would otherwise have more than
    ``max_planning_blocks`` of them (a decision's cost grows with the blocks it scores)."""
    volume = math.prod(config.room_m)
    edge_m = max(config.planning_block_m, (volume / config.max_planning_blocks) ** (1 / 3))
    return max(1, math.ceil(edge_m / config.resolution_m - 1e-9))


PRIOR_KINDS = ("uniform", "hints", "last-seen", "surfaces", "saliency")


def check_prior_spec(spec: str) -> str:
    """``spec`` if it is a prior that :func:`build_prior` or ``dynamic_priors`` builds; else a
    ValueError naming what is wrong with it."""
    kind, colon, arg = spec.partition(":")
    if kind not in PRIOR_KINDS:
        raise ValueError(f"prior {spec!r}: unknown kind {kind!r} (kinds: {', '.join(PRIOR_KINDS)})")
    if kind == "hints":
        if not arg:
            raise ValueError(f"prior {spec!r}: hints needs a file, hints:FILE")
    elif kind == "last-seen":
        try:
            values = [float(v) for v in arg.split(",")]
        except ValueError:
            values = []
        if len(values) not in (3, 4) or not all(math.isfinite(v) for v in values):
            raise ValueError(f"prior {spec!r}: last-seen needs 3 or 4 numbers, last-seen:X,Y,Z[,SECONDS]")
    elif colon:
        raise ValueError(f"prior {spec!r}: {kind} takes no argument")
    return spec


def build_prior(grid: VoxelGrid, specs: list[str]) -> np.ndarray:
    """The static priors among ``--prior`` specs, mixed with equal weights: ``uniform``, ``hints:FILE``,
    ``last-seen:X,Y,Z[,SECONDS]`` (uniform if there is none). ``surfaces`` and ``saliency`` are
    dynamic and left to ``offboard.search.run.dynamic_priors``."""
    weighted = []
    for spec in map(check_prior_spec, specs):
        kind, _, arg = spec.partition(":")
        if kind == "uniform":
            weighted.append((1.0, priors.uniform(grid)))
        elif kind == "hints":
            boxes = load_config(priors.HintsFile, Path(arg)).hint  # its errors name the file already
            try:
                weighted.append((1.0, priors.hints(grid, boxes)))
            except ValueError as exc:  # a box the room's cubes miss
                raise ConfigError(arg, None, str(exc)) from None
        elif kind == "last-seen":
            values = [float(v) for v in arg.split(",")]
            seconds = values[3] if len(values) > 3 else 0.0
            try:
                weighted.append((1.0, priors.last_seen(grid, np.array(values[:3]), seconds)))
            except ValueError as exc:
                raise ConfigError("--prior", spec, str(exc)) from None
    if not weighted:
        weighted.append((1.0, priors.uniform(grid)))
    return priors.combine(grid, weighted)

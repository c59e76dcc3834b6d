"""The SYT greedy search: where to look next and where to move next (report §3.3, §5.2.1).

Pure: it reads the belief and the occupancy map and returns a :class:`Decision`; driving the robot,
perception and logging belong to the caller.

Paper symbols, named once: ``Θ_move`` → ``move_threshold``; ``K`` → ``budget_s``; ``E(f)`` (eq. 3)
→ ``utility``; ``Prob_Ψj`` → ``covering_prob``; ``A`` of eq. 12 → ``distance_weight``.

The four cost functions of §5.2.1, selected by ``cost_function``:

1. (eq. 9) the action with the largest detection probability anywhere, however far;
2. (eq. 10) explore the current position first, then move to the position of largest covering
   probability;
3. (eq. 11) ... then to the position maximising covering probability over path distance;
4. (eq. 12) ... then maximising covering probability × (1 + A / distance).

"Explore the current position first" is eq. 3: at the current position, take the look of largest
E(f) = P_Ψ(f) / t(f) while the covering probability stays at or above Θ_move. Eq. 9 is read with
the detection probability of eq. 1 (Σ p·b), which is what the report's text calls it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from offboard.planning.action_values import ActionGeometry, ActionValues, CameraSettings, evaluate
from offboard.planning.belief import TargetBelief
from offboard.perception.detectability import DetectabilityTable
from offboard.perception.occupancy import OccupancyGrid
from offboard.planning.sensed_sphere import SphereBins, sensed_spheres
from offboard.planning.time_model import TimeModel
from shared.geometry import HeadMount, Intrinsics, Pose2D
from shared.strict import bounds


@dataclass(frozen=True)
class PlannerConfig:
    cost_function: Literal[1, 2, 3, 4] = 3  # the report's best (Tables 2 and 3)
    move_threshold: float = field(default=0.1, metadata=bounds(0.0, 1.0))  # Θ_move (paper, cost 3: 0.05-0.1 fastest)
    distance_weight: float = field(default=1.0, metadata=bounds(0.0, 1e3))  # A of eq. 12 (report: 1)
    budget_s: float = field(default=1800.0, metadata=bounds(1.0, 1e6))  # K, robot time
    min_detection_prob: float = field(default=2e-3, metadata=bounds(0.0, 1.0))  # below: not worth a look
    grid_spacing_m: float = field(default=1.0, metadata=bounds(0.1, 10.0))  # candidate positions
    tilts_deg: tuple[float, ...] = (0.0, 30.0)  # the report's two tilts
    view_overlap: float = field(default=0.4, metadata=bounds(0.0, 0.9))  # between neighbouring settings
    same_position_m: float = field(default=0.5, metadata=bounds(0.0, 5.0))  # "here" for a candidate
    unknown_is_opaque: bool = False  # expected sensed spheres: unknown space hides what is behind it
    sphere_resolution_m: float = field(default=0.1, metadata=bounds(0.01, 1.0))  # map used for radii


@dataclass(frozen=True)
class Decision:
    kind: Literal["look", "move", "stop"]
    reason: str
    azimuth_rad: float = 0.0  # the look (world azimuth, tilt); after a move, the first look there
    tilt_rad: float = 0.0
    position_m: tuple[float, float] | None = None  # where to move
    detection_prob: float = 0.0  # expected P_Ψ(f), eq. 1
    utility: float = 0.0  # the chosen cost function's value
    time_s: float = 0.0  # t(f)
    status: Literal["budget", "exhausted", ""] = ""
    covering_here: float = 0.0
    values: ActionValues | None = None  # candidates' rows first, the current position's last
    setting: int = -1  # index into the planner's camera settings


def candidate_positions(room_size_m: tuple[float, float, float], spacing_m: float) -> np.ndarray:
    """Interior vertices of the floor grid (report §3.3.3): 32 in a 9 × 5 m room at 1 m."""
    xs = np.arange(spacing_m, room_size_m[0] - 1e-9, spacing_m)
    ys = np.arange(spacing_m, room_size_m[1] - 1e-9, spacing_m)
    return np.array([(x, y) for x in xs for y in ys], float)


class SearchPlanner:
    def __init__(self, belief: TargetBelief, config: PlannerConfig, table: DetectabilityTable,
                 time_model: TimeModel, intrinsics: Intrinsics, mount: HeadMount):
        self.belief = belief
        self.config = config
        self.table = table
        self.time_model = time_model
        self.intrinsics = intrinsics
        self.mount = mount
        self.settings = CameraSettings.from_fov(intrinsics, config.tilts_deg, config.view_overlap)
        self.bins = SphereBins()
        self.positions = candidate_positions(belief.grid.size_m, config.grid_spacing_m)
        self._candidates = ActionGeometry(belief, self.positions, self.settings, mount, intrinsics, table, self.bins)

    @property
    def action_count(self) -> int:
        return len(self.positions) * len(self.settings)

    def decide(self, pose: Pose2D, pan_rad: float, tilt_rad: float, elapsed_s: float,
               occupancy: OccupancyGrid, path_lengths_m: np.ndarray, taken: frozenset[int] = frozenset()) -> Decision:
        """The next action from ``pose`` (pan-tilt at ``pan_rad``, ``tilt_rad``), ``elapsed_s`` into the
        search; ``path_lengths_m`` is the navigation distance to each candidate (inf: unreachable);
        ``taken``: the settings already looked at from this position (each is taken once, as in the
        report: the same view again would repeat what the belief already accounts for)."""
        values = self._values(pose, occupancy)
        if taken:
            values.detection_prob[-1, sorted(taken)] = 0.0
        here_detection = values.detection_prob[-1]
        # What looking on here can still find: no more than the looks not yet taken here would (the
        # covering also counts what the taken views left behind, which no look here will see again).
        here_covering = min(float(values.covering_prob[-1]), float(here_detection.sum()))
        values.covering_prob[-1] = here_covering
        look_t = self.time_model.look_times_s(pose.heading_rad, pan_rad, tilt_rad, self.settings.azimuth_rad,
                                              self.settings.tilt_rad)
        far_t = self._candidate_times(pose, path_lengths_m)
        best_anywhere = max(here_detection.max(), np.where(np.isfinite(far_t), values.detection_prob[:-1], 0).max())
        if best_anywhere < self.config.min_detection_prob:
            return Decision("stop", f"no reachable action finds the target with probability ≥ "
                                    f"{self.config.min_detection_prob:g}", status="exhausted",
                            covering_here=here_covering, values=values)
        if self.config.cost_function == 1:
            decision = self._eq9(values, look_t, far_t, here_covering)
        elif here_covering >= self.config.move_threshold and here_detection.max() >= self.config.min_detection_prob:
            decision = self._look_here(values, look_t, here_covering)
        else:
            why = (f"covering probability here {here_covering:.3f} < Θ_move {self.config.move_threshold:g}"
                   if here_covering < self.config.move_threshold else
                   f"no look left here finds it with probability ≥ {self.config.min_detection_prob:g}")
            decision = self._move(values, far_t, path_lengths_m, here_covering, pose, why)
        if elapsed_s + decision.time_s > self.config.budget_s:
            return Decision("stop", f"the next action ({decision.time_s:.1f} s) would exceed the budget "
                                    f"K = {self.config.budget_s:g} s", status="budget",
                            covering_here=here_covering, values=values)
        return decision

    # --- the pieces --------------------------------------------------------------------------------

    def _values(self, pose: Pose2D, occupancy: OccupancyGrid) -> ActionValues:
        near, far = self.table.range_m
        here = np.array([[pose.x_m, pose.y_m]])
        geometries = (self._candidates, ActionGeometry(self.belief, here, self.settings, self.mount,
                                                        self.intrinsics, self.table, self.bins))
        factor = max(1, round(self.config.sphere_resolution_m / occupancy.grid.resolution_m))
        coarse = occupancy.coarsened(factor)
        rows = []
        for geometry in geometries:
            spheres = sensed_spheres(coarse, geometry.centers_m, self.bins, near, far, self.config.unknown_is_opaque)
            rows.append(evaluate(geometry, self.belief, spheres))
        return ActionValues(np.vstack([r.detection_prob for r in rows]),
                            np.concatenate([r.covering_prob for r in rows]))

    def _candidate_times(self, pose: Pose2D, path_lengths_m: np.ndarray) -> np.ndarray:
        """t(f) of every (candidate, setting): travel along the path, then a look (heading on
        arrival taken as the direction of travel)."""
        times = np.full((len(self.positions), len(self.settings)), np.inf)
        for j, (x, y) in enumerate(self.positions):
            if not math.isfinite(path_lengths_m[j]):
                continue
            turn = pose.bearing_to(x, y) if pose.distance_to(x, y) > 1e-6 else 0.0
            travel = self.time_model.travel_s(path_lengths_m[j], turn)
            arrival = math.atan2(y - pose.y_m, x - pose.x_m)
            times[j] = travel + self.time_model.look_times_s(arrival, 0.0, 0.0, self.settings.azimuth_rad,
                                                             self.settings.tilt_rad)
        return times

    def _look_here(self, values: ActionValues, look_t: np.ndarray, covering: float) -> Decision:
        """Eq. 3: the look of largest E(f) = P_Ψ(f) / t(f) from where the robot stands."""
        detection = values.detection_prob[-1]
        utility = detection / look_t
        s = int(np.argmax(utility))
        return Decision("look", f"covering probability here {covering:.3f} ≥ Θ_move {self.config.move_threshold:g}",
                        self.settings.azimuth_rad[s], self.settings.tilt_rad[s], None, float(detection[s]),
                        float(utility[s]), float(look_t[s]), covering_here=covering, values=values, setting=s)

    def _eq9(self, values: ActionValues, look_t: np.ndarray, far_t: np.ndarray, covering: float) -> Decision:
        """Cost 1: the largest detection probability among all reachable actions, wherever they are."""
        far = np.where(np.isfinite(far_t), values.detection_prob[:-1], -1.0)
        here = values.detection_prob[-1]
        if here.max() >= far.max():
            s = int(np.argmax(here))
            return Decision("look", "eq. 9: the best action is here", self.settings.azimuth_rad[s],
                            self.settings.tilt_rad[s], None, float(here[s]), float(here[s]), float(look_t[s]),
                            covering_here=covering, values=values, setting=s)
        j, s = np.unravel_index(int(np.argmax(far)), far.shape)
        return Decision("move", f"eq. 9: the best action is at ({self.positions[j][0]:g}, {self.positions[j][1]:g})",
                        self.settings.azimuth_rad[s], self.settings.tilt_rad[s], tuple(self.positions[j]),
                        float(far[j, s]), float(far[j, s]), float(far_t[j, s]), covering_here=covering,
                        values=values)

    def _move(self, values: ActionValues, far_t: np.ndarray, path_lengths_m: np.ndarray, covering: float,
              pose: Pose2D, why: str) -> Decision:
        """Eq. 10-12: the next position, preferring those whose covering probability is at least
        Θ_move (the robot would leave any other at once); its first look is its best by eq. 3."""
        dist = np.asarray(path_lengths_m, float)
        away = np.hypot(self.positions[:, 0] - pose.x_m, self.positions[:, 1] - pose.y_m) > self.config.same_position_m
        usable = np.isfinite(dist) & away & (values.detection_prob[:-1].max(axis=1) >= self.config.min_detection_prob)
        if not usable.any():
            return Decision("stop", "no reachable position left whose looks are worth taking",
                            status="exhausted", covering_here=covering, values=values)
        cover = values.covering_prob[:-1]
        worth_staying = usable & (cover >= self.config.move_threshold)
        if worth_staying.any():  # where the robot would not leave again at once
            usable = worth_staying
        d = np.maximum(dist, 1e-6)
        score = {2: cover, 3: cover / d, 4: cover * (1.0 + self.config.distance_weight / d)}[self.config.cost_function]
        score = np.where(usable, score, -np.inf)
        j = int(np.argmax(score))
        first = values.detection_prob[j] / far_t[j]
        s = int(np.argmax(first))
        equation = {2: "eq. 10", 3: "eq. 11", 4: "eq. 12"}[self.config.cost_function]
        return Decision("move", f"{why}; {equation} picks ({self.positions[j][0]:g}, {self.positions[j][1]:g})",
                        self.settings.azimuth_rad[s], self.settings.tilt_rad[s], tuple(self.positions[j]),
                        float(values.detection_prob[j, s]), float(score[j]), float(far_t[j, s]),
                        covering_here=covering, values=values, setting=s)

"""The SYT greedy search: where to look next and where to move next (report §3.3, §5.2.1).

Pure: it reads the belief and the occupancy map and returns a :class:`Decision`; driving the robot,
perception and logging belong to the caller.

Paper symbols, named once: ``Θ_move`` → ``move_threshold``; ``K`` → ``budget_s``; ``P_Ψ(f)`` (eq. 1)
→ ``find_prob`` (see :mod:`offboard.planning.action_values`); ``E(f)`` (eq. 3) → ``utility`` of a
look (a move's ``utility`` is its cost function's score, eq. 10-12; cost 1's is P_Ψ(f), eq. 9);
``Prob_Ψj`` → ``covering_prob``; ``A`` of eq. 12 → ``distance_weight``.

The four cost functions of §5.2.1, selected by ``cost_function``:

1. (eq. 9) the action with the largest detection probability anywhere, however far;
2. (eq. 10) explore the current position first, then move to the position of largest covering
   probability;
3. (eq. 11) ... then to the position maximising covering probability over path distance;
4. (eq. 12) ... then maximising covering probability × (1 + A / distance).

"Explore the current position first" is eq. 3: at the current position, take the look of largest
E(f) = P_Ψ(f) / t(f). When to stop looking here is the ``move_rule``:

- ``"rate"`` (default): while the best look here finds more per second than the best visit
  elsewhere, travel included — eq. 3 applied over every action, a visit being the best few looks
  from one position. It needs no threshold, so it holds whether a look rules a place out at once
  (the report's target that faces the camera) or only for the facings it saw (a one-sided target).
  The visit must beat the look here by ``leave_margin``: the best visit overstates what the search
  finds per second after it (the visits that follow are worse), and leaving forfeits the looks left
  here, which after the move cost a trip back;
- ``"threshold"``: the report's rule, while the covering probability here is at least Θ_move.

Eq. 9 is read with the detection probability of eq. 1 (Σ p·b), which is what the report's text
calls it. Candidate positions are the report's grid vertices plus viewpoints aimed at the belief
(:mod:`offboard.planning.viewpoints`). The settings are the report's two tilts; a search that they
leave with nothing worth a look adds a tilt down once (:meth:`SearchPlanner.widen`) before it stops.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Literal

import numpy as np

from offboard.perception.detectability import DetectabilityTable
from offboard.perception.occupancy import FloorMap, OccupancyGrid
from offboard.planning.action_values import (ActionGeometry, ActionValues, CameraSettings, GeometryCache, block_centers,
                                             evaluate, heavy_blocks)
from offboard.planning.belief import TargetBelief
from offboard.planning.sensed_sphere import SphereBins, sensed_spheres
from offboard.planning.time_model import TimeModel
from offboard.planning.viewpoints import AimedViewpoints, best_distance_m, grid_vertices
from shared.geometry import HeadMount, Intrinsics, Pose2D
from shared.strict import bounds

Views = tuple[tuple[float, float, int], ...]  # (x, y, setting) of each view taken: not taken again near there


@dataclass(frozen=True)
class PlannerConfig:
    cost_function: Literal[1, 2, 3, 4] = 3  # the report's best (Tables 2 and 3)
    move_rule: Literal["rate", "threshold"] = "rate"  # when to leave: see the module docstring
    move_threshold: float = field(default=0.1, metadata=bounds(0.0, 1.0))  # Θ_move of the "threshold" rule
    distance_weight: float = field(default=1.0, metadata=bounds(0.0, 1e3))  # A of eq. 12 (report: 1)
    budget_s: float = field(default=1800.0, metadata=bounds(1.0, 1e6))  # K, robot time
    min_detection_prob: float = field(default=2e-3, metadata=bounds(0.0, 1.0))  # a look of smaller find_prob: not worth it
    grid_spacing_m: float = field(default=1.0, metadata=bounds(0.1, 10.0))  # the report's candidate positions
    max_vertices: int = field(default=40, metadata=bounds(1, 10_000))  # the grid vertices nearest the robot
    viewpoints: int = field(default=24, metadata=bounds(0, 1000))  # aimed at the belief, per decision
    viewpoint_lattice_m: float = field(default=0.25, metadata=bounds(0.05, 2.0))  # they snap to it (cached geometry)
    visit_looks: int = field(default=4, metadata=bounds(1, 64))  # the most looks a visit is credited with
    leave_margin: float = field(default=3.0, metadata=bounds(1.0, 100.0))  # the "rate" rule leaves when a visit
    # finds this many times more per second than the best look here
    tilts_deg: tuple[float, ...] = (0.0, 30.0)  # the report's two tilts
    # added once the tilts above leave nothing worth a look (widen); (): the search stops there
    fallback_tilts_deg: tuple[float, ...] = (-30.0,)
    view_overlap: float = field(default=0.4, metadata=bounds(0.0, 0.9))  # between neighbouring settings
    same_position_m: float = field(default=0.5, metadata=bounds(0.0, 5.0))  # "here" for a candidate
    behind_surface_m: float = field(default=0.12, metadata=bounds(0.0, 1.0))  # a target's centre lies behind its face:
    # what a look counts as seen reaches this far behind the surface, in expectation (sensed spheres) as in fact
    sphere_resolution_m: float = field(default=0.1, metadata=bounds(0.01, 1.0))  # map used for radii


@dataclass(frozen=True)
class Decision:
    kind: Literal["look", "move", "stop"]
    reason: str
    azimuth_rad: float = 0.0  # the look (world azimuth, tilt); after a move, the first look there
    tilt_rad: float = 0.0
    position_m: tuple[float, float] | None = None  # where to move
    find_prob: float = 0.0  # expected P_Ψ(f), eq. 1
    utility: float = 0.0  # a look's E(f) (eq. 3); a move's cost-function score (eq. 10-12); cost 1: P_Ψ(f)
    time_s: float = 0.0  # t(f)
    status: Literal["budget", "exhausted", ""] = ""
    covering_here: float = 0.0
    values: ActionValues | None = None  # candidates' rows first, the current position's last
    setting: int = -1  # index into the planner's camera settings


class SearchPlanner:
    def __init__(self, belief: TargetBelief, config: PlannerConfig, table: DetectabilityTable,
                 time_model: TimeModel, intrinsics: Intrinsics, mount: HeadMount):
        for tilt in config.tilts_deg + config.fallback_tilts_deg:
            if problem := time_model.pantilt.check(0.0, tilt):
                raise ValueError(f"planner: a setting's {problem}, which the head cannot reach")
        self.belief = belief
        self.config = config
        self.table = table
        self.time_model = time_model
        self.intrinsics = intrinsics
        self.mount = mount
        self.bins = SphereBins()
        self.vertices = grid_vertices(belief.grid.size_m, config.grid_spacing_m)
        self.positions = self.vertices  # the candidates of the coming decision (see plan_positions)
        self._blocks_m = block_centers(belief)
        self._aimed: AimedViewpoints | None = None
        self.widened = False  # the fallback tilts are in use (widen)
        self._use_tilts(config.tilts_deg)

    def _use_tilts(self, tilts_deg: tuple[float, ...]) -> None:
        """The camera settings at these tilts, and fresh action geometries for them."""
        self.settings = CameraSettings.from_fov(self.intrinsics, tilts_deg, self.config.view_overlap)
        # a baseline decides on every vertex (it never calls plan_positions): a large room's must fit too
        capacity = max(256, self.config.max_vertices + self.config.viewpoints, len(self.vertices))
        self._geometry = GeometryCache(self.belief, self.settings, self.mount, self.intrinsics, self.table, self.bins,
                                       capacity)
        self._here = ActionGeometry(self.belief, np.zeros((1, 2)), self.settings, self.mount, self.intrinsics,
                                    self.table, self.bins)

    def widen(self) -> bool:
        """Add the settings at ``fallback_tilts_deg``, once; whether it did. For a search about to stop
        "exhausted": what the belief still holds inside the room then lies where no setting of the
        usual tilts sees, such as a picture close below the head. Not from the start: a third tilt
        searched worse on ``dev`` (docs/search-experiments.md). The settings already there keep their
        indices, so the settings taken here stay taken."""
        if self.widened or not self.config.fallback_tilts_deg:
            return False
        self.widened = True
        self._use_tilts(self.config.tilts_deg + self.config.fallback_tilts_deg)
        return True

    @property
    def action_count(self) -> int:
        return len(self.positions) * len(self.settings)

    def plan_positions(self, pose: Pose2D, floor: FloorMap, margin_m: float) -> np.ndarray:
        """Choose the candidate positions of the next decision: the grid vertices nearest ``pose``
        and viewpoints aimed at the belief that the base can stand on (``floor``, ``margin_m`` from
        the walls). Returns them (also kept as :attr:`positions`)."""
        near = np.argsort(np.hypot(*(self.vertices - (pose.x_m, pose.y_m)).T))[:self.config.max_vertices]
        if self._aimed is None or self._aimed.margin_m != margin_m:
            self._aimed = AimedViewpoints(self._blocks_m, self.belief.facing_azimuths_rad, best_distance_m(self.table),
                                          self.mount.height_m, self.belief.grid.size_m, margin_m,
                                          self.config.viewpoint_lattice_m)
        aimed = self._aimed.propose(self.belief.coarse_mass().reshape(len(self._blocks_m), -1), self.config.viewpoints)
        cells = floor.cells_of(aimed)
        aimed = aimed[~floor.blocked[cells[:, 0], cells[:, 1]]] if len(aimed) else aimed
        self.positions = np.vstack([self.vertices[np.sort(near)], aimed])
        return self.positions

    def set_processing_s(self, seconds: float) -> None:
        """The measured processing time of a look (capture transfer, stereo, detection, mapping,
        planning): part of every t(f) from now on."""
        self.time_model = replace(self.time_model, processing_s=seconds)

    def set_drive_s_per_m(self, seconds: float) -> None:
        """The measured time per metre of a move (robot time and the navigator's processing): part of
        every travel time from now on."""
        self.time_model = replace(self.time_model, drive_s_per_m=seconds)

    def decide(self, pose: Pose2D, pan_rad: float, tilt_rad: float, elapsed_s: float,
               occupancy: OccupancyGrid, path_lengths_m: np.ndarray, taken: frozenset[int] = frozenset(),
               views: Views = ()) -> Decision:
        """The next action from ``pose`` (pan-tilt at ``pan_rad``, ``tilt_rad``), ``elapsed_s`` into the
        search; ``path_lengths_m`` is the navigation distance to each candidate (inf: unreachable);
        ``taken``: the settings already looked at from this position; ``views``: (x, y, setting) of
        every view taken so far. Each view is taken once, as in the report: the same view again would
        repeat what the belief already accounts for, and eq. 4 would count its near-identical image as
        new evidence."""
        if np.shape(path_lengths_m) != (len(self.positions),):
            raise ValueError(f"path_lengths_m must have one length per candidate position, shape "
                             f"({len(self.positions)},), not {np.shape(path_lengths_m)}")
        values = self._values(pose, occupancy)
        self._drop_taken(values, pose, taken, views)
        here_detection = values.find_prob[-1]
        # What looking on here can still find: no more than the looks not yet taken here would (the
        # covering also counts what the taken views left behind, which no look here will see again).
        here_covering = min(float(values.covering_prob[-1]), float(here_detection.sum()))
        values.covering_prob[-1] = here_covering
        look_t = self.time_model.look_times_s(pose.heading_rad, pan_rad, tilt_rad, self.settings.azimuth_rad,
                                              self.settings.tilt_rad)
        far_t = self.candidate_times(pose, path_lengths_m)
        # a candidate within same_position_m is here: its looks are not the robot's to take elsewhere
        reachable = np.where(np.isfinite(far_t) & self._away(pose)[:, None], values.find_prob[:-1], 0)
        best_anywhere = max(here_detection.max(), reachable.max(initial=0))
        if best_anywhere < self.config.min_detection_prob:
            return Decision("stop", f"no reachable action finds the target with probability ≥ "
                                    f"{self.config.min_detection_prob:g}"
                                    + self._unreachable_worth(values, path_lengths_m, pose), status="exhausted",
                            covering_here=here_covering, values=values)
        if not len(self.positions):  # a room too small for the grid, its aimed viewpoints all blocked
            decision = self._look_here(values, look_t, here_covering, "no other position to go to")
        elif self.config.cost_function == 1:
            decision = self._eq9(values, look_t, far_t, here_covering, pose)
        else:
            move, why, worth = self._why_move(values, look_t, far_t, path_lengths_m, here_covering, pose)
            decision = (self._move(values, far_t, path_lengths_m, here_covering, pose, why, worth) if move else
                        self._look_here(values, look_t, here_covering, why))
        if elapsed_s + decision.time_s > self.config.budget_s:
            return Decision("stop", f"the next action ({decision.time_s:.1f} s) would exceed the budget "
                                    f"K = {self.config.budget_s:g} s", status="budget",
                            covering_here=here_covering, values=values)
        return decision

    # --- the pieces --------------------------------------------------------------------------------

    def _why_move(self, values: ActionValues, look_t: np.ndarray, far_t: np.ndarray, path_lengths_m: np.ndarray,
                  covering: float, pose: Pose2D) -> tuple[bool, str, np.ndarray]:
        """Whether to leave the current position and why (the ``move_rule``), and which candidates
        are worth going to: those the robot would not leave again at once."""
        here = values.find_prob[-1]
        if self.config.move_rule == "threshold":
            worth = values.covering_prob[:-1] >= self.config.move_threshold
            move = covering < self.config.move_threshold
            why = f"covering probability here {covering:.3f} {'<' if move else '≥'} Θ_move {self.config.move_threshold:g}"
        else:
            here_rate = float((here / look_t).max())
            visit = self._visit_rates(values, far_t, path_lengths_m, pose)
            worth = visit > here_rate * self.config.leave_margin
            j = int(np.argmax(visit))
            move = bool(worth[j])
            why = (f"a visit to ({self.positions[j][0]:.2f}, {self.positions[j][1]:.2f}) finds {visit[j]:.4f}/s, "
                   f"the best look here {here_rate:.4f}/s (leaving takes {self.config.leave_margin:g}× that)")
        if not move and here.max() < self.config.min_detection_prob:
            move, why = True, f"no look left here finds it with probability ≥ {self.config.min_detection_prob:g}"
        return move, why, worth

    def _visit_rates(self, values: ActionValues, far_t: np.ndarray, path_lengths_m: np.ndarray,
                     pose: Pose2D) -> np.ndarray:
        """Per candidate: the best detection per second of a visit — travel there, then its best k
        looks (k ≤ ``visit_looks``), their expected detections summed but capped by the position's
        covering probability (overlapping views find the same mass once)."""
        reachable = np.isfinite(np.asarray(path_lengths_m, float)) & np.isfinite(far_t).all(axis=1) & self._away(pose)
        detection, times = values.find_prob[:-1][reachable], far_t[reachable]
        travel = times.min(axis=1) - self.time_model.image_s  # driving there, the first look's slew aside
        order = np.argsort(-detection, axis=1)[:, :self.config.visit_looks]
        found = np.minimum(np.cumsum(np.take_along_axis(detection, order, axis=1), axis=1),
                           values.covering_prob[:-1][reachable, None])
        spent = travel[:, None] + np.cumsum(np.take_along_axis(times, order, axis=1) - travel[:, None], axis=1)
        rates = np.zeros(len(self.positions))
        rates[reachable] = (found / spent).max(axis=1, initial=0.0)
        return rates

    def _drop_taken(self, values: ActionValues, pose: Pose2D, taken: frozenset[int],
                    views: Views) -> None:
        """Zero the detection probability of the looks already taken: ``taken`` here, and each of the
        ``views`` from every position (here included) within ``same_position_m`` of where it was taken,
        so that a robot that comes back to a place does not take its views again."""
        if taken:
            values.find_prob[-1, sorted(taken)] = 0.0
        if not views:
            return
        taken_at = np.array(views, float)
        places = np.vstack([self.positions, [pose.x_m, pose.y_m]])  # the rows of find_prob
        near = np.hypot(places[:, None, 0] - taken_at[None, :, 0],
                        places[:, None, 1] - taken_at[None, :, 1]) <= self.config.same_position_m
        rows, which = np.nonzero(near)
        values.find_prob[rows, taken_at[which, 2].astype(np.int64)] = 0.0

    def _away(self, pose: Pose2D) -> np.ndarray:
        """Candidates that are somewhere else: farther than ``same_position_m`` from the robot."""
        return np.hypot(self.positions[:, 0] - pose.x_m, self.positions[:, 1] - pose.y_m) > self.config.same_position_m

    def _values(self, pose: Pose2D, occupancy: OccupancyGrid) -> ActionValues:
        far = self.table.range_m[1]
        here_row = np.zeros(1, np.int64)
        here = np.array([[pose.x_m, pose.y_m]])
        if not np.array_equal(self._here.positions_m, here):  # the looks from one spot share its geometry
            self._here.place(here_row, here)
        parts = ((self._geometry.geometry, self._geometry.rows(self.positions)), (self._here, here_row))
        factor = max(1, round(self.config.sphere_resolution_m / occupancy.grid.resolution_m))
        coarse = occupancy.coarsened(factor)
        heavy = heavy_blocks(self.belief)
        rows = []
        for geometry, which in parts:
            if not len(which):
                rows.append(ActionValues(np.zeros((0, len(self.settings))), np.zeros(0)))
                continue
            spheres = sensed_spheres(coarse, geometry.cameras_m(which), self.bins, far, self._blocks_m[heavy])
            rows.append(evaluate(geometry, which, self.belief, spheres, self.config.behind_surface_m, heavy))
        return ActionValues(np.vstack([r.find_prob for r in rows]),
                            np.concatenate([r.covering_prob for r in rows]))

    def candidate_times(self, pose: Pose2D, path_lengths_m: np.ndarray) -> np.ndarray:
        """t(f) of every (candidate, setting): travel along the path, then a look (heading on
        arrival taken as the direction of travel); inf where the candidate is unreachable."""
        dx, dy = self.positions[:, 0] - pose.x_m, self.positions[:, 1] - pose.y_m
        arrival = np.arctan2(dy, dx)
        turn = np.where(np.hypot(dx, dy) > 1e-6, np.angle(np.exp(1j * (arrival - pose.heading_rad))), 0.0)
        travel = self.time_model.travel_s(path_lengths_m, turn)
        looks = self.time_model.look_times_s(arrival[:, None], 0.0, 0.0, self.settings.azimuth_rad[None],
                                             self.settings.tilt_rad[None])
        return travel[:, None] + looks

    def _look_here(self, values: ActionValues, look_t: np.ndarray, covering: float, why: str) -> Decision:
        """Eq. 3: the look of largest E(f) = P_Ψ(f) / t(f) from where the robot stands."""
        detection = values.find_prob[-1]
        utility = detection / look_t
        s = int(np.argmax(utility))
        return Decision("look", why,
                        self.settings.azimuth_rad[s], self.settings.tilt_rad[s], None, float(detection[s]),
                        float(utility[s]), float(look_t[s]), covering_here=covering, values=values, setting=s)

    def _unreachable_worth(self, values: ActionValues, dist: np.ndarray, pose: Pose2D) -> str:
        """Why the search ran out, if the map is the reason: a robot boxed in (by furniture, or by a
        stereo phantom the inflation turned into a wall) must not read as a room searched through."""
        elsewhere = self._away(pose)
        reachable = np.isfinite(np.asarray(dist, float)) & elsewhere
        best = values.find_prob[:-1][~reachable & elsewhere].max(initial=0.0)
        if best < self.config.min_detection_prob:
            return ""
        return (f"; {int(reachable.sum())} of {int(elsewhere.sum())} positions are reachable on the map, "
                f"and an unreachable one would find the target with probability {best:.3f}")

    def _eq9(self, values: ActionValues, look_t: np.ndarray, far_t: np.ndarray, covering: float,
             pose: Pose2D) -> Decision:
        """Cost 1: the largest detection probability among all reachable actions, wherever they are
        (a candidate within ``same_position_m`` is here, not a move)."""
        far = np.where(np.isfinite(far_t) & self._away(pose)[:, None], values.find_prob[:-1], -1.0)
        here = values.find_prob[-1]
        if here.max() >= far.max():
            s = int(np.argmax(here))
            return Decision("look", "eq. 9: the best action is here", self.settings.azimuth_rad[s],
                            self.settings.tilt_rad[s], None, float(here[s]), float(here[s]), float(look_t[s]),
                            covering_here=covering, values=values, setting=s)
        j, s = (int(v) for v in np.unravel_index(int(np.argmax(far)), far.shape))
        return Decision("move", f"eq. 9: the best action is at ({self.positions[j][0]:g}, {self.positions[j][1]:g})",
                        self.settings.azimuth_rad[s], self.settings.tilt_rad[s], tuple(self.positions[j]),
                        float(far[j, s]), float(far[j, s]), float(far_t[j, s]), covering_here=covering,
                        values=values, setting=s)

    def _move(self, values: ActionValues, far_t: np.ndarray, path_lengths_m: np.ndarray, covering: float,
              pose: Pose2D, why: str, worth: np.ndarray) -> Decision:
        """Eq. 10-12: the next position, preferring those ``worth`` going to (the robot would leave
        any other at once); its first look is its best by eq. 3."""
        dist = np.asarray(path_lengths_m, float)
        usable = np.isfinite(dist) & self._away(pose) & (values.find_prob[:-1].max(axis=1) >= self.config.min_detection_prob)
        if not usable.any():
            return Decision("stop", "no reachable position left whose looks are worth taking"
                            + self._unreachable_worth(values, dist, pose), status="exhausted",
                            covering_here=covering, values=values)
        cover = values.covering_prob[:-1]
        if (usable & worth).any():
            usable = usable & worth
        d = np.maximum(dist, 1e-6)
        score = {2: cover, 3: cover / d, 4: cover * (1.0 + self.config.distance_weight / d)}[self.config.cost_function]
        score = np.where(usable, score, -np.inf)
        j = int(np.argmax(score))
        first = values.find_prob[j] / far_t[j]
        s = int(np.argmax(first))
        equation = {2: "eq. 10", 3: "eq. 11", 4: "eq. 12"}[self.config.cost_function]
        return Decision("move", f"{why}; {equation} picks ({self.positions[j][0]:g}, {self.positions[j][1]:g})",
                        self.settings.azimuth_rad[s], self.settings.tilt_rad[s], tuple(self.positions[j]),
                        float(values.find_prob[j, s]), float(score[j]), float(far_t[j, s]),
                        covering_here=covering, values=values, setting=s)

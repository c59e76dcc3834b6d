"""The detector's table checked where the target really was (issue 12, "expected against real").

:mod:`~offboard.experiments.calibration` checks the planner's arithmetic: what it expected a look to
find against what the exact update removed, both from the same table. This checks the table itself,
at the one place that matters: for every look with the simulator's pose logged, the rate the table
gives for the target's picture as that camera truly saw it, against whether the detector fired.

A look has the picture *in view* when its centre and its corners drawn in by a tenth
(:meth:`~offboard.experiments.world_facts.Truth.picture_points`) project into the image and no obstacle
crosses the lines to them; its *table rate* is then the table's at the picture's distance, its angle
off the optical axis and the camera's angle off the picture's normal. Looks with a rate of at least
0.05 are binned by it, each view of a run once (:func:`target_views`). Eq. 4 treats every look as a
fresh draw, so a look that follows a miss in view should find the target as often as the table says;
the last columns test that, splitting each bin into a run's looks before and after its first miss in
view. The same looks are grouped by
distance and by angle off the normal too: a table measured in another scene errs first there.

The check assumes the simulator's default camera and head (:data:`SIM_CAMERA`, :data:`SIM_MOUNT`),
which the harness runs; a sweep on another camera would be checked against the wrong one.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from offboard.experiments.calibration import MIN_LOOKS, Look, cell
from offboard.experiments.world_facts import Truth, detector_table, load_facts, parse_placement, segments_hit_box
from offboard.perception.detectability import DetectabilityTable, facing_angle_deg, off_axis_deg
from offboard.perception.detection.detector import detector_names
from shared.geometry import HeadMount, Intrinsics, Pose2D

RATE_EDGES = (0.05, 0.2, 0.4, 0.6, 0.8, 1.0)  # a look below the first edge does not count as in view
DISTANCE_EDGES_M = (0.0, 2.0, 4.0, math.inf)
OFF_NORMAL_EDGES_DEG = (0.0, 30.0, 60.0, 90.0)
SIM_CAMERA = Intrinsics.from_fov(640, 480, 66.0)  # the simulator's default camera, which the harness runs
SIM_MOUNT = HeadMount()  # ... on the default head


@dataclass(frozen=True)
class TargetView:
    """How a look's true camera saw the target's picture, when it was in view."""

    rate: float  # the table's, at the three below
    distance_m: float
    off_axis_deg: float
    off_normal_deg: float


def target_view(truth: Truth, look: Look, table: DetectabilityTable, mount: HeadMount = SIM_MOUNT,
                intrinsics: Intrinsics = SIM_CAMERA) -> TargetView | None:
    """The view of the target's best pictured face (by table rate) from the look's true camera; None
    if no face has its centre and inset corners (:meth:`Truth.picture_points`) in the image and in plain
    sight, or for a look without the simulator's pose and the head's angles. A face seen from behind is
    in view, at rate 0."""
    if not look.camera_known:
        return None
    x, y, heading = look.truth
    camera = mount.camera_in_world(Pose2D(x, y, math.radians(heading)), *np.radians(look.head_deg))
    views = [v for normal in truth.face_normals() if (v := _face_view(truth, normal, camera, table, intrinsics))]
    return max(views, key=lambda v: v.rate, default=None)


def _face_view(truth: Truth, normal: np.ndarray, camera, table: DetectabilityTable,
               intrinsics: Intrinsics) -> TargetView | None:
    points = truth.picture_points(normal)
    uv = intrinsics.project(camera.inverse().apply(points))
    if not (np.all(np.isfinite(uv)) and np.all((uv >= 0) & (uv < [intrinsics.width_px, intrinsics.height_px]))):
        return None
    eye = camera.translation
    if any(segments_hit_box(eye, points, np.array(box.min_m), np.array(box.max_m)).any() for box in truth.obstacles):
        return None
    ray = points[0] - eye
    distance = float(np.linalg.norm(ray))
    off_axis = off_axis_deg(camera, points[0])
    facing = float(facing_angle_deg(math.atan2(ray[1], ray[0]), math.atan2(normal[1], normal[0]),
                                    math.asin(np.clip(ray[2] / distance, -1.0, 1.0))))
    rate = float(table.lookup(np.array([distance]), np.array([off_axis]), np.array([facing]))[0])
    return TargetView(rate, distance, off_axis, facing)


@dataclass(frozen=True)
class ViewedLook:
    view: TargetView
    detected: bool
    after_miss: bool  # it came after its run's first miss in view
    run: int  # which run it came from: a run's looks are much alike, so count runs too


@dataclass(frozen=True)
class ViewGroup:
    label: str
    looks: tuple[ViewedLook, ...]

    def detection_rate(self, after_miss: bool | None = None) -> float | None:
        """The share of its looks (all, or only those before / after a miss in view) that detected."""
        hits = [v.detected for v in self.looks if after_miss is None or v.after_miss == after_miss]
        return sum(hits) / len(hits) if hits else None

    def count(self, after_miss: bool) -> int:
        return sum(v.after_miss == after_miss for v in self.looks)

    @property
    def runs(self) -> int:
        return len({v.run for v in self.looks})

    @property
    def mean_rate(self) -> float | None:
        return sum(v.view.rate for v in self.looks) / len(self.looks) if self.looks else None


# the true room and target, the looks, and the run's detector's table for that target's size
Run = tuple[Truth, list[Look], DetectabilityTable]


def target_views(runs: list[Run]) -> tuple[list[ViewedLook], int, int]:
    """The looks of every run with the target in view (its table rate at least the first of
    :data:`RATE_EDGES`), each view of a run once; how many looks had the simulator's pose and the
    head's angles logged; and how many more in view repeated a view their run had already had.

    A repeated view (the same pose and head angles, as the oracle's looks from its viewpoint, or SYT's
    confirming look until session 55) is rendered exactly again, so the detector answers as before:
    it is no new draw, and counting it would weigh a lucky or unlucky view twice."""
    viewed: list[ViewedLook] = []
    logged = repeated = 0
    for number, (truth, looks, table) in enumerate(runs):
        missed = False
        had = set()
        for look in looks:
            logged += look.camera_known
            if (camera := (look.truth, look.head_deg)) in had:  # it was in view the first time, so again
                repeated += 1
                continue
            view = target_view(truth, look, table)
            if view is None or view.rate < RATE_EDGES[0]:
                continue
            had.add(camera)
            viewed.append(ViewedLook(view, look.detected, missed, number))
            missed = missed or not look.detected
    return viewed, logged, repeated


def _groups(looks: list[ViewedLook], value, edges: tuple[float, ...], unit: str = "") -> list[ViewGroup]:
    """``looks`` grouped by ``value(view)`` between ``edges`` (the last group closed above)."""
    groups = []
    for low, high in zip(edges, edges[1:]):
        last = high == edges[-1]
        inside = tuple(v for v in looks if low <= value(v.view) < high or (last and value(v.view) == high))
        label = f"≥ {low:g}{unit}" if math.isinf(high) else f"[{low:g}, {high:g}{']' if last else ')'}{unit}"
        groups.append(ViewGroup(label, inside))
    return groups


def by_rate(looks: list[ViewedLook]) -> list[ViewGroup]:
    return _groups(looks, lambda v: v.rate, RATE_EDGES)


def by_distance(looks: list[ViewedLook]) -> list[ViewGroup]:
    return _groups(looks, lambda v: v.distance_m, DISTANCE_EDGES_M, " m")


def by_off_normal(looks: list[ViewedLook]) -> list[ViewGroup]:
    return _groups(looks, lambda v: v.off_normal_deg, OFF_NORMAL_EDGES_DEG, "°")


@functools.cache
def _truth(world: str, target: str) -> Truth:
    """The true room and target of a row; a ValueError naming what is wrong with either."""
    return load_facts(world).truth(parse_placement(target))


def viewed_runs(rows: list[dict], looks: list[list[Look]]) -> tuple[list[Run], list[str]]:
    """The runs (rows of results.csv and their looks, in the same order) whose looks logged the
    simulator's pose and the head's angles, with their true room and target and their detector's
    table; and why each other such run was left out (its world gone, its target malformed, its
    detector without a table), naming the run."""
    runs, left_out = [], []
    for row, run in zip(rows, looks):
        if not any(look.camera_known for look in run):
            continue
        if row["detector"] not in detector_names():  # "auto" picks per search; the looks do not say which
            left_out.append(f"{row['key']}: detector {row['detector']!r} has no table of its own")
            continue
        try:
            truth = _truth(row["world"], row["target"])
            runs.append((truth, run, detector_table(row["detector"]).for_face(truth.face_size_m)))
        except ValueError as exc:  # WorldError is one
            left_out.append(f"{row['key']}: {exc}")
    return runs, left_out


def target_views_md(looks: list[ViewedLook], logged: int, repeated: int, source: str,
                    left_out: list[str] = ()) -> list[str]:
    if not logged and not left_out:
        return []  # a sweep from before the looks logged the head's angles
    lines = ["## The detector where the target was", "",
             f"Over {source}: {logged} looks logged the simulator's pose and the head's angles; in {len(looks)} of them the "
             f"target's picture was in view (the run's detector's table gives at least {RATE_EDGES[0]:g} from the true camera, "
             "the picture's centre and its corners drawn in by a tenth in the image, nothing in the way). "
             "Each view of a run counts once: "
             f"{repeated} more looks in view repeated one (the same pose and head angles, as the oracle's looks from its viewpoint), "
             "which the simulator renders exactly again, so the detector answered as before. Binned by that table rate: "
             "the share of them on which the detector fired, for all of them and split at each run's first miss in view. "
             "Eq. 4 treats looks as independent draws: if they are, a look after a miss finds the target as often as one "
             "before.", "",
             "| Table rate | Looks (runs) | Mean table rate | Detected | Before a miss (looks) | After a miss (looks) |",
             "|---|---|---|---|---|---|"]
    rates = by_rate(looks)
    for g in rates:
        lines.append(f"| {g.label} | {len(g.looks)} ({g.runs}) | {cell(g.mean_rate)} | {cell(g.detection_rate())} | "
                     f"{cell(g.detection_rate(False))} ({g.count(False)}) | {cell(g.detection_rate(True))} ({g.count(True)}) |")
    thin = [g.label for g in rates if 0 < len(g.looks) < MIN_LOOKS]
    if thin:
        lines += ["", f"Bins with fewer than {MIN_LOOKS} looks ({', '.join(thin)}) say little."]
    lines += ["", "The same looks by the picture's distance and by the camera's angle off the picture's normal "
              "(where a table measured elsewhere is most likely to be wrong):", "",
              "| View | Looks (runs) | Mean table rate | Detected |", "|---|---|---|---|"]
    for g in by_distance(looks) + by_off_normal(looks):
        lines.append(f"| {g.label} | {len(g.looks)} ({g.runs}) | {cell(g.mean_rate)} | {cell(g.detection_rate())} |")
    if left_out:
        lines += ["", f"Left out ({len(left_out)} runs):", ""] + [f"- {why}" for why in left_out]
    return lines + [""]

"""The detector's table checked where the target really was (issue 12, "expected against real").

:mod:`~offboard.experiments.calibration` checks the planner's arithmetic: what it expected a look to
find against what the exact update removed, both from the same table. This checks the table itself,
at the one place that matters: for every look with the simulator's pose logged, the rate the table
gives for the target's picture as that camera truly saw it, against whether the detector fired.

A look has the picture *in view* when its centre and corners project into the image and no obstacle
crosses the lines to them; its *table rate* is then the table's at the picture's distance, its angle
off the optical axis and the camera's angle off the picture's normal (0 out of view). Looks are
binned by table rate. Eq. 4 treats every look as a fresh draw, so a look that follows a miss in view
should find the target as often as the table says; the last columns test that, splitting each bin
into a run's looks before and after its first miss in view.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from offboard.experiments.calibration import MIN_LOOKS, Look, cell
from offboard.experiments.world_facts import Truth, detector_table, load_facts, segments_hit_box
from offboard.perception.detectability import DetectabilityTable, facing_angle_deg
from shared.geometry import HeadMount, Intrinsics, Pose2D

RATE_EDGES = (0.05, 0.2, 0.4, 0.6, 0.8, 1.0)  # a look below the first edge does not count as in view
SIM_CAMERA = Intrinsics.from_fov(640, 480, 66.0)  # the simulator's default camera, which the harness runs
SIM_MOUNT = HeadMount()  # ... on the default head


def table_rate(truth: Truth, look: Look, table: DetectabilityTable, mount: HeadMount = SIM_MOUNT,
               intrinsics: Intrinsics = SIM_CAMERA) -> float:
    """The table's rate for the target's best pictured face from the look's true camera; 0 out of view
    or for a look without the simulator's pose and the head's angles."""
    if look.truth is None or look.head_deg is None:
        return 0.0
    x, y, heading = look.truth
    camera = mount.camera_in_world(Pose2D(x, y, math.radians(heading)), *np.radians(look.head_deg))
    return max((_face_rate(truth, normal, camera, table, intrinsics) for normal in truth.face_normals()),
               default=0.0)


def _face_rate(truth: Truth, normal: np.ndarray, camera, table: DetectabilityTable, intrinsics: Intrinsics) -> float:
    points = truth.picture_points(normal)
    uv = intrinsics.project(camera.inverse().apply(points))
    if not (np.all(np.isfinite(uv)) and np.all((uv >= 0) & (uv < [intrinsics.width_px, intrinsics.height_px]))):
        return 0.0
    eye = camera.translation
    if any(segments_hit_box(eye, points, np.array(box.min_m), np.array(box.max_m)).any() for box in truth.obstacles):
        return 0.0
    ray = points[0] - eye
    distance = float(np.linalg.norm(ray))
    off_axis = math.degrees(math.acos(np.clip(ray @ camera.rotation[:, 2] / distance, -1.0, 1.0)))
    facing = facing_angle_deg(math.atan2(ray[1], ray[0]), math.atan2(normal[1], normal[0]),
                              math.asin(np.clip(ray[2] / distance, -1.0, 1.0)))
    return float(table.lookup(np.array([distance]), np.array([off_axis]), np.array([facing]))[0])


@dataclass(frozen=True)
class ViewBin:
    low: float
    high: float
    rates: tuple[float, ...]  # table rates of its looks
    found: tuple[bool, ...]  # whether the detector fired on each
    after_miss: tuple[bool, ...]  # whether each came after its run's first miss in view
    run: tuple[int, ...]  # which run each came from: a run's looks are much alike, so count runs too

    def detection_rate(self, after_miss: bool | None = None) -> float | None:
        """The share of its looks (all, or only those before / after a miss in view) that detected."""
        hits = [f for f, a in zip(self.found, self.after_miss) if after_miss is None or a == after_miss]
        return sum(hits) / len(hits) if hits else None

    def count(self, after_miss: bool) -> int:
        return sum(a == after_miss for a in self.after_miss)

    @property
    def runs(self) -> int:
        return len(set(self.run))

    @property
    def label(self) -> str:
        return f"[{self.low:g}, {self.high:g}{']' if self.high == RATE_EDGES[-1] else ')'}"


Run = tuple[Truth, list[Look], DetectabilityTable]  # the true room and target, the looks, the run's detector's table


def target_views(runs: list[Run]) -> tuple[list[ViewBin], int]:
    """The looks of every run with the target in view, binned by table rate; and how many looks had
    the simulator's pose and the head's angles logged (the population)."""
    samples: list[tuple[float, bool, bool, int]] = []
    logged = 0
    for number, (truth, looks, table) in enumerate(runs):
        missed = False
        for look in looks:
            logged += look.truth is not None and look.head_deg is not None
            rate = table_rate(truth, look, table)
            if rate >= RATE_EDGES[0]:
                samples.append((rate, look.detected, missed, number))
                missed = missed or not look.detected
    bins = []
    for low, high in zip(RATE_EDGES, RATE_EDGES[1:]):
        inside = [s for s in samples if low <= s[0] < high or s[0] == high == RATE_EDGES[-1]]
        bins.append(ViewBin(low, high, *(tuple(s[k] for s in inside) for k in range(4))))
    return bins, logged


TABLED_DETECTORS = ("sift", "ncc")  # "auto" picks per search, and the looks do not say which it used


@functools.cache
def _truth(world: str, target: str) -> Truth:
    """The true room and target of a row; a ValueError naming what is wrong with either."""
    try:
        placement = tuple(float(v) for v in target.split(","))
    except ValueError:
        placement = ()
    if len(placement) != 4 or not all(math.isfinite(v) for v in placement):
        raise ValueError(f"target {target!r} is not x,y,z,yaw")
    return load_facts(world).truth(placement)


def viewed_runs(rows: list[dict], looks: list[list[Look]]) -> tuple[list[Run], list[str]]:
    """The runs (rows of results.csv and their looks, in the same order) whose looks logged the
    simulator's pose and the head's angles, with their true room and target and their detector's
    table; and why each other such run was left out (its world gone, its target malformed, its
    detector without a table), naming the run."""
    runs, left_out = [], []
    for row, run in zip(rows, looks):
        if not any(look.truth and look.head_deg for look in run):
            continue
        if row["detector"] not in TABLED_DETECTORS:
            left_out.append(f"{row['key']}: detector {row['detector']!r} has no table of its own")
            continue
        try:
            runs.append((_truth(row["world"], row["target"]), run, detector_table(row["detector"])))
        except ValueError as exc:  # WorldError is one
            left_out.append(f"{row['key']}: {exc}")
    return runs, left_out


def target_views_md(bins: list[ViewBin], logged: int, source: str, left_out: list[str] = ()) -> list[str]:
    if not logged and not left_out:
        return []  # a sweep from before the looks logged the head's angles
    total = sum(len(b.rates) for b in bins)
    lines = ["## The detector where the target was", "",
             f"Over {source}: {logged} looks logged the simulator's pose and the head's angles; in {total} of them the "
             f"target's picture was in view (the run's detector's table gives at least {RATE_EDGES[0]:g} from the true camera, "
             "the picture all in the image, nothing in the way). Binned by that table rate: the share of them on which "
             "the detector fired, for all of them and split at each run's first miss in view. Eq. 4 treats looks as "
             "independent draws: if they are, a look after a miss finds the target as often as one before.", "",
             "| Table rate | Looks (runs) | Mean table rate | Detected | Before a miss (looks) | After a miss (looks) |",
             "|---|---|---|---|---|---|"]
    for b in bins:
        mean = sum(b.rates) / len(b.rates) if b.rates else None
        lines.append(f"| {b.label} | {len(b.rates)} ({b.runs}) | "
                     f"{cell(mean)} | {cell(b.detection_rate())} | {cell(b.detection_rate(False))} ({b.count(False)}) | "
                     f"{cell(b.detection_rate(True))} ({b.count(True)}) |")
    thin = [b.label for b in bins if 0 < len(b.rates) < MIN_LOOKS]
    if thin:
        lines += ["", f"Bins with fewer than {MIN_LOOKS} looks ({', '.join(thin)}) say little."]
    if left_out:
        lines += ["", f"Left out ({len(left_out)} runs):", ""] + [f"- {why}" for why in left_out]
    return lines + [""]

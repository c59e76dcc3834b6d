"""The planner's model checked against what happened (issue 12, deliverable 4): per look, the detection
probability the planner expected against the mass the exact update removed, binned over a sweep.

Each run's folder holds ``looks.jsonl``, written by the search, one JSON object per look::

    {"action": 3, "expected_p": 0.12, "realised_p": 0.10, "detected": false, "processing_s": 1.4, "motion_s": 6.2}

``expected_p``: what the planner predicted for that look; ``realised_p``: the mass the exact update
removed (or would have found); ``detected``: whether the detector fired. :func:`read_looks` reads and
validates one file; :func:`calibration` bins looks by expected P; :func:`calibration_md` is the
report's section. :func:`coverage` and :func:`coverage_md` say how much of the belief the looks rule
out: the pace any search under that prior is held to.

A look also has ``x_m``, ``y_m``, ``heading_deg``: the pose the robot believed it had, and
``pan_deg``, ``tilt_deg``: the head's angles. In the harness's runs it has the simulator's truth
beside them, ``true_x_m``, ``true_y_m``, ``true_heading_deg``; :func:`localisation_md` sums up the
difference, and :mod:`~offboard.experiments.target_views` checks the detector where the target was.
"""

from __future__ import annotations

import json
import math
import statistics
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from shared.geometry import Pose2D

LOOKS_FILE = "looks.jsonl"
BIN_EDGES = (0.0, 0.05, 0.1, 0.2, 0.4, 1.0)  # the last bin includes 1
MIN_LOOKS = 20  # a bin with fewer looks is shown but not checked
TOLERANCE = 0.2  # |mean expected − mean realised| ≤ this × mean expected
LOCALISATION_FAR_M = 0.3  # a pose error the report counts: the success radius is 0.5 m


@dataclass(frozen=True)
class Look:
    action: int
    expected_p: float
    realised_p: float
    detected: bool
    processing_s: float
    motion_s: float
    believed: tuple[float, float, float] | None = None  # (x_m, y_m, heading_deg) the robot believed it had
    truth: tuple[float, float, float] | None = None  # the simulator's, where the harness logged it
    head_deg: tuple[float, float] | None = None  # (pan, tilt) the look was taken at, where logged

    @property
    def camera_known(self) -> bool:
        """Both the simulator's pose and the head's angles were logged: the true camera can be rebuilt."""
        return self.truth is not None and self.head_deg is not None

    @property
    def pose_error_m(self) -> float | None:
        """|believed − true| position."""
        return None if self.truth is None else math.dist(self.believed[:2], self.truth[:2])

    @property
    def heading_error_deg(self) -> float | None:
        return None if self.truth is None else abs(math.remainder(self.believed[2] - self.truth[2], 360.0))

    def shift_at(self, point_xy: tuple[float, float]) -> float | None:
        """How far the pose error moves a world point: what the camera saw there from the true pose is
        placed as if seen from the believed one (at 3 m, 1° of heading alone moves it 5 cm)."""
        if self.truth is None:
            return None
        believed, truth = (Pose2D(x, y, math.radians(h)).to_transform() for x, y, h in (self.believed, self.truth))
        point = np.array([point_xy[0], point_xy[1], 0.0])
        return float(np.linalg.norm(believed.compose(truth.inverse()).apply(point) - point))


_FIELDS = {"action": int, "expected_p": float, "realised_p": float, "detected": bool, "processing_s": float,
           "motion_s": float}


def _is(value: object, kind: type) -> bool:
    if kind is bool or isinstance(value, bool):  # a bool is an int in Python: never a number here
        return kind is bool and isinstance(value, bool)
    if kind is int:
        return isinstance(value, int)
    return isinstance(value, (int, float)) and math.isfinite(value)


def parse_look(text: str, where: str = "look") -> Look:
    """One line of ``looks.jsonl``; a ``ValueError`` naming ``where`` and the field if it is malformed."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{where}: not JSON ({exc.msg})") from None
    except RecursionError:  # nested past Python's stack: no look is
        raise ValueError(f"{where}: not a look (nested too deep)") from None
    if not isinstance(data, dict):
        raise ValueError(f"{where}: expected an object, got {type(data).__name__}")
    values = {}
    for name, kind in _FIELDS.items():
        if name not in data:
            raise ValueError(f"{where}: missing {name!r}")
        if not _is(data[name], kind):
            raise ValueError(f"{where}: {name} = {data[name]!r} is not a finite {kind.__name__}")
        values[name] = kind(data[name])
    for name in ("expected_p", "realised_p"):
        if not 0.0 <= values[name] <= 1.0 + 1e-9:
            raise ValueError(f"{where}: {name} = {values[name]!r} is not a probability")
    if "true_x_m" in data:
        for name in _POSE_FIELDS:
            if not _is(data.get(name), float):
                raise ValueError(f"{where}: {name} = {data.get(name)!r} is not a finite float")
        values["believed"] = (float(data["x_m"]), float(data["y_m"]), float(data["heading_deg"]))
        values["truth"] = (float(data["true_x_m"]), float(data["true_y_m"]), float(data["true_heading_deg"]))
    if "pan_deg" in data or "tilt_deg" in data:
        for name in ("pan_deg", "tilt_deg"):
            if not _is(data.get(name), float):
                raise ValueError(f"{where}: {name} = {data.get(name)!r} is not a finite float")
        values["head_deg"] = (float(data["pan_deg"]), float(data["tilt_deg"]))
    return Look(**values)


_POSE_FIELDS = ("x_m", "y_m", "heading_deg", "true_x_m", "true_y_m", "true_heading_deg")


def read_looks(path: Path) -> list[Look]:
    """Every look of one run (``[]`` if the run wrote no log)."""
    path = Path(path)
    if not path.is_file():
        return []
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except UnicodeDecodeError as exc:
        raise ValueError(f"{path}: not text (byte {exc.start} is not UTF-8)") from None
    return [parse_look(line, f"{path}:{n}") for n, line in enumerate(lines, 1) if line.strip()]


@dataclass(frozen=True)
class CalibrationBin:
    low: float
    high: float
    looks: int
    expected: float | None  # mean expected P
    realised: float | None  # mean realised P
    hit_rate: float | None  # share of looks whose detector fired

    @property
    def checked(self) -> bool:
        return self.looks >= MIN_LOOKS

    @property
    def passes(self) -> bool | None:
        """|mean expected − mean realised| ≤ :data:`TOLERANCE` × mean expected; None if too few looks."""
        if not self.checked:
            return None
        return abs(self.expected - self.realised) <= TOLERANCE * self.expected


def _mean(values: list[float]) -> float | None:
    return statistics.fmean(values) if values else None


def calibration(looks: list[Look]) -> list[CalibrationBin]:
    """Looks binned by expected P (:data:`BIN_EDGES`), each bin's means and hit rate."""
    bins = []
    for k, (low, high) in enumerate(zip(BIN_EDGES, BIN_EDGES[1:])):
        last = k == len(BIN_EDGES) - 2
        inside = [x for x in looks if low <= x.expected_p < high or (last and x.expected_p >= high)]
        bins.append(CalibrationBin(low, high, len(inside), _mean([x.expected_p for x in inside]),
                                   _mean([x.realised_p for x in inside]), _mean([float(x.detected) for x in inside])))
    return bins


def cell(value: float | None, digits: int = 2) -> str:
    """A number for a Markdown table; a dash where there is none."""
    return "—" if value is None else f"{value:.{digits}f}"


def calibration_md(bins: list[CalibrationBin], source: str) -> list[str]:
    """The report's section; ``source`` says which runs (worlds, seeds) the looks came from."""
    total = sum(b.looks for b in bins)
    lines = ["## Calibration: expected against realised P", ""]
    if total == 0:
        return lines + [f"No run logged its looks ({LOOKS_FILE}): nothing to check.", ""]
    lines += [f"{total} looks of {source}, binned by the detection probability the planner expected. Realised P: "
              f"the mass the exact update removed. Check: |mean expected − mean realised| ≤ {TOLERANCE:.0%} of the "
              f"mean expected, in every bin with ≥ {MIN_LOOKS} looks. Both come from the same belief and detector "
              "table, so the check is of the planner's arithmetic (coarse blocks against the update's cubes), not of "
              "the model against the world: the hit rate is that (weak and false detections count as hits).", "",
              "| Expected P | Looks | Mean expected P | Mean realised P | Hit rate | Check |", "|---" * 6 + "|"]
    for b in bins:
        bracket = "]" if b.high == BIN_EDGES[-1] else ")"
        verdict = {None: f"— (< {MIN_LOOKS} looks)", True: "PASS", False: "FAIL"}[b.passes]
        lines.append(f"| [{b.low:g}, {b.high:g}{bracket} | {b.looks} | {cell(b.expected, 3)} | {cell(b.realised, 3)} | "
                     f"{cell(b.hit_rate, 3)} | {verdict} |")
    checked = [b for b in bins if b.checked]
    overall = "PASS" if checked and all(b.passes for b in checked) else ("FAIL" if checked else "not checked")
    return lines + ["", f"Calibration overall: **{overall}** ({sum(bool(b.passes) for b in checked)}/{len(checked)} "
                        "checked bins pass).", ""]


COVERAGE_LOOKS = (6, 12, 24)


@dataclass(frozen=True)
class Coverage:
    looks: int  # k
    searching: int  # runs that took k looks without a detection
    ruled_out: float | None  # their median P[F] after those k looks
    found_within: float | None  # share of all runs that found the target in at most k looks


def ruled_out(looks: list[Look]) -> list[float]:
    """P[F] after each look before the first detection: the probability that the looks so far would
    have found the target, 1 − Π(1 − realised P) (each realised P is eq. 1 on the belief before it)."""
    missed, out = 1.0, []
    for look in looks:
        if look.detected:
            break
        missed *= 1.0 - look.realised_p
        out.append(1.0 - missed)
    return out


def coverage(runs: list[tuple[list[Look], int | None]]) -> list[Coverage]:
    """Per k of :data:`COVERAGE_LOOKS`, over ``runs`` (each its looks and the looks it took to find the
    target, None if it did not)."""
    rows = []
    for k in COVERAGE_LOOKS:
        after_k = [p[k - 1] for p in (ruled_out(looks) for looks, _ in runs) if len(p) >= k]
        found = [found_at is not None and found_at <= k for _, found_at in runs]
        rows.append(Coverage(k, len(after_k), statistics.median(after_k) if after_k else None,
                             _mean([float(f) for f in found])))
    return rows


def coverage_md(rows: list[Coverage], source: str) -> list[str]:
    """The report's section; ``source`` says which runs (worlds, seeds) the looks came from."""
    lines = ["## Coverage: what the looks rule out", "",
             f"Over {source}. P[F] after k looks without a detection: the probability, under the planner's model, "
             "that those looks would have found the target (1 − Π(1 − realised P)), the share of the prior they "
             "checked. Where it is small, a search that looks this way needs more than k looks in most rooms; the "
             "last column is what happened (more than P[F] where targets are not placed as the prior says).", "",
             "| Looks k | Runs with k looks and no detection | Their median P[F] | Runs that found it within k looks |",
             "|---" * 4 + "|"]
    lines += [f"| {r.looks} | {r.searching} | {cell(r.ruled_out, 3)} | "
              f"{'—' if r.found_within is None else f'{r.found_within:.0%}'} |" for r in rows]
    return lines + [""]


def localisation_md(looks: list[Look], source: str) -> list[str]:
    """The report's section on where the robot believed it stood at its looks against where it stood
    (the simulator's truth); nothing if no look logged the truth."""
    errors = sorted(x.pose_error_m for x in looks if x.pose_error_m is not None)
    if not errors:
        return []
    turns = sorted(x.heading_error_deg for x in looks if x.heading_error_deg is not None)
    far = sum(e > LOCALISATION_FAR_M for e in errors) / len(errors)
    return ["## Localisation at the looks", "",
            f"Over {source}: {len(errors)} looks. The distance between the position the planner believed the "
            f"robot was at and the simulator's true position: median {statistics.median(errors):.3f} m, p95 "
            f"{_p95(errors):.3f} m, max {errors[-1]:.3f} m; {far:.0%} of the looks were more than "
            f"{LOCALISATION_FAR_M:g} m off. The heading's error: median {statistics.median(turns):.1f}°, p95 "
            f"{_p95(turns):.1f}°, max {turns[-1]:.1f}° (at 3 m, 1° moves a point 5 cm sideways). An error here moves "
            "what the look saw, and where a detection puts the target, by as much.", ""]


def _p95(ordered: list[float]) -> float:
    return ordered[min(len(ordered) - 1, math.ceil(0.95 * len(ordered)) - 1)]

"""``results.csv`` (its columns, appending, reading) and, from it, ``report.md`` and bar charts
(report §5.2.3, Tables 2 and 3).

Actions, time and distance are averaged over successful runs (the target found, the estimate within
:data:`~offboard.experiments.harness.SUCCESS_RADIUS_M` of the truth); success rates and SPL are over all runs.
Each table cell shows our mean beside the report's. The report's six conclusions are checked against
our numbers with explicit criteria (:func:`conclusions`); run on the report's own tables every check
agrees, which the tests assert. Plots are drawn with OpenCV.

Time is honest: motion (the robot's clock: driving, turning, slewing, capturing) and processing (the
measured wall time of capture transfer, stereo, detection, mapping and planning) are shown apart and
summed; only the sum is compared with the report's minutes, which included about 15 s of processing
per action. Every table of results names the worlds (or suites) and seeds it comes from, the paired
tables (SYT against a baseline, a prior against ``uniform``) those of their paired runs, and counts
runs apart from scenarios (world × start × target, its seeds averaged: the standard error's samples).
Successful runs from which no position sees the target by SPL's rule score SPL 0; the report says how
many, and gives SPL over the runs with a finite shortest path beside it. Per world, each method has its
own table; the priors are shown side by side; the planner's expected P is checked against the
realised P (:mod:`offboard.experiments.calibration`).
"""

from __future__ import annotations

import csv
import logging
import math
import os
import statistics
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from offboard.experiments.calibration import (LOOKS_FILE, Look, calibration, calibration_md, cell, coverage,
                                              coverage_md, localisation_md, read_looks)
from offboard.experiments.failures import failures_md, last_true_look
from offboard.experiments.target_views import target_views, target_views_md, viewed_runs
from shared.image_files import write_bgr

log = logging.getLogger(__name__)

COSTS = (1, 2, 3, 4)
PRIORS = {"uniform": "No knowledge", "tables": "Knowledge"}
METRICS = {"actions": "Number of actions", "time_min": "Total time (min.)", "distance_m": "Distance traveled (m.)"}
# Tables 2 and 3 of the report: prior -> metric -> costs 1..4
REPORT = {
    "uniform": {"actions": (9.4375, 8.722, 8.45, 8.733), "time_min": (16.1875, 8.111, 6.8, 7.533),
                "distance_m": (22.385, 8.77, 3.85, 8.0273)},
    "tables": {"actions": (5.0, 5.5, 4.9, 4.933), "time_min": (10.4375, 5.9, 3.8, 4.333),
               "distance_m": (13.4675, 5.9815, 3.4095, 4.14133)},
}
REPORT_SUCCESS = 0.91
REPORT_PROCESSING_S = 15.0  # per action, inside the report's minutes
SAME_ACTIONS = 0.25  # conclusion 2: "no significant effect" = mean actions within this relative spread

Tables = dict[str, dict[str, list[float | None]]]  # prior -> metric -> one value per cost (None: no run)


# --- results.csv -----------------------------------------------------------------------------------

RUN_COLUMNS = ("method", "world", "start", "target", "cost", "prior", "seed")
SUMMARY_COLUMNS = ("found", "status", "actions", "positions_visited", "distance_m", "robot_time_s", "wall_time_s",
                   "planning_ms_p50", "planning_ms_p95", "target_estimate_m", "prob_outside", "prob_inside",
                   "success_prob", "cost_function", "detector", "decisions", "prior_spec")  # summary's "prior"
DERIVED_COLUMNS = ("estimate_error_m", "shortest_path_m", "success", "spl", "run_wall_s", "error", "key")
# added later, at the end: summary.json's motion (robot clock) and processing (wall) seconds, empty when the
# search did not measure them; the run's folder under the sweep's --out (its looks.jsonl)
TIME_COLUMNS = ("motion_time_s", "processing_time_s", "run_dir")
# later still: summary.json's frames searched on the way between positions (not looks); empty before then
GLANCE_COLUMNS = ("glances",)
COLUMNS = RUN_COLUMNS + SUMMARY_COLUMNS + DERIVED_COLUMNS + TIME_COLUMNS + GLANCE_COLUMNS
TEXT_COLUMNS = ("method", "world", "start", "target", "prior", "status", "key", "error", "detector", "prior_spec",
                "target_estimate_m", "run_dir")


TORN_SUFFIX = ".torn"  # results.csv.torn: the unfinished last row of a sweep killed while writing it


def finished_keys(results: Path) -> set[str]:
    """Runs already done (a row whose status is not an error). A last row cut short by a kill is
    moved to ``results.csv.torn`` first, so that its run is done again."""
    if not results.is_file():
        return set()
    _set_torn_row_aside(results)
    if results.stat().st_size == 0:  # killed before its header was whole: the next row writes one
        results.unlink()
        return set()
    with results.open(newline="") as f:
        if tuple(next(csv.reader(f), ())) != COLUMNS:
            raise ValueError(f"{results} has other columns than this harness writes: use another --out")
    return {row["key"] for row in load_results(results, latest=False) if not row["status"].startswith("error")}


def _set_torn_row_aside(results: Path) -> None:
    data = results.read_bytes()
    if not data or data.endswith(b"\n"):
        return
    head, _, torn = data.rpartition(b"\n")
    aside = results.with_name(results.name + TORN_SUFFIX)
    with aside.open("ab") as f:
        f.write(torn + b"\n")
    with results.open("r+b") as f:
        f.truncate(len(head) + 1 if head else 0)
    log.warning("%s: its last row was cut short (%d bytes); moved to %s, and its run will be done again",
                results, len(torn), aside)


def append_row(results: Path, row: dict) -> None:
    """Append one run's row and flush it to disk at once (an interrupted sweep keeps it)."""
    new = not results.is_file()
    with results.open("a", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS, extrasaction="ignore")
        if new:
            writer.writeheader()
        writer.writerow(row)
        f.flush()
        os.fsync(f.fileno())


def _measured(text: str, column: str, where: str) -> float | None:
    """A number column's value; None where empty (not measured); a ValueError naming the cell where it
    is neither: coerced to None, a typo read as "not measured" and moved the means silently."""
    if text == "":
        return None
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise ValueError(f"{where}: {column} {text!r}, not a finite number")
    return value


# the columns every results.csv has had; those added later are empty in an older file
REQUIRED_COLUMNS = RUN_COLUMNS + SUMMARY_COLUMNS + DERIVED_COLUMNS


def load_results(path: Path, latest: bool = True) -> list[dict]:
    """One row per run (the last attempt of each; every attempt if not ``latest``), with numbers and
    booleans parsed. A ValueError names the file, and the line, of a row that is not one this harness
    writes."""
    with Path(path).open(newline="") as f:
        reader = csv.DictReader(f)
        try:
            missing = [c for c in REQUIRED_COLUMNS if c not in (reader.fieldnames or ())]
            if missing:
                raise ValueError(f"{path}: not an experiment's results.csv: no column {', '.join(missing)}")
            rows = [_parsed(row, f"{path}:{reader.line_num}") for row in reader]
        except (csv.Error, UnicodeDecodeError) as exc:  # a field past csv's limit, bytes that are not text
            raise ValueError(f"{path}: the row after line {reader.line_num} is not one this harness writes "
                             f"({exc})") from None
    return list({r["key"]: r for r in rows}.values()) if latest else rows


def _parsed(row: dict, where: str) -> dict:
    if None in row:  # more fields than the header: csv keeps the rest under None
        raise ValueError(f"{where}: {len(row) - 1 + len(row[None])} fields where the header has {len(row) - 1}")
    if None in row.values():  # fewer: csv fills the missing ones with None
        raise ValueError(f"{where}: {sum(v is not None for v in row.values())} fields where the header has "
                         f"{len(row)}")
    allowed = tuple(map(str, COSTS)) if row["method"] == "syt" else ("",)  # the cost function is SYT's
    if row["cost"] not in allowed:
        raise ValueError(f"{where}: cost {row['cost']!r} for method {row['method']!r}, not one of {allowed}")
    for flag in ("found", "success"):
        if row[flag] not in ("True", "False"):
            raise ValueError(f"{where}: {flag} {row[flag]!r}, not True or False")
    parsed = {**dict.fromkeys(TIME_COLUMNS + GLANCE_COLUMNS),
              **{k: v if k in TEXT_COLUMNS else _measured(v, k, where) for k, v in row.items()
                 if k not in ("found", "success", "cost")}}
    if parsed["spl"] is not None and not 0.0 <= parsed["spl"] <= 1.0:
        raise ValueError(f"{where}: spl {row['spl']!r}, not in [0, 1]")
    parsed.update(found=row["found"] == "True", success=row["success"] == "True",
                  cost=int(row["cost"]) if row["cost"] else None)
    return {**parsed, **_times(parsed)}


def _times(row: dict) -> dict:
    """Minutes: motion (the robot's clock), processing (measured wall time), and ``time_min``, the time
    compared with the report's: their sum, or the robot's clock alone where processing was not measured."""
    motion_s = row.get("motion_time_s")
    motion_s = row["robot_time_s"] if motion_s is None else motion_s
    processing_s = row.get("processing_time_s")
    total_s = motion_s if processing_s is None or motion_s is None else motion_s + processing_s
    return {"motion_min": _minutes(motion_s), "processing_min": _minutes(processing_s), "time_min": _minutes(total_s)}


def _minutes(seconds: float | None) -> float | None:
    return None if seconds is None else seconds / 60


def mean_of(values: list) -> float | None:
    """The mean of the values that are not None (None if none is)."""
    values = [v for v in values if v is not None]
    return statistics.fmean(values) if values else None


def syt_tables(rows: list[dict]) -> Tables:
    """Means over successful SYT runs for each prior, metric and cost function."""
    out: Tables = {}
    for prior in PRIORS:
        cells = {c: [r for r in rows if r["method"] == "syt" and r["prior"] == prior and r["cost"] == c
                     and r["success"]] for c in COSTS}
        out[prior] = {m: [mean_of([r[m] for r in cells[c]]) for c in COSTS] for m in METRICS}
    return out


# --- the six conclusions ---------------------------------------------------------------------------

@dataclass(frozen=True)
class Verdict:
    claim: str
    agrees: bool | None  # None: some cell has no successful run
    evidence: str


def _comparisons(pairs: list[tuple[float | None, float | None]]) -> tuple[bool | None, int]:
    """(all a < b, how many hold); None if a value is missing."""
    if any(a is None or b is None for a, b in pairs):
        return None, sum(1 for a, b in pairs if a is not None and b is not None and a < b)
    held = sum(a < b for a, b in pairs)
    return held == len(pairs), held


def conclusions(t: Tables) -> list[Verdict]:
    """The report's six conclusions, each checked on ``t`` (ours, or the report's own tables)."""
    u, k = t["uniform"], t["tables"]
    return _knowledge_and_actions(u, k) + _two_stages(u, k) + _best(u, k)


def _knowledge_and_actions(u: dict, k: dict) -> list[Verdict]:
    ok1, n1 = _comparisons([(k[m][c], u[m][c]) for m in METRICS for c in range(4)])
    spreads = []
    for tab in (u, k):
        a = [v for v in tab["actions"] if v is not None]
        spreads.append((max(a) - min(a)) / statistics.fmean(a) if len(a) == 4 and statistics.fmean(a) > 0 else None)
    ok2 = None if None in spreads else all(s <= SAME_ACTIONS for s in spreads)
    return [
        Verdict("Prior knowledge drastically accelerates the search (time, actions, distance).", ok1,
                f"{n1}/12 cost×metric cells lower with knowledge; mean over costs: "
                f"time {cell(mean_of(u['time_min']))} → {cell(mean_of(k['time_min']))} min, "
                f"actions {cell(mean_of(u['actions']))} → {cell(mean_of(k['actions']))}, "
                f"distance {cell(mean_of(u['distance_m']))} → {cell(mean_of(k['distance_m']))} m"),
        Verdict("The cost function has no significant effect on the number of actions.", ok2,
                f"spread (max − min) / mean of the four costs' mean actions: no knowledge {cell(spreads[0])}, "
                f"knowledge {cell(spreads[1])} (criterion ≤ {SAME_ACTIONS:g})"),
    ]


def _two_stages(u: dict, k: dict) -> list[Verdict]:
    moving = ("distance_m", "time_min")
    ok3, n3 = _comparisons([(tab[m][c], tab[m][0]) for tab in (u, k) for m in moving for c in (1, 2, 3)])
    ok4, n4 = _comparisons([(tab[m][c], tab[m][1]) for tab in (u, k) for m in moving for c in (2, 3)])
    return [
        Verdict("The two-stage search (costs 2-4) reduces distance and time against cost 1.", ok3,
                f"{n3}/12 comparisons hold; distance cost 1 vs 2/3/4: no knowledge {cell(u['distance_m'][0])} vs "
                f"{'/'.join(cell(v) for v in u['distance_m'][1:])} m, knowledge {cell(k['distance_m'][0])} vs "
                f"{'/'.join(cell(v) for v in k['distance_m'][1:])} m"),
        Verdict("Minimising the distance to the next position (costs 3, 4) reduces distance and time further.", ok4,
                f"{n4}/8 comparisons against cost 2 hold; time cost 2 vs 3/4: no knowledge {cell(u['time_min'][1])} vs "
                f"{cell(u['time_min'][2])}/{cell(u['time_min'][3])} min, knowledge {cell(k['time_min'][1])} vs "
                f"{cell(k['time_min'][2])}/{cell(k['time_min'][3])} min"),
    ]


def _best(u: dict, k: dict) -> list[Verdict]:
    cells = {m: [tab[m][c] for tab in (u, k) for c in range(4)] for m in ("time_min", "distance_m")}
    known = {m: [v for v in vs if v is not None] for m, vs in cells.items()}
    ok5 = None if any(None in vs for vs in cells.values()) else all(k[m][2] == min(vs) for m, vs in cells.items())
    ok6, n6 = _comparisons([(k["actions"][c], k["actions"][1]) for c in (0, 2, 3)])
    return [
        Verdict("Knowledge with cost 3 gives the best results (least time and distance of all eight cells).", ok5,
                f"knowledge + cost 3: {cell(k['time_min'][2])} min, {cell(k['distance_m'][2])} m; least of all cells: "
                f"{cell(min(known['time_min'], default=None))} min, {cell(min(known['distance_m'], default=None))} m"),
        Verdict("The number of actions is best minimised by costs 1, 3 and 4 (checked with knowledge, where the "
                "report's Table 3 supports it; in its Table 2 cost 1 needs the most).", ok6,
                f"{n6}/3 of costs 1/3/4 need fewer actions than cost 2: "
                f"{'/'.join(cell(k['actions'][c]) for c in (0, 2, 3))} vs {cell(k['actions'][1])}"),
    ]


# --- methods, latency, wall time -------------------------------------------------------------------

@dataclass(frozen=True)
class MethodStats:
    name: str
    runs: int
    successes: int
    spl: float | None
    time_min: float | None  # over successful runs, like actions, distance, motion and processing
    actions: float | None
    distance_m: float | None
    latency_p50_ms: float | None  # median over runs of each run's p50
    latency_p95_ms: float | None  # 95th percentile over runs of each run's p95
    motion_min: float | None = None
    processing_min: float | None = None  # None: no run measured it
    glances: float | None = None  # over successful runs; None: some run did not count them
    scope: str = ""  # the worlds and seeds the figures come from
    finite_runs: int = 0  # runs with a finite shortest path (some position sees the target by SPL's rule)
    finite_spl: float | None = None  # SPL over those runs alone

    @property
    def success_rate(self) -> float | None:
        return self.successes / self.runs if self.runs else None


def scope(rows: list[dict]) -> str:
    """Which worlds and seeds ``rows`` come from, and how many scenarios (start × target) per world."""
    seeds = sorted({r["seed"] for r in rows if r["seed"] is not None})
    scenarios = len({(r["world"], r["start"], r["target"]) for r in rows})
    return (f"{_worlds_text(dict.fromkeys(r['world'] for r in rows)) or 'no world'}; "
            f"seeds {','.join(f'{s:g}' for s in seeds) or '—'}; {scenarios} start × target scenarios")


def _worlds_text(worlds: dict) -> str:
    """World names; when several share a suite (``test/room-2000-3``) or, for world files given by
    path, a folder, they are counted under its name."""
    groups: dict[str, list[str]] = {}
    for name in worlds:
        groups.setdefault(name.rpartition("/")[0] or name, []).append(name)
    return ", ".join(_group_text(key, names) for key, names in groups.items())


def _group_text(key: str, names: list[str]) -> str:
    if len(names) == 1:
        return names[0]
    if names[0].endswith(".toml"):
        return f"{len(names)} world files in {key}"
    return f"the {key} suite ({len(names)} worlds)"


def _stats(name: str, rows: list[dict]) -> MethodStats:
    ok = [r for r in rows if r["success"]]
    finite = [r for r in rows if r["shortest_path_m"] is not None]
    p50 = [r["planning_ms_p50"] for r in rows if r["planning_ms_p50"] is not None]
    p95 = [r["planning_ms_p95"] for r in rows if r["planning_ms_p95"] is not None]
    return MethodStats(name, len(rows), len(ok), mean_of([r["spl"] or 0.0 for r in rows]),
                       *(mean_of([r[m] for r in ok]) for m in ("time_min", "actions", "distance_m")),
                       statistics.median(p50) if p50 else None, float(np.percentile(p95, 95)) if p95 else None,
                       mean_of([r["motion_min"] for r in ok]), _all_measured(ok, "processing_min"),
                       _all_measured(ok, "glances"), scope(rows), len(finite),
                       mean_of([r["spl"] or 0.0 for r in finite]))


def _all_measured(rows: list[dict], column: str) -> float | None:
    """The mean of ``column`` if every run measured it (a partial mean would not compare), else None."""
    values = [r.get(column) for r in rows]  # a results.csv from before the column has none
    return None if None in values else mean_of(values)


def variants(rows: list[dict]) -> list[tuple[str, list[dict]]]:
    """The runs grouped by method, cost function and prior: SYT's first (by cost, then prior), then each
    baseline's, in the order first seen."""
    groups: dict[tuple, list[dict]] = {}
    order = {p: i for i, p in enumerate(dict.fromkeys(r["prior"] for r in rows))}
    for r in sorted(rows, key=lambda r: (r["method"] != "syt", r["cost"] or 0, order[r["prior"]])):
        groups.setdefault((r["method"], r["cost"], r["prior"]), []).append(r)
    return [(variant_name(*key), members) for key, members in groups.items()]


def variant_name(method: str, cost: float | None, prior: str) -> str:
    return f"SYT cost {cost:g}, {prior}" if method == "syt" else f"{method}, {prior}"


def method_stats(rows: list[dict]) -> list[MethodStats]:
    """SYT over all costs, SYT per cost, then each baseline in the order first seen; each over every
    prior it ran with, which its name lists when there are several (the next table splits them)."""
    syt = [r for r in rows if r["method"] == "syt"]
    groups = [("syt (all costs)", syt)] if syt else []
    groups += [(f"syt (cost {c})", [r for r in syt if r["cost"] == c]) for c in COSTS
               if any(r["cost"] == c for r in syt)]
    groups += [(name, [r for r in rows if r["method"] == name])
               for name in dict.fromkeys(r["method"] for r in rows if r["method"] != "syt")]
    return [_stats(_with_priors(name, group), group) for name, group in groups]


def _with_priors(name: str, rows: list[dict]) -> str:
    """``syt (cost 3), uniform + tables``: the priors pooled in ``rows``, when there are several."""
    priors = dict.fromkeys(r["prior"] for r in rows)
    return f"{name}, {' + '.join(priors)}" if len(priors) > 1 else name


def _scenario(row: dict) -> tuple:
    return row["world"], row["start"], row["target"], row["prior"], row["seed"]


def placement(row: dict) -> tuple:
    """What two methods or two priors are paired on: world, start, target and seed (the seed last)."""
    return row["world"], row["start"], row["target"], row["seed"]


# baselines given the truth: strong references, not rivals, and not bounds: the oracle drives to a stricter
# viewpoint (a detection rate of 0.9, with margins) than SPL's shortest path is measured to (0.8), so a search
# can score a higher SPL than it (the report counts how often)
YARDSTICKS = ("oracle",)


@dataclass(frozen=True)
class SplMargin:
    """SYT's SPL against one baseline's on the scenarios both ran (start × target × seed), a failure
    counting 0 on either side, as in the mean SPL."""

    baseline: str
    prior: str  # SYT's
    their_prior: str  # the baseline's: the same, or the only one it ran with (its tours ignore the prior)
    scenarios: int
    syt: float
    theirs: float
    stderr: float | None  # of the paired difference; None below two scenarios
    by_seed: tuple[tuple[float, float], ...]  # (seed, difference)
    distinct_scenarios: int = 0  # world × start × target, its seeds averaged: the standard error's samples
    scope: str = ""  # the worlds and seeds of the paired runs
    syt_ahead: int = 0  # paired runs in which SYT's SPL is above the baseline's

    @property
    def difference(self) -> float:
        return self.syt - self.theirs


def spl_margins(rows: list[dict], cost: int = 3) -> list[SplMargin]:
    """Per SYT prior and baseline, SYT's paired SPL margin (``cost``): the issue's "SPL above the best
    baseline's", with its standard error and its spread over seeds. A baseline that never ran with
    SYT's prior is paired by its runs with the one prior it ran with, which the margin names."""
    def runs(method: str, prior: str) -> dict[tuple, dict]:
        return {placement(r): r for r in rows
                if r["method"] == method and r["prior"] == prior and (method != "syt" or r["cost"] == cost)}

    def spl(by_key: dict[tuple, dict]) -> dict[tuple, float]:
        return {key: r["spl"] or 0.0 for key, r in by_key.items()}

    out = []
    for prior in dict.fromkeys(r["prior"] for r in rows if r["method"] == "syt"):
        syt_runs = runs("syt", prior)
        syt = spl(syt_runs)
        for name in dict.fromkeys(r["method"] for r in rows if r["method"] != "syt"):
            ran = list(dict.fromkeys(r["prior"] for r in rows if r["method"] == name))
            their_prior = prior if prior in ran else ran[0] if len(ran) == 1 else None
            theirs = spl(runs(name, their_prior)) if their_prior else {}
            common = sorted(set(syt) & set(theirs), key=str)
            if not common:
                continue
            diffs = {s: syt[s] - theirs[s] for s in common}
            by_seed = tuple((seed, statistics.fmean([d for s, d in diffs.items() if s[-1] == seed]))
                            for seed in sorted({s[-1] for s in common}))
            out.append(SplMargin(name, prior, their_prior, len(common), scenario_mean({s: syt[s] for s in common}),
                                 scenario_mean({s: theirs[s] for s in common}), paired_stderr(diffs), by_seed,
                                 len(_per_scenario(diffs)), scope([syt_runs[s] for s in common]),
                                 sum(d > 0 for d in diffs.values())))
    return out


def scenario_mean(values: dict[tuple, float]) -> float:
    """The mean of per-run values keyed by placement (:func:`placement`), each scenario counted once,
    its seeds averaged: as :func:`paired_stderr` counts them, so that a difference of two such means is
    the one its standard error is of, even where scenarios ran with different numbers of seeds."""
    return statistics.fmean(_per_scenario(values))


def _per_scenario(values: dict[tuple, float]) -> list[float]:
    """Per scenario (a placement without its seed), the mean over its seeds."""
    seeds: dict[tuple, list[float]] = {}
    for key, value in values.items():
        seeds.setdefault(key[:-1], []).append(value)
    return [statistics.fmean(v) for v in seeds.values()]


def paired_stderr(diffs: dict[tuple, float]) -> float | None:
    """The standard error of the mean of paired differences keyed by placement (:func:`placement`),
    each scenario (world × start × target) one sample, its seeds averaged: a seed repeats a scenario
    almost exactly (the same room, start and target; only the sensors' noise differs), so seeds are
    not independent samples, and counting them as such understates the error (on `test`, 120 runs of
    40 scenarios: 0.038 where it is 0.063). None below two scenarios."""
    means = _per_scenario(diffs)
    return statistics.stdev(means) / math.sqrt(len(means)) if len(means) > 1 else None


def _difference_md(difference: float, stderr: float | None) -> str:
    """A paired difference for a table cell, its standard error in brackets when there is one."""
    return f"{difference:+.3f}" + ("" if stderr is None else f" ({stderr:.3f})")


@dataclass(frozen=True)
class PriorGain:
    """SYT with one prior against SYT with the reference prior, same cost, on the scenarios both ran
    (world × start × target × seed): SPL over all of them (a failure counts 0), looks over those both found."""

    cost: float
    prior: str
    reference: str
    scenarios: int
    spl: float
    reference_spl: float
    stderr: float | None  # of the paired SPL difference
    found_both: int
    looks: float | None
    reference_looks: float | None
    distinct_scenarios: int = 0  # world × start × target, its seeds averaged: the standard error's samples
    scope: str = ""  # the worlds and seeds of the paired runs

    @property
    def difference(self) -> float:
        return self.spl - self.reference_spl


def prior_gains(rows: list[dict], reference: str = "uniform") -> list[PriorGain]:
    """What each prior buys SYT over ``reference``, paired per scenario: the issue's priors "against
    uniform, reported as SPL and looks"."""
    syt = {(r["cost"], r["prior"], *placement(r)): r for r in rows if r["method"] == "syt"}
    out = []
    for cost, prior in dict.fromkeys(key[:2] for key in syt):
        pairs = [(run, syt[(cost, reference, *key[2:])]) for key, run in syt.items()
                 if key[:2] == (cost, prior) and (cost, reference, *key[2:]) in syt]
        if prior == reference or not pairs:
            continue
        both = [(a["actions"], b["actions"]) for a, b in pairs if a["success"] and b["success"]]
        diffs = {placement(a): (a["spl"] or 0.0) - (b["spl"] or 0.0) for a, b in pairs}
        out.append(PriorGain(cost, prior, reference, len(pairs),
                             scenario_mean({placement(a): a["spl"] or 0.0 for a, _ in pairs}),
                             scenario_mean({placement(b): b["spl"] or 0.0 for _, b in pairs}), paired_stderr(diffs),
                             len(both), mean_of([a for a, _ in both]), mean_of([b for _, b in both]),
                             len(_per_scenario(diffs)), scope([a for a, _ in pairs])))
    return out


def _timed_pairs(rows: list[dict], cost: int = 3) -> list[tuple[str, list[tuple], dict, dict]]:
    """Per baseline: (name, the scenarios both it and SYT with ``cost`` found, SYT's runs, its runs), the
    runs keyed by :func:`_scenario`."""
    syt = {_scenario(r): r for r in rows if r["method"] == "syt" and r["cost"] == cost and r["success"]}
    out = []
    for name in dict.fromkeys(r["method"] for r in rows if r["method"] != "syt"):
        mine = {_scenario(r): r for r in rows if r["method"] == name and r["success"]}
        out.append((name, sorted(set(syt) & set(mine)), syt, mine))
    return out


# --- report.md -------------------------------------------------------------------------------------

def _table_md(prior: str, ours: Tables, rows: list[dict]) -> list[str]:
    title = "Table 2" if prior == "uniform" else "Table 3"
    lines = [f"### {PRIORS[prior]} (prior `{prior}`; the report's {title})", "",
             "| Average per run | " + " | ".join(f"Cost({c})" for c in COSTS) + " |", "|---" * 5 + "|"]
    for metric, label in METRICS.items():
        cells = [f"{cell(ours[prior][metric][i])} ({REPORT[prior][metric][i]:g})" for i in range(4)]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    counts = []
    for c in COSTS:
        members = [r for r in rows if r["method"] == "syt" and r["prior"] == prior and r["cost"] == c]
        counts.append(f"{sum(r['success'] for r in members)}/{len(members)}")
    mine = [r for r in rows if r["method"] == "syt" and r["prior"] == prior]
    return lines + ["| Successful / all runs | " + " | ".join(counts) + " |", "", f"From {scope(mine)}.", ""]


def _stats_md(stats: list[MethodStats], first: str = "Method", latency: bool = True, scoped: bool = True,
             finite: bool = False) -> list[str]:
    """One row per :class:`MethodStats`: success, SPL (and, if ``finite``, SPL over the runs with a finite
    shortest path, their number in brackets), looks and glances, distance, motion, processing and their sum."""
    heads = [first, "Runs", "Success", "SPL"] + ["SPL, finite shortest path (runs)"] * finite
    heads += ["Looks", "Glances", "Distance (m)", "Motion (min)", "Processing (min)", "Motion + processing (min)"]
    heads += ["Planning p50 / p95 (ms): the median run's p50, the 95th percentile of the runs' p95"] * latency
    heads += ["Worlds; seeds"] * scoped
    lines = ["| " + " | ".join(heads) + " |", "|---" * len(heads) + "|"]
    for s in stats:
        rate = "—" if s.success_rate is None else f"{100 * s.success_rate:.1f}%"
        total = s.time_min if s.processing_min is not None else None
        cells = [s.name, str(s.runs), rate, cell(s.spl, 3)] + [f"{cell(s.finite_spl, 3)} ({s.finite_runs})"] * finite
        cells += [cell(s.actions, 1), cell(s.glances, 1), cell(s.distance_m), cell(s.motion_min),
                  cell(s.processing_min), cell(total)]
        cells += [f"{cell(s.latency_p50_ms, 0)} / {cell(s.latency_p95_ms, 0)}"] * latency + [s.scope] * scoped
        lines.append("| " + " | ".join(cells) + " |")
    return lines + [""]


def _per_world_md(rows: list[dict]) -> list[str]:
    worlds: dict[str, list[dict]] = {}
    for r in rows:
        worlds.setdefault(r["world"], []).append(r)
    return ["## Per world", "", "Each world's runs, per method, cost function and prior (looks, distance and times "
            "over successful runs; success and SPL over all).", ""] + _groups_md(worlds)


def _groups_md(groups: dict[str, list[dict]]) -> list[str]:
    """A heading, the scope and a table of variants per group of runs."""
    lines = []
    for name, mine in groups.items():
        lines += [f"### {name}", "", f"From {scope(mine)}.", ""]
        lines += _stats_md([_stats(variant, group) for variant, group in variants(mine)], "Variant", False, False)
    return lines


NEAR_M, FAR_M = 1.5, 3.0  # edges of the groups by SPL's shortest path


def distance_group(row: dict) -> str:
    """Which group by SPL's shortest path a run falls in: the same extra metres cost more SPL the
    shorter that path is, so methods differ most where the target is near (one that looks all around
    before it drives loses little there)."""
    shortest = row["shortest_path_m"]
    if shortest is None:
        return "no position sees the target"
    if shortest == 0:
        return "seen from the start (0 m)"
    if shortest < NEAR_M:
        return f"under {NEAR_M:g} m"
    return f"{NEAR_M:g} m to {FAR_M:g} m" if shortest < FAR_M else f"{FAR_M:g} m or more"


def by_distance(rows: list[dict]) -> dict[str, list[dict]]:
    """The runs in their :func:`distance_group`, the groups from the nearest target to the farthest
    (those no position sees last)."""
    groups: dict[str, list[dict]] = {}
    for r in sorted(rows, key=lambda r: math.inf if r["shortest_path_m"] is None else r["shortest_path_m"]):
        groups.setdefault(distance_group(r), []).append(r)
    return groups


def _by_distance_md(rows: list[dict]) -> list[str]:
    return ["## By how far the target was", "", "Runs grouped by SPL's shortest path from the start (looks, "
            "distance and times over successful runs; success and SPL over all).", ""] + _groups_md(by_distance(rows))


def _priors_md(rows: list[dict]) -> list[str]:
    """SYT with each prior side by side, per cost function."""
    syt = [r for r in rows if r["method"] == "syt"]
    priors = list(dict.fromkeys(r["prior"] for r in syt))
    lines = ["## Priors side by side (SYT)", ""]
    if len(priors) < 2:
        return lines + [f"This sweep ran SYT with one prior ({', '.join(priors) or 'none'}); "
                        "`--priors uniform,tables,surfaces,saliency` compares them.", ""]
    lines += ["`tables` is given knowledge (the surfaces targets stand on); `surfaces` and `saliency` need none (they "
              "learn from the map and the images as the search goes).", "",
              "| Cost | Prior | Runs | Success | SPL | Looks | Distance (m) | Worlds; seeds |", "|---" * 8 + "|"]
    for cost in sorted({r["cost"] for r in syt}):
        for prior in priors:
            members = [r for r in syt if r["cost"] == cost and r["prior"] == prior]
            if members:
                s = _stats(prior, members)
                lines.append(f"| {cost:g} | {prior} | {s.runs} | {100 * s.success_rate:.1f}% | {cell(s.spl, 3)} | "
                             f"{cell(s.actions, 1)} | {cell(s.distance_m)} | {s.scope} |")
    return lines + [""] + _gains_md(rows)


def _gains_md(rows: list[dict]) -> list[str]:
    gains = prior_gains(rows)
    if not gains:
        return []
    lines = ["Each prior against `uniform` on the same scenarios (world × start × target × seed) and cost, paired: "
             "SPL over all (a failure counts 0; the standard error is the paired difference's, "
             "one sample per world × start × target, its seeds averaged), looks over the "
             "scenarios both found.", "",
             "| Cost | Prior | Runs (scenarios) | SPL | SPL with `uniform` | Difference | Both found | Looks | "
             "Looks with `uniform` | Worlds; seeds |", "|---" * 10 + "|"]
    for g in gains:
        lines.append(f"| {g.cost:g} | {g.prior} | {g.scenarios} ({g.distinct_scenarios}) | {g.spl:.3f} | "
                     f"{g.reference_spl:.3f} | {_difference_md(g.difference, g.stderr)} | {g.found_both} | "
                     f"{cell(g.looks, 1)} | {cell(g.reference_looks, 1)} | {g.scope} |")
    return lines + [""]


def _time_md(rows: list[dict]) -> list[str]:
    ok = [r for r in rows if r["success"] and r["method"] == "syt"]  # set against the report's SYT
    measured = [r for r in ok if r["processing_min"] is not None]
    lines = ["## Time: motion and processing", "",
             "Motion is the robot's clock (driving, turning, slewing the head, capturing). Processing is the measured "
             "wall time of capture transfer, stereo, detection, mapping and planning, at the looks and along the moves "
             "(the navigator's stereo, localisation and routing). The report's minutes included "
             f"about {REPORT_PROCESSING_S:g} s of processing per action, so only motion + processing compares like "
             "with like; Tables 2 and 3 show that sum."]
    if len(measured) < len(ok):
        lines[-1] += (f" **{len(ok) - len(measured)} of {len(ok)} successful SYT runs did not measure "
                      "processing**: their time is motion only and understates the report's kind of minutes.")
    per_action = mean_of([60 * r["processing_min"] / r["actions"] for r in measured if r["actions"]])
    if per_action is not None:
        lines[-1] += (f" Ours: {per_action:.1f} s of processing per action (mean over {len(measured)} "
                      f"successful SYT runs; {scope(measured)}).")
    return lines + [""]


def _margins_md(rows: list[dict]) -> list[str]:
    margins = spl_margins(rows)
    if not margins:
        return []
    lines = ["SPL of SYT with cost 3 against each baseline on the scenarios (start × target × seed) both ran, "
             "paired; a failure counts 0. A baseline that did not run with SYT's prior is paired by the one prior "
             "it ran with (its tours do not read the prior; only its candidate viewpoints do). The standard error is "
             "the paired difference's, one sample per world × start × target with its seeds averaged (a seed "
             "repeats a scenario almost exactly, so seeds are not independent samples); per seed, the mean "
             f"difference. {_yardsticks_md(margins)}", "",
             "| SYT's prior | Baseline (its prior) | Runs (scenarios) | SYT SPL | Baseline SPL | SYT − baseline | "
             "Per seed | Worlds; seeds |",
             "|---" * 8 + "|"]
    for m in margins:
        seeds = ", ".join(f"{seed:g}: {d:+.3f}" for seed, d in m.by_seed)
        lines.append(f"| {m.prior} | {m.baseline} ({m.their_prior}) | {m.scenarios} ({m.distinct_scenarios}) | "
                     f"{m.syt:.3f} | {m.theirs:.3f} | {_difference_md(m.difference, m.stderr)} | {seeds} | "
                     f"{m.scope} |")
    for prior in dict.fromkeys(m.prior for m in margins):
        rivals = [m for m in margins if m.prior == prior and m.baseline not in YARDSTICKS]
        if rivals:
            best = max(rivals, key=lambda m: m.theirs)
            lines += ["", f"SYT with prior `{prior}`: the best baseline ({', '.join(YARDSTICKS)} excluded) is "
                          f"**{best.baseline}** (prior `{best.their_prior}`), SYT − it = **{best.difference:+.3f}**."]
    return lines + [""]


def _yardsticks_md(margins: list[SplMargin]) -> str:
    """What a baseline given the truth is: a strong reference, and why it is not a bound."""
    from offboard.experiments.baselines import BaselineConfig  # here: it brings the planner, which the report needs not
    from offboard.experiments.world_facts import SeeingCriteria

    names = ", ".join(YARDSTICKS)
    ahead = "; ".join(f"SYT with prior `{m.prior}` scores above {m.baseline} in {m.syt_ahead} of {m.scenarios} "
                      "paired runs" for m in margins if m.baseline in YARDSTICKS)
    return (f"{names.capitalize()} is given the truth: a strong reference, not a rival, and not a bound on what a "
            f"search can reach: it drives to a stricter viewpoint (a detection rate of "
            f"{BaselineConfig().oracle_view.min_rate:g}, with margins) than SPL's shortest path is measured to "
            f"({SeeingCriteria().min_rate:g}), so a search that sees the target from nearer can score a higher "
            "SPL" + (f" ({ahead})." if ahead else "."))


def _paired_md(rows: list[dict]) -> list[str]:
    pairs = _timed_pairs(rows)
    if not pairs:
        return ["No baseline runs (`--baselines`).", ""]
    lines = _margins_md(rows) + [
             "Mean time to find (robot time and processing) on the runs (start × target × prior × seed) that "
             "both SYT with cost 3 and the baseline solved; in brackets, the scenarios (world × start × target) they "
             "are of:", "", "| Baseline | Runs (scenarios) | SYT (min) | Baseline (min) | SYT ahead | Worlds; seeds |",
             "|---" * 6 + "|"]
    for name, common, syt, theirs_by_scenario in pairs:  # each run's minutes: robot time and measured processing
        mine, theirs = (mean_of([runs[s]["time_min"] for s in common]) for runs in (syt, theirs_by_scenario))
        ahead = "—" if mine is None or theirs is None else ("yes" if mine < theirs else "no")
        scenarios = len({s[:3] for s in common})
        lines.append(f"| {name} | {len(common)} ({scenarios}) | {cell(mine)} | {cell(theirs)} | {ahead} | "
                     f"{scope([syt[s] for s in common]) if common else '—'} |")
    return lines + [""]


def _errors_md(rows: list[dict]) -> list[str]:
    """Runs that crashed or timed out (counted as failures above), grouped by their message."""
    errors: dict[str, int] = {}
    for r in rows:
        if r["status"].startswith("error"):
            message = (r["error"] or r["status"]).split(": ", 1)[-1][:160]
            errors[message] = errors.get(message, 0) + 1
    if not errors:
        return ["No run crashed or timed out.", ""]
    lines = [f"{sum(errors.values())} runs crashed or timed out (counted as failures above; rerunning the same "
             "command tries them again):", ""]
    return lines + [f"- {n} × `{message}`" for message, n in sorted(errors.items(), key=lambda e: -e[1])] + [""]


def _wall_md(rows: list[dict], sweep: tuple[int, float, int] | None = None) -> list[str]:
    walls = [r["run_wall_s"] for r in rows if r["run_wall_s"] is not None]
    if not walls:
        return []
    ran = [] if sweep is None else [f"The sweep that wrote this report ran {sweep[0]} runs in **{sweep[1] / 60:.1f} min** "
                                    f"of wall time with {sweep[2]} jobs.", ""]
    methods = dict.fromkeys(r["method"] for r in rows)
    by_method = {m: mean_of([r["run_wall_s"] for r in rows if r["method"] == m]) for m in methods}
    return ["## Wall time", "", *ran, f"{len(walls)} runs took {sum(walls) / 60:.1f} min of worker wall time in all "
            f"(mean {statistics.fmean(walls):.0f} s, median {statistics.median(walls):.0f} s, max {max(walls):.0f} s "
            "per run; a worker's first run includes its agent's start-up); with N jobs the sweep's wall time is about "
            "this sum / N. "
            "Mean per run: " + ", ".join(f"{m} {cell(w, 0)} s" for m, w in by_method.items()) + ".", ""]


def render(rows: list[dict], sweep: tuple[int, float, int] | None = None, looks: list[list[Look]] = (),
           last_looks: dict[str, Look | None] | None = None) -> str:
    """The report; ``sweep``: (runs, wall seconds, jobs) of the sweep that just ran, if one did; ``looks``:
    each SYT run's logged looks, in the order of its rows (the calibration and the coverage);
    ``last_looks``: each failed run's last look with the simulator's truth, by row key (the failures)."""
    ours = syt_tables(rows)
    syt = [r for r in rows if r["method"] == "syt"]
    rate = sum(r["success"] for r in syt) / len(syt) if syt else None
    lines = ["# Experiment: the SYT search against the report's §5.2", "",
             f"{len(rows)} runs ({len(syt)} SYT) from {scope(rows)}. Success: the target found and the estimate "
             "within 0.5 m of its true centre. **Actions, time and distance are averaged over successful runs; success "
             "rates and SPL over all runs.** Time is motion (the robot's simulated clock) plus measured processing "
             "(see *Time*). Each cell: ours (the report's).", "",
             "## Tables 2 and 3", ""]
    for prior in PRIORS:
        lines += _table_md(prior, ours, rows)
    lines += _time_md(rows)
    lines += ["## Success, SPL, planning latency", "",
              f"SYT success rate, all its runs pooled: **{'—' if rate is None else f'{100 * rate:.1f}%'}** "
              f"(report: {100 * REPORT_SUCCESS:.0f}%). "
              "SPL: success × shortest path / max(driven, shortest path), the shortest path being the collision-free "
              "any-angle path on the true floor map to the closest position from which the detector's measured "
              "table gives a rate ≥ 0.8, with the camera aimed within its tilt limits, the whole picture in the image and nothing "
              "across the lines to its centre and its corners drawn in by a tenth."]
    unseen = any(r["shortest_path_m"] is None for r in rows)
    lines[-1] += _unseen_md(rows)
    lines += [""] + _stats_md(method_stats(rows), finite=unseen) + _errors_md(rows)
    lines += ["### Per method, cost function and prior", ""]
    lines += _stats_md([_stats(name, group) for name, group in variants(rows)], "Variant", finite=unseen)
    lines += failures_md(variants(rows), last_looks or {})
    lines += _per_world_md(rows) + _by_distance_md(rows) + _priors_md(rows)
    source = f"the SYT runs ({scope(syt)})"
    every_look = [look for run in looks for look in run]
    lines += calibration_md(calibration(every_look), source)
    # found, however well then placed: P[F] is the chance that the looks detect the target
    found_at = [int(r["actions"]) if r["found"] else None for r in syt]
    lines += coverage_md(coverage(list(zip(looks, found_at))), source)
    lines += localisation_md(every_look, source)
    viewed, left_out = viewed_runs(syt, looks)
    lines += target_views_md(*target_views(viewed), source, left_out)
    lines += ["## SYT against the baselines", ""] + _paired_md(rows)
    lines += ["## The report's six conclusions", ""] + _conclusions_md(syt, ours)
    lines += [""] + _wall_md(rows, sweep) + ["## Plots", ""] + [f"![{p}]({p})" for p in PLOTS] + [""]
    return "\n".join(lines)


def _unseen_md(rows: list[dict]) -> str:
    """What SPL makes of the runs from which no position sees the target by its rule (an infinite
    shortest path): they score 0, found or not; said where SPL is first given, with SPL without them."""
    unseen = [r for r in rows if r["shortest_path_m"] is None]
    if not unseen:
        return ""
    found = [r for r in unseen if r["success"]]
    text = (f" **{len(found)} successful runs score SPL 0: no position sees the target by SPL's rule** "
            f"(worlds: {scope(found)})." if found else "")
    if len(unseen) > len(found):
        text += f" {len(unseen)} runs in all have no finite shortest path ({scope(unseen)})."
    return text + " The column *SPL, finite shortest path* gives SPL over the other runs, their number in brackets."


def _conclusions_md(syt: list[dict], ours: Tables) -> list[str]:
    """Each conclusion's verdict, or, when the sweep did not run all eight cells (costs 1-4, with and
    without knowledge) they compare, one line saying so instead of six that cannot tell."""
    ran = {(r["cost"], r["prior"]) for r in syt}
    missing = [(c, p) for p in PRIORS for c in COSTS if (c, p) not in ran]
    if missing:
        return [f"Not checked: they compare SYT with costs 1-4, with and without knowledge, and this sweep did not "
                f"run {', '.join(f'cost {c} with `{p}`' for c, p in missing)} (`--preset paper` runs them all)."]
    verdict = {True: "**agrees**", False: "**does not agree**", None: "**cannot tell** (a cell has no success)"}
    return [f"{i}. {v.claim} — {verdict[v.agrees]}: {v.evidence}." for i, v in enumerate(conclusions(ours), 1)]


# --- plots -----------------------------------------------------------------------------------------

PLOTS = ("actions.png", "time.png", "distance.png", "success.png")
_COLOURS = ((180, 119, 31), (14, 127, 255), (232, 199, 174), (120, 187, 255), (44, 160, 44), (40, 39, 214),
            (189, 103, 148), (75, 86, 140))  # BGR


def _nice_top(value: float) -> float:
    if value <= 0:
        return 1.0
    step = 10 ** math.floor(math.log10(value))
    return next(m * step for m in (1, 2, 2.5, 5, 10) if m * step >= value)


def bar_chart(path: Path, title: str, groups: list[str], series: list[tuple[str, list[float | None]]],
              unit: str, size: tuple[int, int] = (900, 520)) -> None:
    """Grouped bars: one group per label in ``groups``, one bar per series (missing values left out)."""
    w, h = size
    left, right, top, bottom = 70, 20, 60, 90
    img = np.full((h, w, 3), 255, np.uint8)
    font = cv2.FONT_HERSHEY_SIMPLEX
    peak = _nice_top(max((v for _, vs in series for v in vs if v is not None), default=1.0))
    y_of = lambda v: int(h - bottom - (h - top - bottom) * v / peak)  # noqa: E731 - local scale
    cv2.putText(img, title, (left, 30), font, 0.65, (0, 0, 0), 1, cv2.LINE_AA)
    for i in range(6):
        v = peak * i / 5
        cv2.line(img, (left, y_of(v)), (w - right, y_of(v)), (225, 225, 225), 1)
        cv2.putText(img, f"{v:g}", (8, y_of(v) + 4), font, 0.4, (60, 60, 60), 1, cv2.LINE_AA)
    cv2.putText(img, unit, (8, top - 12), font, 0.4, (60, 60, 60), 1, cv2.LINE_AA)
    slot = (w - left - right) / max(len(groups), 1)
    bar = slot * 0.8 / max(len(series), 1)
    for g, label in enumerate(groups):
        x0 = left + g * slot + slot * 0.1
        cv2.putText(img, label, (int(x0), h - bottom + 18), font, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
        for s, (_, values) in enumerate(series):
            if values[g] is None:
                continue
            xa, xb = int(x0 + s * bar), int(x0 + (s + 1) * bar) - 2
            cv2.rectangle(img, (xa, y_of(values[g])), (xb, y_of(0)), _COLOURS[s % len(_COLOURS)], -1)
            cv2.putText(img, f"{values[g]:.3g}", (xa, y_of(values[g]) - 4), font, 0.33, (0, 0, 0), 1, cv2.LINE_AA)
    cv2.line(img, (left, y_of(0)), (w - right, y_of(0)), (0, 0, 0), 1)
    for s, (name, _) in enumerate(series):
        x, y = left + (s % 4) * 200, h - bottom + 42 + (s // 4) * 20
        cv2.rectangle(img, (x, y - 10), (x + 14, y + 2), _COLOURS[s % len(_COLOURS)], -1)
        cv2.putText(img, name, (x + 20, y), font, 0.42, (0, 0, 0), 1, cv2.LINE_AA)
    write_bgr(path, img)


def write_plots(rows: list[dict], out: Path) -> list[Path]:
    ours = syt_tables(rows)
    groups = [f"Cost({c})" for c in COSTS]
    paths = []
    for name, metric, unit in (("actions.png", "actions", "looks"), ("time.png", "time_min", "minutes"),
                               ("distance.png", "distance_m", "metres")):
        series = [(f"ours, {PRIORS[p].lower()}", ours[p][metric]) for p in PRIORS]
        series += [(f"report, {PRIORS[p].lower()}", list(REPORT[p][metric])) for p in PRIORS]
        bar_chart(out / name, f"{METRICS[metric]}: mean over successful SYT runs", groups, series, unit)
        paths.append(out / name)
    stats = method_stats(rows)
    bar_chart(out / "success.png", "Success rate per method (report: 91%)", [s.name for s in stats],
              [("success rate, %", [None if s.success_rate is None else 100 * s.success_rate for s in stats])], "%",
              size=(max(900, 110 * len(stats)), 520))
    return paths + [out / "success.png"]


def write_report(results: Path, out: Path, sweep: tuple[int, float, int] | None = None) -> list[Path]:
    """report.md and the plots beside it; returns what was written."""
    rows = load_results(results)
    logged = {r["key"]: read_looks(Path(results).parent / r["run_dir"] / LOOKS_FILE) if r["run_dir"] else []
              for r in rows if r["method"] == "syt" or not r["success"]}  # each run's file read once
    looks = [logged[r["key"]] for r in rows if r["method"] == "syt"]
    last_looks = {r["key"]: last_true_look(logged[r["key"]]) for r in rows if not r["success"]}
    out.mkdir(parents=True, exist_ok=True)
    report = out / "report.md"
    report.write_text(render(rows, sweep, looks, last_looks))
    return [report, *write_plots(rows, out)]

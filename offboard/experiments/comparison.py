"""Two sweeps of one grid, paired run for run: what a change to the search did.

``syt-offboard compare BASE NEW`` reads each folder's ``results.csv`` and pairs the runs both hold
(method, cost function, prior, world, start, target, seed). A world is known by its file's name, so
the same room given as ``fresh/room-1.toml`` in one sweep and by an absolute path in the other
pairs; a sweep holding two worlds of one name from different folders pairs on the names as typed.
With a fixed ``planned_processing_s`` a run repeats exactly (unless it runs to the budget K, which
counts the processing measured), so a run that changed, changed because of what differs between the
sweeps (the code or the configuration). SPL is paired as the report
pairs SYT with a baseline: a failure counts 0, and its mean and standard error count each scenario once
(:func:`~offboard.experiments.report.paired_stderr`). A run that crashed or timed out (an error row)
counts 0 there too, so an infrastructure failure looks like a loss; the difference over the pairs where
neither side errored is given beside it, with how many pairs it leaves out. Looks and distance are over
the runs both sweeps found. Each variant names the worlds and seeds of its paired runs. The runs are
also grouped by SPL's shortest path
(:func:`~offboard.experiments.report.distance_group`), where a change near the target and one far
from it can cancel out.

Planning time is the one figure the machine's load moves from day to day, so its pairing is only
fair between sweeps run on the same machine on the same day.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from offboard.experiments.calibration import cell
from offboard.experiments.report import (by_distance, load_results, mean_of, paired_stderr, placement, scenario_mean,
                                         scope, variant_name)

RESULTS_FILE = "results.csv"
OUTCOME = ("success", "actions", "distance_m", "spl")  # a run whose outcome differs in any of these changed


@dataclass(frozen=True)
class Side:
    """One sweep's figures on the paired runs."""

    found: int  # runs that succeeded
    spl: float  # over all paired runs, a failure counting 0, each scenario once (its seeds averaged)
    looks: float | None  # over the runs both sweeps found
    distance_m: float | None  # likewise
    errors: int = 0  # runs that crashed or timed out: failures, but not the search's doing


@dataclass(frozen=True)
class PairedGroup:
    """A variant's paired runs, or those of one distance group of it."""

    variant: str  # as the report names it: "SYT cost 3, uniform", "exhaustive, uniform"
    group: str  # "all", or a distance group
    runs: int
    changed: int  # runs whose outcome (:data:`OUTCOME`) differs
    base: Side
    new: Side
    spl_stderr: float | None  # of the paired SPL difference; None below two scenarios
    error_pairs: int = 0  # pairs in which either run crashed or timed out (an error row)
    spl_difference_no_errors: float | None = None  # the paired SPL difference without those pairs; None: no pair left
    spl_stderr_no_errors: float | None = None  # its standard error, each scenario once; None below two scenarios
    scope: str = ""  # the worlds and seeds of the paired runs (base's names)

    @property
    def spl_difference(self) -> float:
        return self.new.spl - self.base.spl


@dataclass(frozen=True)
class PairedLatency:
    """Planning time per decision, paired per run: each run's 95th percentile."""

    variant: str
    runs: int
    base_median_ms: float  # the median run's 95th percentile
    new_median_ms: float
    base_p95_ms: float  # the 95th percentile of the runs' 95th percentiles, the report's figure
    new_p95_ms: float
    difference_ms: float  # mean of new − base, each scenario once (its seeds averaged), as its standard error
    stderr_ms: float | None  # counting each scenario once, as for SPL
    scope: str = ""  # the worlds and seeds of the paired runs (base's names)


@dataclass(frozen=True)
class Comparison:
    base: str
    new: str
    groups: tuple[PairedGroup, ...]
    latency: tuple[PairedLatency, ...]
    only_base: int  # runs in one sweep only: not compared
    only_new: int
    yardstick_changed: int = 0  # paired runs whose shortest path (SPL's l) differs: SPL measured otherwise


def load_sweep(folder: Path) -> list[dict]:
    """The runs of the sweep written to ``folder`` (its ``results.csv``)."""
    results = Path(folder) / RESULTS_FILE
    if not results.is_file():
        raise FileNotFoundError(f"{folder}: no {RESULTS_FILE} here; give a folder that `experiment --out` wrote")
    return load_results(results)


def compare(base_rows: list[dict], new_rows: list[dict], base: str = "base", new: str = "new") -> Comparison:
    """Pair the runs of two sweeps and compare them per variant, in all and per distance group."""
    by_name = _names_are_unique(base_rows) and _names_are_unique(new_rows)
    base_runs, new_runs = ({_run_key(r, by_name): r for r in rows} for rows in (base_rows, new_rows))
    common = [k for k in base_runs if k in new_runs]
    pairs: dict[str, list[tuple[dict, dict]]] = {}
    for key in common:
        pairs.setdefault(variant_name(*key[:3]), []).append((base_runs[key], new_runs[key]))
    groups, latency = [], []
    for variant, both in pairs.items():
        groups.append(_paired(variant, "all", both))
        groups += [_paired(variant, name, [(a, new_runs[_run_key(a, by_name)]) for a in members])
                   for name, members in by_distance([a for a, _ in both]).items()]
        timed = _paired_latency(variant, both)
        if timed:
            latency.append(timed)
    yardstick = sum(base_runs[k]["shortest_path_m"] != new_runs[k]["shortest_path_m"] for k in common)
    return Comparison(base, new, tuple(groups), tuple(latency), len(base_runs) - len(common),
                      len(new_runs) - len(common), yardstick)


def _world_name(world: str) -> str:
    """A world as its file's name: ``dev/room-1000-1``, ``/x/fresh/room-1000-1.toml`` → ``room-1000-1``."""
    return Path(world).name.removesuffix(".toml")


def _names_are_unique(rows: list[dict]) -> bool:
    """Whether no two of the sweep's worlds share a file name (then a name is a world)."""
    worlds = {r["world"] for r in rows}
    return len(worlds) == len({_world_name(w) for w in worlds})


def _run_key(row: dict, by_name: bool) -> tuple:
    world, *rest = placement(row)
    return (row["method"], row["cost"] if row["method"] == "syt" else None, row["prior"],
            _world_name(world) if by_name else world, *rest)


def _paired(variant: str, group: str, pairs: list[tuple[dict, dict]]) -> PairedGroup:
    found_both = [(a, b) for a, b in pairs if a["success"] and b["success"]]

    def side(pick: Callable[[tuple[dict, dict]], dict]) -> Side:
        mine = [pick(p) for p in pairs]
        return Side(sum(r["success"] for r in mine), scenario_mean({placement(r): r["spl"] or 0.0 for r in mine}),
                    *(mean_of([pick(p)[column] for p in found_both]) for column in ("actions", "distance_m")),
                    sum(_errored(r) for r in mine))

    diffs = {placement(a): (b["spl"] or 0.0) - (a["spl"] or 0.0) for a, b in pairs}
    clean = {placement(a): (b["spl"] or 0.0) - (a["spl"] or 0.0) for a, b in pairs
             if not (_errored(a) or _errored(b))}
    changed = sum(any(a[c] != b[c] for c in OUTCOME) for a, b in pairs)
    return PairedGroup(variant, group, len(pairs), changed, side(lambda p: p[0]), side(lambda p: p[1]),
                       paired_stderr(diffs), len(pairs) - len(clean), scenario_mean(clean) if clean else None,
                       paired_stderr(clean) if clean else None, scope([a for a, _ in pairs]))


def _errored(row: dict) -> bool:
    """Whether the run crashed or timed out: a failure, but not the search's doing."""
    return row["status"].startswith("error")


def _paired_latency(variant: str, pairs: list[tuple[dict, dict]]) -> PairedLatency | None:
    timed = [(a, b) for a, b in pairs if a["planning_ms_p95"] is not None and b["planning_ms_p95"] is not None]
    if not timed:
        return None
    base, new = (np.array([p[i]["planning_ms_p95"] for p in timed]) for i in (0, 1))
    diffs = {placement(a): b["planning_ms_p95"] - a["planning_ms_p95"] for a, b in timed}
    return PairedLatency(variant, len(timed), float(np.median(base)), float(np.median(new)),
                         float(np.percentile(base, 95)), float(np.percentile(new, 95)), scenario_mean(diffs),
                         paired_stderr(diffs), scope([a for a, _ in timed]))


# --- output ----------------------------------------------------------------------------------------

def comparison_json(c: Comparison) -> dict:
    """The comparison as one JSON object (differences included, so a tool need not recompute them)."""
    return {"base": c.base, "new": c.new, "only_base": c.only_base, "only_new": c.only_new,
            "yardstick_changed": c.yardstick_changed,
            "groups": [{**asdict(g), "spl_difference": g.spl_difference} for g in c.groups],
            "latency": [asdict(t) for t in c.latency]}


def _without_errors(g: PairedGroup) -> str:
    """The difference over the pairs where neither run errored, beside the one over all, when they differ."""
    if not g.error_pairs:
        return ""
    if g.spl_difference_no_errors is None:
        return f"; without errors: — (all {_pairs(g.error_pairs)} left out)"
    stderr = "" if g.spl_stderr_no_errors is None else f" ({g.spl_stderr_no_errors:.3f})"
    return f"; without errors: {g.spl_difference_no_errors:+.3f}{stderr}, {_pairs(g.error_pairs)} left out"


def _pairs(n: int) -> str:
    return f"{n} pair" + ("" if n == 1 else "s")


def comparison_md(c: Comparison) -> str:
    """The comparison as Markdown: one table of outcomes, one of planning time."""
    errored = any(g.error_pairs for g in c.groups)
    lines = [f"Paired run for run: base `{c.base}`, new `{c.new}`. SPL over all paired runs (a failure counts 0), "
             "its difference's standard error counting each scenario once; looks and distance over the runs "
             "both found." + (" A crashed or timed-out run counts 0 too; beside the difference, the difference (SE) "
                              "over the pairs where neither run errored, and how many pairs that leaves out."
                              if errored else ""), "",
             "| Variant | Runs | Changed | Successes, base / new | SPL, base → new | Difference (SE) | Looks | "
             "Distance (m) |", "|---" * 8 + "|"]
    for g in c.groups:
        name = g.variant if g.group == "all" else f"… {g.group}"
        stderr = "" if g.spl_stderr is None else f" ({g.spl_stderr:.3f})"
        lines.append(f"| {name} | {g.runs} | {g.changed} | {g.base.found} / {g.new.found} | "
                     f"{g.base.spl:.3f} → {g.new.spl:.3f} | {g.spl_difference:+.3f}{stderr}{_without_errors(g)} | "
                     f"{cell(g.base.looks, 1)} → {cell(g.new.looks, 1)} | "
                     f"{cell(g.base.distance_m)} → {cell(g.new.distance_m)} |")
    lines += [""] + [f"{g.variant}: paired runs from {g.scope}." for g in c.groups if g.group == "all"]
    if c.latency:
        lines += ["", "Planning time per decision, each run's 95th percentile (fair only between sweeps run on the "
                      "same machine the same day); the paired difference is the mean of new − base, each scenario "
                      "once (its seeds averaged), as its standard error counts them:", "",
                  "| Variant | Runs | Median run, base → new (ms) | 95th percentile of runs, base → new (ms) | "
                  "Paired difference (SE) |", "|---" * 5 + "|"]
        for t in c.latency:
            stderr = "" if t.stderr_ms is None else f" ({t.stderr_ms:.1f})"
            lines.append(f"| {t.variant} | {t.runs} | {t.base_median_ms:.0f} → {t.new_median_ms:.0f} | "
                         f"{t.base_p95_ms:.0f} → {t.new_p95_ms:.0f} | {t.difference_ms:+.1f}{stderr} |")
        lines += [""] + [f"{t.variant}: timed runs from {t.scope}." for t in c.latency]
    crashed = "; ".join(f"{g.variant}: {g.base.errors} in base, {g.new.errors} in new" for g in c.groups
                        if g.group == "all" and (g.base.errors or g.new.errors))
    if crashed:
        lines += ["", "Crashed or timed out, counted as failures though not the search's doing (run `experiment` "
                      f"again with the same --out to redo them): {crashed}."]
    if c.only_base or c.only_new:
        lines += ["", f"Not compared: {c.only_base} runs only in base, {c.only_new} only in new."]
    if c.yardstick_changed:
        lines += ["", f"**{c.yardstick_changed} paired runs have another shortest path in new**: SPL's yardstick "
                      "changed between the sweeps (the code that measures it, or the worlds), so their SPL "
                      "difference is not the search's alone."]
    return "\n".join(lines) + "\n"

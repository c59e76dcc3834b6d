"""The report: per-world tables, motion and processing apart, priors side by side, and the calibration of
expected against realised P from each run's looks.jsonl."""

from __future__ import annotations

import csv
import json
import statistics
from pathlib import Path

import pytest
from conftest import experiment_args

from offboard.experiments import harness
from offboard.experiments.calibration import (LOOKS_FILE, Look, calibration, coverage, coverage_md, parse_look,
                                              read_looks)
from offboard.experiments.harness import Run, make_row
from offboard.experiments.report import (COLUMNS, REQUIRED_COLUMNS, append_row, distance_group, finished_keys,
                                         load_results, prior_gains, scope, spl_margins, write_report)
from offboard.experiments.world_facts import load_facts

SUMMARY = {"found": True, "status": "found", "actions": 6, "positions_visited": 2, "distance_m": 3.0,
           "robot_time_s": 240.0, "wall_time_s": 30.0, "planning_ms_p50": 40.0, "planning_ms_p95": 80.0,
           "prob_outside": 0.0, "prob_inside": 1.0, "success_prob": 0.9, "cost_function": 3, "detector": "sift",
           "decisions": 6, "prior": "uniform"}
TARGETS = {"paper-lab": (1.7, 4.65, 0.75, -90.0), "office": (4.3, 2.6, 0.74, -90.0)}
STARTS = {"paper-lab": (4.5, 0.6, 90.0), "office": (2.625, 3.125, 0.0)}


def _look(expected: float, realised: float, detected: bool = False) -> dict:
    return {"action": 1, "expected_p": expected, "realised_p": realised, "detected": detected,
            "processing_s": 2.0, "motion_s": 5.0}


def _row(results: Path, method: str, world: str, prior: str, seed: int, motion_s: float | None,
         processing_s: float | None, looks: list[dict] = (), **outcome) -> dict:
    x, y, z, yaw = TARGETS[world]
    summary = {**SUMMARY, "target_estimate_m": [x, y - 0.05, z + 0.1], **outcome}
    if motion_s is not None:
        summary.update(motion_time_s=motion_s, processing_time_s=processing_s)
    run = Run(method, world, STARTS[world], TARGETS[world], 3 if method == "syt" else None, prior, seed)
    row = make_row(run, load_facts(world), summary, 10.0)
    append_row(results, row)
    run_dir = results.parent / row["run_dir"]
    run_dir.mkdir(parents=True, exist_ok=True)
    (run_dir / LOOKS_FILE).write_text("".join(json.dumps(look) + "\n" for look in looks))
    return row


def test_rows_carry_motion_and_processing_time_and_glances_and_keep_the_old_columns_first(tmp_path):
    results = tmp_path / "results.csv"
    row = _row(results, "syt", "office", "uniform", 0, 120.0, 60.0, glances=7)
    assert row["motion_time_s"] == 120.0 and row["processing_time_s"] == 60.0 and row["run_dir"].startswith("runs/")
    assert COLUMNS[:7] == ("method", "world", "start", "target", "cost", "prior", "seed")
    assert COLUMNS[-4:] == ("motion_time_s", "processing_time_s", "run_dir", "glances") and COLUMNS[-5] == "key"
    _row(results, "syt", "office", "uniform", 1, None, None)  # a search that did not measure them
    loaded = {r["seed"]: r for r in load_results(results)}
    assert loaded[0]["time_min"] == pytest.approx(3.0) and loaded[0]["processing_min"] == pytest.approx(1.0)
    assert loaded[1]["processing_min"] is None and loaded[1]["time_min"] == pytest.approx(4.0)  # robot clock only
    assert loaded[0]["glances"] == 7 and loaded[1]["glances"] is None


def test_the_report_has_a_table_per_world_times_apart_and_names_worlds_and_seeds(tmp_path):
    results = tmp_path / "results.csv"
    for world in ("paper-lab", "office"):
        for method in ("syt", "frontier", "oracle"):
            for seed in (0, 1):
                _row(results, method, world, "uniform", seed, 100.0 + 50 * (method == "syt"), 30.0, glances=4 + seed)
    write_report(results, tmp_path)
    text = (tmp_path / "report.md").read_text()
    for section in ("## Per world", "### paper-lab", "### office", "## Time: motion and processing",
                    "## Calibration: expected against realised P", "## Priors side by side (SYT)"):
        assert section in text, section
    office = text.split("### office")[1].split("##")[0]
    assert "From office; seeds 0,1; 1 start × target scenarios." in office
    assert "| SYT cost 3, uniform | 2 | 100.0% |" in office and "| frontier, uniform | 2 | 100.0% |" in office
    # motion 2.50 min, processing 0.50, their sum 3.00: shown apart and summed
    assert "| 2.50 | 0.50 | 3.00 |" in office
    assert "| Looks | Glances | Distance (m) |" in office and "| 6.0 | 4.5 | 3.00 |" in office  # glances: 4 and 5
    assert "about 15 s of processing per action" in text and "5.0 s of processing per action" in text
    assert "paper-lab, office; seeds 0,1" in text


def test_the_spl_margin_pairs_scenarios_and_the_best_baseline_is_never_the_oracle(tmp_path):
    results = tmp_path / "results.csv"
    for seed in (0, 1, 2, 3):  # seed 3: SYT alone, so it has no pair and stays out of the margin
        _row(results, "syt", "office", "uniform", seed, 100.0, 30.0, distance_m=0.0)
    for seed in (0, 1, 2):
        _row(results, "oracle", "office", "uniform", seed, 100.0, 30.0, distance_m=0.0)
        _row(results, "exhaustive", "office", "uniform", seed, 100.0, 30.0, found=seed > 0, distance_m=8.0 + seed)
    _row(results, "syt", "office", "tables", 1, 100.0, 30.0, distance_m=0.0)  # baselines ran with uniform only
    rows = load_results(results)
    spl = {(r["method"], r["seed"]): r["spl"] or 0.0 for r in rows}
    diffs = [spl["syt", s] - spl["exhaustive", s] for s in (0, 1, 2)]
    assert spl["syt", 0] == 1.0 and 0 < spl["exhaustive", 1] < 1 and spl["exhaustive", 0] == 0
    margin = {m.baseline: m for m in spl_margins(rows) if m.prior == "uniform"}
    assert margin["exhaustive"].scenarios == 3
    assert margin["exhaustive"].difference == pytest.approx(sum(diffs) / 3)
    assert margin["exhaustive"].stderr is None  # three seeds of one scenario are one sample, not three
    assert [d for _, d in margin["exhaustive"].by_seed] == pytest.approx(diffs)
    assert margin["oracle"].difference == 0.0
    tables = {m.baseline: m for m in spl_margins(rows) if m.prior == "tables"}
    assert tables["exhaustive"].their_prior == "uniform" and tables["exhaustive"].scenarios == 1
    assert tables["exhaustive"].difference == pytest.approx(diffs[1])
    write_report(results, tmp_path)
    text = (tmp_path / "report.md").read_text()
    assert ("SYT with prior `uniform`: the best baseline (oracle excluded) is **exhaustive** (prior `uniform`), "
            f"SYT − it = **{sum(diffs) / 3:+.3f}**") in text


def test_the_oracle_is_called_a_strong_reference_not_a_ceiling_as_a_search_can_beat_its_spl(tmp_path):
    results = tmp_path / "results.csv"
    for seed, (mine, oracle) in enumerate(((0.0, 10.0), (10.0, 10.0))):  # seed 0: SYT drives less, its SPL higher
        _row(results, "syt", "office", "uniform", seed, 100.0, 30.0, distance_m=mine)
        _row(results, "oracle", "office", "uniform", seed, 100.0, 30.0, distance_m=oracle)
    write_report(results, tmp_path)
    text = (tmp_path / "report.md").read_text()
    assert "ceiling" not in text and "bound what a search can reach" not in text
    assert "Oracle is given the truth: a strong reference, not a rival, and not a bound" in text
    assert ("stricter viewpoint (a detection rate of 0.9, with margins) than SPL's shortest path is measured to "
            "(0.8)") in text
    assert "SYT with prior `uniform` scores above oracle in 1 of 2 paired runs" in text
    [margin] = spl_margins(load_results(results))
    assert margin.syt_ahead == 1 and margin.difference > 0


def test_paired_tables_count_runs_and_scenarios_apart_and_name_their_worlds_and_seeds(tmp_path):
    results = tmp_path / "results.csv"
    for seed in (0, 1, 2):  # three seeds of one office scenario, one seed of a paper-lab one
        _row(results, "syt", "office", "uniform", seed, 100.0, 30.0)
        _row(results, "syt", "office", "tables", seed, 100.0, 30.0)
        _row(results, "exhaustive", "office", "uniform", seed, 100.0, 30.0, found=seed > 0)
    _row(results, "syt", "paper-lab", "uniform", 0, 100.0, 30.0)
    _row(results, "exhaustive", "paper-lab", "uniform", 0, 100.0, 30.0)
    write_report(results, tmp_path)
    text = (tmp_path / "report.md").read_text()
    margin_row = next(line for line in text.splitlines() if line.startswith("| uniform | exhaustive (uniform) |"))
    assert margin_row.startswith("| uniform | exhaustive (uniform) | 4 (2) | ")
    assert margin_row.endswith("| office, paper-lab; seeds 0,1,2; 2 start × target scenarios |")
    assert "| Runs (scenarios) | SYT SPL |" in text and "| Scenarios |" not in text
    assert "| 3 | tables | 3 (1) | " in text  # the prior against uniform
    # time to find: the runs (same prior) SYT and exhaustive both found, of two scenarios
    timed = next(line for line in text.split("Mean time to find")[1].splitlines() if line.startswith("| exhaustive | "))
    assert timed.startswith("| exhaustive | 3 (2) | ") and timed.endswith(
        "| office, paper-lab; seeds 0,1,2; 2 start × target scenarios |")
    rows = load_results(results)
    margin = {m.prior: m for m in spl_margins(rows)}
    assert (margin["uniform"].scenarios, margin["uniform"].distinct_scenarios) == (4, 2)  # the stderr's n is 2
    assert (margin["tables"].scenarios, margin["tables"].distinct_scenarios) == (3, 1)
    [gain] = prior_gains(rows)
    assert (gain.scenarios, gain.distinct_scenarios) == (3, 1)
    assert gain.scope == "office; seeds 0,1,2; 1 start × target scenarios"


def test_successful_runs_no_position_sees_are_said_to_score_spl_0_where_spl_is_first_given(tmp_path):
    results = tmp_path / "results.csv"
    for seed in (0, 1, 2):
        row = _row(tmp_path / "scratch.csv", "syt", "office", "uniform", seed, 100.0, 30.0)
        unseen = seed == 2  # found, but by SPL's rule no position sees the target: SPL 0
        append_row(results, {**row, "shortest_path_m": "" if unseen else row["shortest_path_m"],
                             "spl": 0.0 if unseen else row["spl"]})
    rows = load_results(results)
    finite = statistics.fmean([r["spl"] for r in rows if r["seed"] != 2])
    write_report(results, tmp_path)
    text = (tmp_path / "report.md").read_text()
    first = text.split("## Success, SPL, planning latency")[1].split("### ")[0]
    assert ("**1 successful runs score SPL 0: no position sees the target by SPL's rule** "
            "(worlds: office; seeds 2; 1 start × target scenarios).") in first
    assert "| SPL | SPL, finite shortest path (runs) |" in first
    every = statistics.fmean([r["spl"] for r in rows])
    assert f"| syt (all costs) | 3 | 100.0% | {every:.3f} | {finite:.3f} (2) |" in first


def test_a_report_whose_every_target_is_seen_has_no_finite_spl_column(tmp_path):
    results = tmp_path / "results.csv"
    _row(results, "syt", "office", "uniform", 0, 100.0, 30.0)
    write_report(results, tmp_path)
    text = (tmp_path / "report.md").read_text()
    assert "score SPL 0" not in text and "finite shortest path" not in text


def test_the_standard_error_counts_each_scenario_once_its_seeds_averaged(tmp_path):
    results = tmp_path / "results.csv"
    driven = {"office": (8.0, 9.0, 10.0), "paper-lab": (12.0, 16.0, 20.0)}
    for world, metres in driven.items():
        for seed, distance_m in enumerate(metres):
            _row(results, "syt", world, "uniform", seed, 100.0, 30.0, distance_m=0.0)
            _row(results, "exhaustive", world, "uniform", seed, 100.0, 30.0, distance_m=distance_m)
            _row(results, "syt", world, "tables", seed, 100.0, 30.0, distance_m=distance_m)
    rows = load_results(results)
    spl = {(r["method"], r["prior"], r["world"], r["seed"]): r["spl"] or 0.0 for r in rows}
    diffs = {(w, s): spl["syt", "uniform", w, s] - spl["exhaustive", "uniform", w, s] for w in driven for s in range(3)}
    assert len(set(diffs.values())) == 6
    scenario_means = [statistics.fmean(diffs[w, s] for s in range(3)) for w in driven]
    expected = statistics.stdev(scenario_means) / 2 ** 0.5
    assert expected != pytest.approx(statistics.stdev(diffs.values()) / 6 ** 0.5)
    margin = {m.baseline: m for m in spl_margins(rows) if m.prior == "uniform"}["exhaustive"]
    assert margin.scenarios == 6 and margin.stderr == pytest.approx(expected)
    tables = {g.prior: g for g in prior_gains(rows)}["tables"]  # the same pairs, the other way round
    assert tables.stderr == pytest.approx(expected)


def test_with_more_seeds_in_one_scenario_the_margin_still_counts_each_scenario_once(tmp_path):
    results = tmp_path / "results.csv"
    seeds = {"office": (0, 1, 2), "paper-lab": (0,)}  # an interrupted sweep: paper-lab ran one seed
    for world, ran in seeds.items():
        for seed in ran:
            _row(results, "syt", world, "uniform", seed, 100.0, 30.0, distance_m=0.0)
            _row(results, "exhaustive", world, "uniform", seed, 100.0, 30.0, distance_m=8.0 + 4 * seed)
            _row(results, "syt", world, "tables", seed, 100.0, 30.0, distance_m=8.0 + 4 * seed)
    rows = load_results(results)
    spl = {(r["method"], r["prior"], r["world"], r["seed"]): r["spl"] or 0.0 for r in rows}
    per_scenario = [statistics.fmean(spl["syt", "uniform", w, s] - spl["exhaustive", "uniform", w, s] for s in ran)
                    for w, ran in seeds.items()]
    per_run = statistics.fmean(spl["syt", "uniform", w, s] - spl["exhaustive", "uniform", w, s]
                               for w, ran in seeds.items() for s in ran)
    assert per_run != pytest.approx(statistics.fmean(per_scenario))
    margin = {m.baseline: m for m in spl_margins(rows) if m.prior == "uniform"}["exhaustive"]
    assert margin.difference == pytest.approx(statistics.fmean(per_scenario))  # the mean its error is of
    assert margin.stderr == pytest.approx(statistics.stdev(per_scenario) / 2 ** 0.5)
    gain = {g.prior: g for g in prior_gains(rows)}["tables"]
    assert gain.spl - gain.reference_spl == pytest.approx(-statistics.fmean(per_scenario))

def test_runs_are_grouped_by_how_far_the_target_was_nearest_first(tmp_path):
    results = tmp_path / "results.csv"
    shortest_paths = (4.0, "", 1.5, 0.7, 0.0, 2.9, 3.0)
    for seed, shortest in enumerate(shortest_paths):
        row = _row(tmp_path / "scratch.csv", "syt", "office", "uniform", seed, 100.0, 30.0)
        append_row(results, {**row, "shortest_path_m": shortest})
    groups = [distance_group(r) for r in sorted(load_results(results), key=lambda r: r["seed"])]
    assert groups == ["3 m or more", "no position sees the target", "1.5 m to 3 m", "under 1.5 m",
                      "seen from the start (0 m)", "1.5 m to 3 m", "3 m or more"]
    write_report(results, tmp_path)
    section = (tmp_path / "report.md").read_text().split("## By how far the target was")[1].split("\n## ")[0]
    headings = [line[4:] for line in section.splitlines() if line.startswith("### ")]
    assert headings == ["seen from the start (0 m)", "under 1.5 m", "1.5 m to 3 m", "3 m or more",
                        "no position sees the target"]
    runs = [line.split(" | ")[1] for line in section.splitlines() if line.startswith("| SYT cost 3, uniform |")]
    assert runs == ["1", "1", "2", "2", "1"]


def test_processing_not_measured_is_said_and_not_summed(tmp_path):
    results = tmp_path / "results.csv"
    _row(results, "syt", "office", "uniform", 0, 100.0, 30.0)
    _row(results, "syt", "office", "uniform", 1, None, None)
    write_report(results, tmp_path)
    text = (tmp_path / "report.md").read_text()
    assert "**1 of 2 successful SYT runs did not measure processing**" in text
    assert "| SYT cost 3, uniform | 2 | 100.0% | " in text and "| — | — |" in text  # no partial means


def test_the_processing_set_against_the_report_s_is_syt_s_alone(tmp_path):
    """The baselines' runs were averaged into "Ours", beside the report's 15 s for its SYT."""
    results = tmp_path / "results.csv"
    _row(results, "syt", "office", "uniform", 0, 100.0, 30.0)  # 6 actions: 5 s each
    _row(results, "exhaustive", "office", "uniform", 0, 100.0, 90.0)
    write_report(results, tmp_path)
    assert "Ours: 5.0 s of processing per action (mean over 1 successful SYT runs" in (tmp_path / "report.md").read_text()


def test_priors_are_shown_side_by_side(tmp_path):
    results = tmp_path / "results.csv"
    for prior in ("uniform", "tables", "surfaces", "saliency"):
        _row(results, "syt", "office", prior, 0, 100.0, 30.0)
    write_report(results, tmp_path)
    section = (tmp_path / "report.md").read_text().split("## Priors side by side (SYT)")[1].split("\n## ")[0]
    side_by_side, paired = section.split("Each prior against `uniform`")
    rows = [line for line in side_by_side.splitlines() if line.startswith("| 3 |")]
    assert [line.split(" | ")[1] for line in rows] == ["uniform", "tables", "surfaces", "saliency"]
    assert [line.split(" | ")[1] for line in paired.splitlines() if line.startswith("| 3 |")] == [
        "tables", "surfaces", "saliency"]


def test_each_prior_is_paired_with_uniform_on_the_same_scenarios(tmp_path):
    results = tmp_path / "results.csv"
    for seed, actions in ((0, 10), (1, 20)):
        _row(results, "syt", "office", "uniform", seed, 100.0, 30.0, actions=actions)
    _row(results, "syt", "office", "surfaces", 0, 100.0, 30.0, actions=4)
    _row(results, "syt", "office", "surfaces", 1, 100.0, 30.0, found=False, status="exhausted")  # counts SPL 0
    _row(results, "syt", "office", "saliency", 2, 100.0, 30.0)  # no uniform run to pair with
    rows = load_results(results)
    spl = {(r["prior"], r["seed"]): r["spl"] for r in rows}
    [gain] = prior_gains(rows)
    assert (gain.prior, gain.scenarios, gain.found_both) == ("surfaces", 2, 1)
    assert gain.difference == pytest.approx((spl["surfaces", 0] - spl["uniform", 0] - spl["uniform", 1]) / 2)
    assert (gain.looks, gain.reference_looks) == (4, 10)  # looks only where both found it
    write_report(results, tmp_path)
    text = (tmp_path / "report.md").read_text()
    assert gain.stderr is None  # two seeds of one scenario: one sample, so no standard error to show
    assert f"| 3 | surfaces | 2 (1) | {gain.spl:.3f} | {gain.reference_spl:.3f} | {gain.difference:+.3f} | 1 |" in text


def test_the_calibration_bins_looks_and_checks_each_bin_with_enough_looks(tmp_path):
    results = tmp_path / "results.csv"
    good = [_look(0.3, 0.28, k % 4 == 0) for k in range(20)]  # within 20 %
    bad = [_look(0.02, 0.001) for _ in range(25)]  # the model promises 20 times what happens
    few = [_look(0.5, 0.1, True) for _ in range(3)]  # far off, but too few looks to judge
    _row(results, "syt", "office", "uniform", 0, 100.0, 30.0, good[:10] + bad)
    _row(results, "syt", "office", "uniform", 1, 100.0, 30.0, good[10:] + few)
    _row(results, "frontier", "office", "uniform", 0, 100.0, 30.0, bad)  # baselines are not the model
    write_report(results, tmp_path)
    text = (tmp_path / "report.md").read_text()
    assert "48 looks of the SYT runs (office; seeds 0,1" in text
    assert "| [0, 0.05) | 25 | 0.020 | 0.001 | 0.000 | FAIL |" in text
    assert "| [0.2, 0.4) | 20 | 0.300 | 0.280 | 0.250 | PASS |" in text
    assert "| [0.4, 1] | 3 | 0.500 | 0.100 | 1.000 | — (< 20 looks) |" in text
    assert "Calibration overall: **FAIL** (1/2 checked bins pass)." in text
    assert "the check is of the planner's arithmetic" in text  # not of the model against the world
    assert "## Coverage: what the looks rule out" in text and "Over the SYT runs (office; seeds 0,1" in text


def test_coverage_is_what_the_looks_before_a_detection_ruled_out_beside_what_was_found():
    def misses(n: int) -> list[Look]:  # each look rules out a tenth of what is left
        return [Look(k, 0.1, 0.1, False, 0.0, 0.0) for k in range(1, n + 1)]

    hit = Look(0, 0.5, 0.5, True, 0.0, 0.0)
    runs = [(misses(12), None), (misses(6) + [hit, hit], 8), ([hit, hit], 2)]
    by_k = {c.looks: c for c in coverage(runs)}
    assert (by_k[6].searching, by_k[12].searching, by_k[24].searching) == (2, 1, 0)
    assert by_k[6].ruled_out == pytest.approx(1 - 0.9 ** 6) and by_k[12].ruled_out == pytest.approx(1 - 0.9 ** 12)
    assert by_k[24].ruled_out is None  # no run searched that long without a detection
    assert [by_k[k].found_within for k in (6, 12, 24)] == pytest.approx([1 / 3, 2 / 3, 2 / 3])
    assert "| 12 | 1 | 0.718 | 67% |" in coverage_md(coverage(runs), "three runs")


def test_bin_edges_belong_to_the_upper_bin_and_one_to_the_last():
    bins = calibration([Look(1, p, p, False, 0.0, 0.0) for p in (0.0, 0.05, 0.1, 0.2, 0.4, 1.0)])
    assert [b.looks for b in bins] == [1, 1, 1, 1, 2]


@pytest.mark.parametrize("text, named", [
    ('{"action": 1, "expected_p": 0.1, "realised_p": 0.1, "detected": false, "processing_s": 1.0}', "motion_s"),
    ('{"action": 1, "expected_p": 1.5, "realised_p": 0.1, "detected": false, "processing_s": 1, "motion_s": 2}',
     "expected_p"),
    ('{"action": true, "expected_p": 0.1, "realised_p": 0.1, "detected": false, "processing_s": 1, "motion_s": 2}',
     "action"),
    ('{"action": 1, "expected_p": 0.1, "realised_p": 0.1, "detected": 0, "processing_s": 1, "motion_s": 2}',
     "detected"),
    ('{"action": 1, "expected_p": 0.1, "realised_p": NaN, "detected": false, "processing_s": 1, "motion_s": 2}',
     "realised_p"),
    ('{"action": 1, "expected_p": 0.1, "realised_p": 0.1, "detected": false, "processing_s": 1, "motion_s": 2, '
     '"x_m": 1.0, "y_m": 2.0, "heading_deg": 0, "true_x_m": "here", "true_y_m": 2.0, "true_heading_deg": 0}',
     "true_x_m"),
    ('{"action": 1, "expected_p": 0.1, "realised_p": 0.1, "detected": false, "processing_s": 1, "motion_s": 2, '
     '"x_m": 1.0, "y_m": 2.0, "true_x_m": 1.0, "true_y_m": 2.0, "true_heading_deg": 0}', "heading_deg"),
    ("[1, 2]", "expected an object"),
    ("{not json", "not JSON"),
    ("[" * 100_000 + "]" * 100_000, "nested too deep"),  # a bare RecursionError before
])
def test_a_malformed_look_is_refused_naming_the_line_and_field(tmp_path, text, named):
    path = tmp_path / LOOKS_FILE
    path.write_text(json.dumps(_look(0.1, 0.1)) + "\n" + text + "\n")
    with pytest.raises(ValueError, match=f"{LOOKS_FILE}:2: .*{named}"):
        read_looks(path)
    assert parse_look(json.dumps(_look(0.1, 0.05, True))).detected is True
    assert read_looks(tmp_path / "absent.jsonl") == []


def test_a_look_log_that_is_not_text_is_refused_naming_it(tmp_path):
    path = tmp_path / LOOKS_FILE
    path.write_bytes(json.dumps(_look(0.1, 0.1)).encode() + b"\n\xff\xfe\n")
    with pytest.raises(ValueError, match=f"{LOOKS_FILE}: not text"):  # a bare UnicodeDecodeError before
        read_looks(path)


def test_the_report_sums_up_how_far_the_believed_pose_was_from_the_true_one_at_the_looks(tmp_path):
    results = tmp_path / "results.csv"
    at = {"x_m": 1.0, "y_m": 2.0, "true_y_m": 2.0, "heading_deg": 179.0, "pan_deg": 0.0, "tilt_deg": 0.0}
    looks = [{**_look(0.1, 0.1), **at, "true_x_m": 1.0 + off, "true_heading_deg": -179.0 - 10 * off}
             for off in (0.0, 0.1, 0.1, 0.2, 0.5)]  # headings across ±180°: 0° to 3° apart
    _row(results, "syt", "office", "uniform", 0, 100.0, 30.0, looks + [_look(0.1, 0.1)])  # one look without truth
    write_report(results, tmp_path)
    text = (tmp_path / "report.md").read_text()
    assert ("## Localisation at the looks" in text and "5 looks" in text and "median 0.100 m, p95 0.500 m, "
            "max 0.500 m; 20% of the looks were more than 0.3 m off" in text)
    assert "The heading's error: median 1.0°, p95 3.0°, max 3.0°" in text
    assert "## The detector where the target was" in text and "5 looks logged the simulator's pose" in text
    assert parse_look(json.dumps(_look(0.1, 0.1))).pose_error_m is None  # a search outside the harness


def test_each_failed_run_is_put_down_to_a_cause_and_a_heading_error_counts_by_what_it_moves(tmp_path):
    results = tmp_path / "results.csv"
    x, y, z, _ = TARGETS["office"]
    off = [x, y + 0.6, z + 0.1]  # found, 0.6 m from the truth: a failure
    seen_from = {"x_m": x - 3.0, "y_m": y, "true_x_m": x - 3.0, "true_y_m": y, "true_heading_deg": 0.0}
    turned = {**_look(0.5, 0.5, True), **seen_from, "heading_deg": 8.0}  # 8° at 3 m: the target moves 0.42 m
    right = {**_look(0.5, 0.5, True), **seen_from, "heading_deg": 1.0}
    _row(results, "oracle", "office", "uniform", 0, 60.0, 5.0, [right, turned], target_estimate_m=off)
    _row(results, "oracle", "office", "uniform", 1, 60.0, 5.0, [right], target_estimate_m=off)
    _row(results, "syt", "office", "uniform", 0, 60.0, 5.0, [right], found=False, status="exhausted")
    _row(results, "syt", "office", "uniform", 1, 60.0, 5.0, [right])  # a success: not listed
    write_report(results, tmp_path)
    text = (tmp_path / "report.md").read_text().split("## Failures")[1].split("\n## ")[0]
    assert "| SYT cost 3, uniform | 2 | 1 | 1 | 0 | 0 | 0 |" in text
    assert "| oracle, uniform | 2 | 2 | 0 | 1 | 1 | 0 |" in text
    rows = [line for line in text.splitlines() if line.startswith("| ") and "office" in line]
    assert len(rows) == 3
    [turned_row] = [r for r in rows if "localisation" in r]
    assert "| 0 | localisation | found |" in turned_row and turned_row.endswith("| 0.00 | 0.42 |")  # no position error
    assert any("| 1 | estimate | found |" in r and r.endswith("| 0.00 | 0.05 |") for r in rows)
    assert any("| not found | exhausted |" in r for r in rows)


def test_a_run_found_without_a_logged_pose_is_not_put_down_to_its_estimate(tmp_path):
    results = tmp_path / "results.csv"
    x, y, z, _ = TARGETS["office"]
    _row(results, "oracle", "office", "uniform", 0, 60.0, 5.0, [_look(0.5, 0.5, True)],  # no truth beside the pose
         target_estimate_m=[x, y + 0.6, z])
    write_report(results, tmp_path)
    text = (tmp_path / "report.md").read_text().split("## Failures")[1].split("\n## ")[0]
    assert "| Not found | Localisation | Estimate | Pose unchecked |" in text
    assert "| oracle, uniform | 1 | 1 | 0 | 0 | 0 | 1 |" in text and "| pose unchecked | found |" in text


def test_a_failed_run_with_a_malformed_target_is_named_and_the_rest_of_the_report_written(tmp_path):
    results = tmp_path / "results.csv"
    x, y, _, _ = TARGETS["office"]
    seen = {**_look(0.5, 0.5, True), "x_m": x - 3.0, "y_m": y, "heading_deg": 0.0, "true_x_m": x - 3.0,
            "true_y_m": y, "true_heading_deg": 0.0, "pan_deg": 0.0, "tilt_deg": 0.0}
    row = _row(tmp_path / "scratch.csv", "syt", "office", "uniform", 0, 60.0, 5.0, [seen],
               target_estimate_m=[x, y, 2.0])  # found, 1.2 m too high: a failure
    append_row(results, {**row, "target": "1,2,3"})
    write_report(results, tmp_path)
    text = (tmp_path / "report.md").read_text()
    failed = text.split("## Failures")[1].split("\n## ")[0]
    assert "| 1,2,3 | 0 | pose unchecked | found |" in failed and failed.rstrip().endswith(
        f"- {row['key']}: target '1,2,3' is not x,y,z,yaw")
    assert "## Coverage" in text and f"- {row['key']}: target '1,2,3' is not x,y,z,yaw" in text.split(
        "## The detector where the target was")[1]  # left out there by name too


def test_coverage_counts_a_run_that_found_the_target_though_it_placed_it_too_far(tmp_path):
    results = tmp_path / "results.csv"
    x, y, z, _ = TARGETS["office"]
    _row(results, "syt", "office", "uniform", 0, 60.0, 5.0, [_look(0.5, 0.5, True)])
    _row(results, "syt", "office", "uniform", 1, 60.0, 5.0, [_look(0.5, 0.5, True)], target_estimate_m=[x, y + 0.6, z])
    write_report(results, tmp_path)
    coverage_section = (tmp_path / "report.md").read_text().split("## Coverage")[1].split("\n## ")[0]
    assert "| 6 | 0 | — | 100% |" in coverage_section  # both found it at their sixth look


def test_a_suites_worlds_are_named_by_the_suite():
    rows = [{"world": w, "seed": s, "start": "0,0,0", "target": t} for w, s, t in
            (("test/room-1", 0.0, "a"), ("test/room-2", 1.0, "a"), ("office", 0.0, "b"), ("office", 0.0, "c"))]
    assert scope(rows) == "the test suite (2 worlds), office; seeds 0,1; 4 start × target scenarios"


def test_world_files_given_by_path_are_counted_under_their_folder():
    rows = [{"world": w, "seed": 0.0, "start": "0,0,0", "target": "a"} for w in
            ("/data/rooms/room-1.toml", "/data/rooms/room-2.toml", "/data/other.toml", "paper-lab")]
    assert scope(rows) == ("2 world files in /data/rooms, /data/other.toml, paper-lab; seeds 0; "
                           "4 start × target scenarios")


# --- a results.csv that is not as the harness writes it ------------------------------------------

def test_a_row_cut_short_by_a_kill_is_set_aside_and_its_run_done_again(tmp_path, caplog):
    results = tmp_path / "results.csv"
    rows = [_row(results, "syt", "office", "uniform", seed, 100.0, 30.0) for seed in (0, 1)]
    whole = results.read_bytes()
    torn = whole[whole.rindex(b"\n", 0, len(whole) - 1) + 1:-40]  # the last row, its end never written
    results.write_bytes(whole[:len(whole) - len(torn) - 40] + torn)
    assert finished_keys(results) == {rows[0]["key"]}
    assert (tmp_path / "results.csv.torn").read_bytes() == torn + b"\n"
    assert "cut short" in caplog.text and [r["seed"] for r in load_results(results)] == [0]
    append_row(results, rows[1])  # done again: a whole row, not glued to the torn one
    assert [r["seed"] for r in load_results(results)] == [0, 1]


@pytest.mark.parametrize("cut_at", [0, 10])
def test_a_header_cut_short_or_never_written_leaves_a_folder_that_resumes(tmp_path, caplog, cut_at):
    """Killed inside the header (or before it), the folder used to refuse every resume: "other columns"."""
    results = tmp_path / "results.csv"
    row = _row(results, "syt", "office", "uniform", 0, 100.0, 30.0)
    results.write_bytes(results.read_bytes()[:cut_at])
    assert finished_keys(results) == set() and not results.exists()
    append_row(results, row)
    assert [r["key"] for r in load_results(results)] == [row["key"]]  # a header, then the row


@pytest.mark.parametrize(("edit", "problem"), [
    (lambda text: text.replace(",key,", ",name,", 1), "results.csv: not an experiment's results.csv: no column key"),
    (lambda text: text.replace("\n", ",extra\n", 2).replace(",extra", "", 1), f"results.csv:2: {len(COLUMNS) + 1} fields where the header has {len(COLUMNS)}"),
    (lambda text: text.replace(",3,uniform,", ",three,uniform,", 1), "results.csv:2: cost 'three' for method 'syt'"),
    (lambda text: text.replace(",3,uniform,", ",,uniform,", 1), "results.csv:2: cost '' for method 'syt'"),
    # these were read as "not measured", or a failure, and moved the means silently
    (lambda text: text.replace(",True,found,6,", ",True,found,six,", 1), "results.csv:2: actions 'six', not a finite number"),
    (lambda text: text.replace(",True,found,6,", ",True,found,nan,", 1), "results.csv:2: actions 'nan', not a finite number"),
    (lambda text: text.replace(",True,found,6,", ",yes,found,6,", 1), "results.csv:2: found 'yes', not True or False"),
    (lambda text: text.replace(",True,0.4773,", ",True,2.5,", 1), "results.csv:2: spl '2.5', not in [0, 1]"),
    (lambda text: text.replace(",True,0.4773,", "," + "x" * 140_000 + ",0.4773,", 1), "results.csv: the row after line 1 is not one"),
])
def test_a_malformed_results_file_is_refused_naming_the_line_and_kept(tmp_path, caplog, edit, problem):
    results = tmp_path / "results.csv"
    for seed in (0, 1):
        _row(results, "syt", "office", "uniform", seed, 100.0, 30.0)
    results.write_text(edit(results.read_text()))
    before = results.read_text()
    with pytest.raises(ValueError, match="results.csv"):
        load_results(results)
    assert harness.main(experiment_args("--report-only", "--out", str(tmp_path))) == 2
    refusal = [r.getMessage() for r in caplog.records if r.levelname == "ERROR"]
    assert refusal and problem in refusal[0] and results.read_text() == before
    assert harness.main(experiment_args("--out", str(tmp_path), "--limit", "1")) == 2  # nor resumed into
    assert results.read_text() == before


def test_a_results_file_from_before_the_later_columns_is_still_reported(tmp_path):
    results = tmp_path / "results.csv"
    _row(results, "syt", "office", "uniform", 0, 100.0, 30.0)
    with results.open(newline="") as f:
        table = list(csv.reader(f))
    with results.open("w", newline="") as f:  # the file as the first harness wrote it
        csv.writer(f).writerows(line[:len(REQUIRED_COLUMNS)] for line in table)
    assert harness.main(experiment_args("--report-only", "--out", str(tmp_path))) == 0
    row, = load_results(results)
    assert row["run_dir"] is None and row["glances"] is None and row["time_min"] is not None

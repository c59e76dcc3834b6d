"""Two sweeps compared run for run: what changed, by how much, with an error that counts scenarios once."""

from __future__ import annotations

import json
import logging
import statistics
from pathlib import Path

import pytest

from offboard.cli import main
from offboard.experiments.comparison import compare, load_sweep
from offboard.experiments.report import append_row

# (world, start, shortest path): three scenarios, one near, one middling, one far
SCENARIOS = (("office", "1,1,0", 0.8), ("office", "5,1,90", 2.0), ("paper-lab", "4.5,0.6,90", 4.0))


def _write(folder: Path, outcomes: dict[tuple, tuple], method: str = "syt", world_as=lambda world: world) -> Path:
    """A results.csv holding one run per (scenario index, seed): (success, SPL, looks, distance, p95 ms);
    ``world_as`` writes a scenario's world as a sweep given it otherwise would have recorded it."""
    folder.mkdir(exist_ok=True)
    for (index, seed), (success, spl, looks, distance, p95) in outcomes.items():
        world, start, shortest = SCENARIOS[index]
        append_row(folder / "results.csv", {
            "method": method, "world": world_as(world), "start": start, "target": "own",
            "cost": 3 if method == "syt" else "", "prior": "uniform", "seed": seed, "found": success,
            "success": success, "spl": spl if success else 0.0, "actions": looks, "distance_m": distance,
            "shortest_path_m": shortest, "planning_ms_p95": p95, "key": f"{method}-{world_as(world)}-{index}-{seed}",
            "status": "found" if success else "budget"})
    return folder


BASE = {(0, 0): (True, 0.9, 10, 1.0, 60.0), (0, 1): (True, 0.9, 10, 1.0, 70.0),
        (1, 0): (True, 0.7, 20, 3.0, 80.0), (1, 1): (True, 0.6, 22, 3.5, 90.0),
        (2, 0): (True, 0.8, 30, 5.0, 100.0), (2, 1): (True, 0.8, 30, 5.0, 110.0)}


def _changed() -> dict[tuple, tuple]:
    """The near scenario loses on both seeds, one middling run fails, and a run only the new sweep has."""
    new = dict(BASE)
    new[0, 0] = (True, 0.5, 14, 2.0, 50.0)
    new[0, 1] = (True, 0.6, 12, 1.6, 60.0)
    new[1, 1] = (False, 0.0, 40, 9.0, 95.0)
    new[2, 2] = (True, 0.8, 30, 5.0, 100.0)
    return new


def test_runs_are_paired_and_a_change_shows_with_an_error_counting_each_scenario_once(tmp_path):
    base, new = load_sweep(_write(tmp_path / "base", BASE)), load_sweep(_write(tmp_path / "new", _changed()))
    result = compare(base, new)
    every, *by_distance = [g for g in result.groups if g.variant == "SYT cost 3, uniform"]
    assert (every.group, every.runs, every.changed, result.only_base, result.only_new) == ("all", 6, 3, 0, 1)
    assert every.base.spl == pytest.approx(statistics.fmean([0.9, 0.9, 0.7, 0.6, 0.8, 0.8]))
    assert every.spl_difference == pytest.approx((-0.4 - 0.3 - 0.6) / 6)
    scenario_means = [(-0.4 - 0.3) / 2, -0.6 / 2, 0.0]  # seeds averaged: three samples, not six
    assert every.spl_stderr == pytest.approx(statistics.stdev(scenario_means) / 3 ** 0.5)
    assert (every.base.found, every.new.found) == (6, 5)
    assert every.new.looks == pytest.approx(statistics.fmean([14, 12, 20, 30, 30]))  # the failed run's pair left out
    assert every.base.looks == pytest.approx(statistics.fmean([10, 10, 20, 30, 30]))
    assert [(g.group, g.runs, g.changed) for g in by_distance] == [
        ("under 1.5 m", 2, 2), ("1.5 m to 3 m", 2, 1), ("3 m or more", 2, 0)]
    assert by_distance[2].spl_difference == 0.0 and by_distance[2].spl_stderr is None  # one scenario: no error


def test_planning_time_is_paired_per_run(tmp_path):
    base, new = load_sweep(_write(tmp_path / "base", BASE)), load_sweep(_write(tmp_path / "new", _changed()))
    (timing,) = compare(base, new).latency
    assert timing.runs == 6 and timing.base_median_ms == 85.0 and timing.new_median_ms == 87.5
    assert timing.difference_ms == pytest.approx((-10 - 10 + 0 + 5 + 0 + 0) / 6)
    assert timing.base_p95_ms == pytest.approx(107.5)  # the report's 95th percentile of the runs' own


def test_methods_are_compared_apart_and_an_unchanged_one_shows_no_change(tmp_path):
    _write(tmp_path / "base", BASE)
    _write(tmp_path / "base", BASE, method="exhaustive")
    _write(tmp_path / "new", _changed())
    _write(tmp_path / "new", BASE, method="exhaustive")
    result = compare(load_sweep(tmp_path / "base"), load_sweep(tmp_path / "new"))
    exhaustive = next(g for g in result.groups if g.variant == "exhaustive, uniform" and g.group == "all")
    assert exhaustive.runs == 6 and exhaustive.changed == 0 and exhaustive.spl_difference == 0.0
    assert {g.variant for g in result.groups} == {"SYT cost 3, uniform", "exhaustive, uniform"}


def test_a_world_given_by_another_path_to_its_file_pairs_by_the_file_s_name(tmp_path):
    base = load_sweep(_write(tmp_path / "base", BASE, world_as=lambda w: f"fresh/{w}.toml"))
    new = load_sweep(_write(tmp_path / "new", _changed(), world_as=lambda w: f"/data/fresh/{w}.toml"))
    every = next(g for g in compare(base, new).groups if g.group == "all")
    assert (every.runs, every.changed) == (6, 3)


def test_two_worlds_of_one_name_from_different_folders_are_not_taken_for_one(tmp_path):
    for folder in ("a", "b"):  # the same scenarios in two rooms that share a file name
        _write(tmp_path / "sweep", BASE, world_as=lambda w, folder=folder: f"{folder}/{w}.toml")
    sweep = load_sweep(tmp_path / "sweep")
    every = next(g for g in compare(sweep, sweep).groups if g.group == "all")
    assert (every.runs, every.changed) == (12, 0)


def test_the_command_prints_json_and_markdown(tmp_path, capsys):
    base, new = _write(tmp_path / "base", BASE), _write(tmp_path / "new", _changed())
    assert main(["compare", str(base), str(new), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    first = printed["groups"][0]
    assert first["group"] == "all" and first["spl_difference"] == pytest.approx(-1.3 / 6) and printed["only_new"] == 1
    assert main(["compare", str(base), str(new)]) == 0
    markdown = capsys.readouterr().out
    assert "| SYT cost 3, uniform | 6 | 3 | 6 / 5 | 0.783 → 0.567 | -0.217 (0.109) |" in markdown
    assert "Not compared: 0 runs only in base, 1 only in new." in markdown


def test_a_run_that_crashed_is_named_apart_from_a_search_that_failed(tmp_path, capsys):
    base, new = _write(tmp_path / "base", BASE), _write(tmp_path / "new", _changed())
    with (new / "results.csv").open() as f:
        lines = f.read().splitlines()
    crashed = next(i for i, line in enumerate(lines) if ",budget," in line)  # the failed run: a timeout instead
    lines[crashed] = lines[crashed].replace(",budget,", ",error: timeout,")
    (new / "results.csv").write_text("\n".join(lines) + "\n")
    every = compare(load_sweep(base), load_sweep(new)).groups[0]
    assert (every.base.errors, every.new.errors, every.new.found) == (0, 1, 5)
    assert main(["compare", str(base), str(new)]) == 0
    assert "SYT cost 3, uniform: 0 in base, 1 in new" in capsys.readouterr().out
    assert main(["compare", str(base), str(base)]) == 0
    assert "Crashed or timed out" not in capsys.readouterr().out

def test_a_crash_is_left_out_of_a_second_difference_printed_beside_the_one_that_counts_it_0(tmp_path, capsys):
    base, new = _write(tmp_path / "base", BASE), _write(tmp_path / "new", _changed())
    with (new / "results.csv").open() as f:
        lines = f.read().splitlines()
    crashed = next(i for i, line in enumerate(lines) if ",budget," in line)  # scenario 1, seed 1: a timeout instead
    lines[crashed] = lines[crashed].replace(",budget,", ",error: timeout,")
    (new / "results.csv").write_text("\n".join(lines) + "\n")
    scenario_means = [(-0.4 - 0.3) / 2, 0.0, 0.0]  # scenario 1 keeps only its seed 0, unchanged
    assert main(["compare", str(base), str(new)]) == 0
    stderr = statistics.stdev(scenario_means) / 3 ** 0.5
    assert (f"| -0.217 (0.109); without errors: {statistics.fmean(scenario_means):+.3f} ({stderr:.3f}), "
            "1 pair left out |") in capsys.readouterr().out
    every = compare(load_sweep(base), load_sweep(new)).groups[0]
    assert every.spl_difference == pytest.approx((-0.4 - 0.3 - 0.6) / 6)  # the crash still counts 0 here
    assert every.error_pairs == 1
    assert every.spl_difference_no_errors == pytest.approx(statistics.fmean(scenario_means))
    assert every.spl_stderr_no_errors == pytest.approx(statistics.stdev(scenario_means) / 3 ** 0.5)
    assert main(["compare", str(base), str(new), "--json"]) == 0
    first = json.loads(capsys.readouterr().out)["groups"][0]
    assert first["spl_difference"] == pytest.approx(-1.3 / 6) and first["error_pairs"] == 1  # old keys kept
    assert first["spl_difference_no_errors"] == pytest.approx(statistics.fmean(scenario_means))
    assert compare(load_sweep(base), load_sweep(base)).groups[0].error_pairs == 0


def test_the_printed_table_calls_successes_so_and_names_the_worlds_and_seeds_paired(tmp_path, capsys):
    base, new = _write(tmp_path / "base", BASE), _write(tmp_path / "new", _changed())
    assert main(["compare", str(base), str(new)]) == 0
    markdown = capsys.readouterr().out
    assert "| Successes, base / new |" in markdown and "Found" not in markdown
    assert "SYT cost 3, uniform: paired runs from office, paper-lab; seeds 0,1; 3 start × target scenarios." in markdown
    assert "SYT cost 3, uniform: timed runs from office, paper-lab; seeds 0,1; 3 start × target scenarios." in markdown
    assert main(["compare", str(base), str(new), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["groups"][0]["base"]["found"] == 6 and printed["groups"][0]["scope"].startswith("office, paper-lab")


def test_the_planning_time_difference_counts_each_scenario_once_as_its_standard_error(tmp_path):
    base = {**BASE, (2, 2): (True, 0.8, 30, 5.0, 100.0), (2, 3): (True, 0.8, 30, 5.0, 100.0)}
    new = {**BASE, (2, 2): (True, 0.8, 30, 5.0, 160.0), (2, 3): (True, 0.8, 30, 5.0, 160.0)}
    (timing,) = compare(load_sweep(_write(tmp_path / "base", base)), load_sweep(_write(tmp_path / "new", new))).latency
    per_scenario = [0.0, 0.0, (0 + 0 + 60 + 60) / 4]  # scenario 2 ran four seeds, the others two
    assert timing.runs == 8
    assert timing.difference_ms == pytest.approx(statistics.fmean(per_scenario))  # 10 ms, not 120 / 8 = 15 ms
    assert timing.stderr_ms == pytest.approx(statistics.stdev(per_scenario) / 3 ** 0.5)


def test_the_command_names_a_folder_without_results_and_sweeps_with_nothing_in_common(tmp_path, caplog):
    base = _write(tmp_path / "base", BASE)
    caplog.set_level(logging.ERROR)
    assert main(["compare", str(base), str(tmp_path / "missing")]) == 2
    assert f"{tmp_path / 'missing'}: no results.csv here" in caplog.text
    other = _write(tmp_path / "other", BASE, method="frontier")
    assert main(["compare", str(base), str(other)]) == 2
    assert "no run in common" in caplog.text


def test_pairs_measured_against_another_shortest_path_are_counted_and_said(tmp_path):
    """A change to how SPL's shortest path is measured showed as runs the search had changed."""
    from offboard.experiments.comparison import comparison_md

    base = load_sweep(_write(tmp_path / "base", BASE))
    assert compare(base, load_sweep(_write(tmp_path / "same", BASE))).yardstick_changed == 0
    new = load_sweep(_write(tmp_path / "new", BASE))
    new[0]["shortest_path_m"] = 0.7
    result = compare(base, new)
    assert result.yardstick_changed == 1
    assert "**1 paired runs have another shortest path in new**" in comparison_md(result)

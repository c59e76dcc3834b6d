"""syt-offboard fuzz: the planner side's targets, the merged report, and the message without hypothesis."""

import json
import os
import subprocess
import sys

import pytest

from offboard.fuzz.targets import offboard_targets
from shared.fuzzing import run_target


@pytest.mark.parametrize("target", offboard_targets(), ids=lambda t: t.name)
def test_offboard_decoders_pass_a_short_fuzz(target):
    report = run_target(target, 60)
    assert report.cases >= 60
    assert report.failures == 0, report.examples
    assert report.refused > 30


@pytest.mark.integration
def test_the_command_merges_both_sides_into_one_json():
    run = subprocess.run([sys.executable, "-m", "offboard.cli", "fuzz", "--cases", "20", "--only", "hints",
                          "--only", "arcos", "--json"], capture_output=True, text=True, timeout=180, check=False)
    assert run.returncode == 0, run.stderr
    result = json.loads(run.stdout)
    assert sorted(d["decoder"] for d in result["decoders"]) == ["arcos stream", "hints toml"]
    assert all(d["cases"] >= 20 for d in result["decoders"]) and result["failures"] == 0


@pytest.mark.integration
def test_without_hypothesis_the_command_says_how_to_install_it(tmp_path):
    (tmp_path / "hypothesis").mkdir()
    (tmp_path / "hypothesis" / "__init__.py").write_text("raise ImportError('no hypothesis here')\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), os.getcwd()])}
    run = subprocess.run([sys.executable, "-m", "offboard.cli", "fuzz", "--cases", "5"], capture_output=True,
                         text=True, timeout=60, env=env, check=False)
    assert run.returncode == 2
    assert "pip install" in run.stderr and "[test]" in run.stderr

"""The safety bench in small: one trial of each fault, real processes, the issue's targets checked."""

from __future__ import annotations

from contextlib import ExitStack

import pytest

from offboard.bench.safety import FAULTS, realtime_agent, run_trials, summarize
from shared.transport import DEFAULT_LEASE_MS

pytestmark = pytest.mark.integration

WATCHDOG_MS = 1000  # the agent's default


def test_the_robot_stops_when_its_planner_is_killed_frozen_or_cut_off(tmp_path):
    with ExitStack() as stack:
        agent = realtime_agent(stack, tmp_path, DEFAULT_LEASE_MS)
        trials = run_trials(agent, 1, DEFAULT_LEASE_MS)
    result = summarize(trials, DEFAULT_LEASE_MS, WATCHDOG_MS)
    assert [t.fault for t in trials] == list(FAULTS) and all(t.stopped for t in trials)
    assert result["kill_stop_ms_max"] <= 300
    assert result["link_stop_ms_max"] <= DEFAULT_LEASE_MS + 300
    # a frozen planner is caught by the watchdog, although the observer polls state all along
    assert WATCHDOG_MS - 250 <= result["freeze_stop_ms_max"] <= WATCHDOG_MS + 100
    assert abs(result["freeze_stop_robot_ms_max"] - result["freeze_stop_ms_max"]) < 20  # one clock
    assert 0.3 < result["drift_after_fault_m_max"] < 0.6  # ~1 s at 0.5 m/s, frozen
    log = (tmp_path / "onboard.log").read_text()
    assert "planner gone" in log and "watchdog: no word from the planner" in log

"""The safety bench in small: one trial of each fault, real processes, the issue's targets checked."""

from __future__ import annotations

from contextlib import ExitStack

import pytest

from offboard.bench.safety import (
    FAULTS,
    realtime_agent,
    run_trials,
    summarize,
    watchdog_ms,
)
from shared.transport import DEFAULT_LEASE_MS

pytestmark = pytest.mark.integration


@pytest.mark.long
def test_the_robot_stops_when_its_planner_is_killed_frozen_or_cut_off(tmp_path):
    with ExitStack() as stack:
        agent = realtime_agent(stack, tmp_path, DEFAULT_LEASE_MS)
        trials = run_trials(agent, 1, DEFAULT_LEASE_MS)
        watchdog = watchdog_ms(agent)
    result = summarize(trials, DEFAULT_LEASE_MS, watchdog)
    assert [t.fault for t in trials] == list(FAULTS) and all(t.stopped for t in trials)
    assert result["kill_stop_ms_max"] <= 300
    assert result["link_stop_ms_max"] <= DEFAULT_LEASE_MS + 300
    # a frozen planner is caught by the watchdog, although the observer polls state all along
    assert watchdog - 250 <= result["freeze_stop_ms_max"] <= min(watchdog + 100, 1000)
    assert abs(result["freeze_stop_robot_ms_max"] - result["freeze_stop_ms_max"]) < 20  # one clock
    assert 0.2 < result["drift_after_fault_m_max"] < 0.5  # ~0.8 s at 0.5 m/s, frozen
    log = (tmp_path / "onboard.log").read_text()
    assert "planner gone" in log and "watchdog: no word from the planner" in log

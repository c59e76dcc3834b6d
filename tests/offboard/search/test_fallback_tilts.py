"""A search that the usual tilts leave with nothing worth a look, while the belief still holds the
target inside the room, looks down before it gives up; a resumed search remembers that it did."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from conftest import saved_and_read, search_on
from offboard.planning.planner import PlannerConfig
from offboard.search import checkpoint
from offboard.search.loop import SearchConfig

pytestmark = pytest.mark.integration

# Only the raised tilt: no view of it sees anything below the head, so a target on the floor is out of
# every usual view from everywhere.
RAISED_ONLY = SearchConfig(planned_processing_s=0.45, planner=PlannerConfig(tilts_deg=(30.0,)))


def on_the_floor(search) -> None:
    """All the belief inside the room on the floor's lowest 0.3 m."""
    grid = search.belief.grid
    weights = np.zeros(grid.shape)
    weights[:, :, : int(0.3 / grid.resolution_m)] = 1.0
    search.belief.set_prior(weights, prob_outside=0.05)


def test_a_search_out_of_usual_views_looks_down(sim_agent):
    search = search_on(sim_agent[1], config=RAISED_ONLY)
    on_the_floor(search)
    usual = len(search.planner.settings)
    decision = search._choose(search._pose())
    assert decision.kind != "stop", decision.reason
    assert search.state.widened and len(search.planner.settings) > usual
    assert np.degrees(search.planner.settings.tilt_rad[decision.setting]) == pytest.approx(-30.0)


def test_without_fallback_tilts_it_stops_there(sim_agent):
    config = dataclasses.replace(RAISED_ONLY, planner=dataclasses.replace(RAISED_ONLY.planner, fallback_tilts_deg=()))
    search = search_on(sim_agent[1], config=config)
    on_the_floor(search)
    decision = search._choose(search._pose())
    assert decision.kind == "stop" and decision.status == "exhausted" and not search.state.widened


def test_a_resumed_search_keeps_the_fallback_tilts(sim_agent, tmp_path):
    search = search_on(sim_agent[1], config=RAISED_ONLY)
    on_the_floor(search)
    search._choose(search._pose())
    assert search.planner.widened
    saved = saved_and_read(tmp_path, search)
    resumed = search_on(sim_agent[1], config=RAISED_ONLY)
    assert not resumed.planner.widened
    checkpoint.restore(resumed, saved)
    assert resumed.planner.widened and len(resumed.planner.settings) == len(search.planner.settings)

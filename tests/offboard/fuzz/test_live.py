"""Live fuzz against a real agent process over Zenoh on loopback."""

import pytest
from conftest import client_transport

from offboard.fuzz.live import LiveQuery, LiveReport, _judge, run_live
from shared import messages as m
from shared.codec import encode
from shared.fuzzing import Case
from shared.keys import RobotKeys


@pytest.mark.integration
def test_bad_queries_each_get_an_error_and_the_agent_serves_on(sim_agent):
    agent, _ = sim_agent
    with client_transport(agent).open() as session:
        report = run_live(session, "syt", 300)
    assert report.queries == 300
    assert report.failures == 0, report.examples
    assert report.by_code.get("protocol", 0) > 200 and report.by_code.get("limit", 0) > 0
    assert report.state_after_ok and report.pose_unchanged
    assert report.odometry_hz_after >= 9.0
    assert report.ok


@pytest.mark.integration
def test_a_query_the_agent_carries_out_is_a_failure(sim_agent):
    agent, _ = sim_agent
    keys, report = RobotKeys("syt"), LiveReport()
    query = LiveQuery("state", encode(m.StateRequest("fine")), "protocol", Case(None, None, True, "valid"))
    with client_transport(agent).open() as session:
        _judge(query, session.get(keys.state, payload=query.payload, timeout=5.0), report)
    assert report.failures == 1 and "accepted" in report.examples[0]

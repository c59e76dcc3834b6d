"""One request/reply exchange: what the caller is told when nobody answers, or nobody in time."""

from __future__ import annotations

import time

import pytest

from shared import messages as m
from shared.launch import free_tcp_port
from shared.rpc import RobotUnavailable, request
from shared.transport import TransportConfig


@pytest.fixture()
def sessions():
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    with TransportConfig(listen=(endpoint,), multicast_scouting=False).open() as server, \
            TransportConfig(connect=(endpoint,), multicast_scouting=False).open() as client:
        yield server, client


def test_a_key_nobody_serves_is_said_to_be_unanswered_at_once(sessions):
    _, client = sessions
    with pytest.raises(RobotUnavailable, match=r"nobody answered syt/x/state \(the query ended after 0\.\d s of its 5\)"):
        request(client, "syt/x/state", m.StateRequest("c1"), m.StateReply, 5.0)


def test_a_server_that_holds_the_query_past_its_timeout_is_said_to_be_silent(sessions):
    """Zenoh answers such a query itself with an error reply 'Timeout', which was shown raw."""
    server, client = sessions
    held = []
    server.declare_queryable("syt/x/state", held.append)  # keeps the query, never answers
    deadline = time.monotonic() + 10.0
    with pytest.raises(RobotUnavailable, match=r"no reply from syt/x/state within 0\.5 s"):
        while time.monotonic() < deadline:  # until the queryable's route has reached the client
            try:
                request(client, "syt/x/state", m.StateRequest("c1"), m.StateReply, 0.5)
            except RobotUnavailable as exc:
                if "nobody answered" not in str(exc):
                    raise
                time.sleep(0.05)
    assert held, "the query never reached the server"

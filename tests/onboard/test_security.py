"""Mutual TLS and access control with real processes: one agent with make-certs' robot config, and intruders.

Every intruder is refused, the robot does not move, and the agent's log says why; the planner still drives.
"""

from __future__ import annotations

import datetime as dt
import json
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import zenoh

from offboard.robot.robot_client import RobotClient
from onboard.certificates import Issued, issue, make_certificates
from onboard.secure_transport import GRANTS, listen_endpoints, write_configs
from shared import messages as m
from shared.codec import encode
from shared.keys import RobotKeys
from shared.launch import LoopbackAgent, onboard_agent
from shared.transport import TransportConfig

pytestmark = pytest.mark.integration

KEYS = RobotKeys("syt")


@pytest.fixture(scope="module")
def certs(tmp_path_factory) -> Path:
    """make-certs' files and configs, an expired planner certificate of the same CA, and another CA's planner."""
    out = tmp_path_factory.mktemp("certs")
    make_certificates(out)
    write_configs(out, out)
    long_ago = dt.datetime.now(dt.timezone.utc) - dt.timedelta(days=30)
    issue(Issued.read(out, "ca"), "planner", days=1, not_before=long_ago).write(out, "expired")
    make_certificates(out / "other-ca")
    return out


@pytest.fixture(scope="module")
def secured(certs, tmp_path_factory) -> Iterator[tuple[LoopbackAgent, RobotClient, Path]]:
    """The agent with the robot's TLS and access-control config, and a planner that holds a valid certificate."""
    log_path = tmp_path_factory.mktemp("agent") / "onboard.log"
    args = ["--backend", "sim", "--world", "paper-lab", "--zenoh-config", str(certs / "zenoh-robot.json5")]
    with onboard_agent(args, log_path, protocol="tls") as agent:
        planner = TransportConfig(zenoh_config=certs / "zenoh-planner.json5", connect=(agent.endpoint,))
        with planner.open() as session, RobotClient(session, "syt") as robot:
            agent.wait_ready(session, "syt")
            robot.wait_for_robot()
            yield agent, robot, log_path


def _tls(certs: Path, ca: Path | None = None, cert: Path | None = None) -> dict:
    """A client's TLS section: trust ``ca``, present ``cert`` (its .pem and .key) if given."""
    tls = {"root_ca_certificate": str(ca or certs / "ca.pem"), "enable_mtls": cert is not None}
    if cert is not None:
        tls |= {"connect_certificate": f"{cert}.pem", "connect_private_key": f"{cert}.key"}
    return {"transport/link/tls": tls}


def _session(agent: LoopbackAgent, extra: dict, config: Path | None = None, protocol: str = "tls") -> zenoh.Session:
    endpoint = agent.endpoint.replace("tls/", f"{protocol}/")
    return TransportConfig(connect=(endpoint,), zenoh_config=config, multicast_scouting=False, extra=extra).open()


def _try_to_drive(session: zenoh.Session) -> list:
    """What a move (and a state query) gets back: nothing, for an intruder."""
    replies = list(session.get(KEYS.move, payload=encode(m.MoveCommand("intruder", distance_m=1.0)), timeout=1.0))
    return replies + list(session.get(KEYS.state, payload=encode(m.StateRequest("intruder")), timeout=0.5))


def _log_after(log_path: Path, start: int, words: str, timeout_s: float = 3.0) -> str:
    """The agent's log written since ``start`` once it contains ``words`` (the log pump runs on its own)."""
    deadline = time.monotonic() + timeout_s
    while True:
        text = log_path.read_text()[start:]
        if words in text or time.monotonic() > deadline:
            return text


def test_the_planner_drives_and_nothing_it_needs_is_dropped(secured):
    agent, robot, log_path = secured
    before = robot.sim_truth()
    assert robot.move(distance_m=0.3).status == "done"
    after = robot.sim_truth()
    assert abs(after.x_m - before.x_m) + abs(after.y_m - before.y_m) == pytest.approx(0.3, abs=0.01)
    assert robot.look(10.0, 0.0).pan_deg == pytest.approx(10.0)
    text = log_path.read_text()
    assert "Common Name: planner" in text and "planner connected" in text
    assert "access control dropped" not in text  # the list grants the planner all it uses
    assert "without TLS" not in text  # tls on loopback: no exposure warning


@pytest.mark.parametrize("intruder,protocol,tls,words", [
    ("no certificate, plain tcp", "tcp", None, "TLS: "),
    ("no certificate, TLS", "tls", {}, "no certificates"),
    ("another CA's planner certificate", "tls", {"cert": "other-ca/planner"}, "invalid peer certificate"),
    ("an expired planner certificate", "tls", {"cert": "expired"}, "certificate expired"),
])
def test_intruders_without_a_valid_certificate_are_refused(secured, certs, intruder, protocol, tls, words):
    agent, robot, log_path = secured
    start, before = len(log_path.read_text()), robot.sim_truth()
    extra = {} if tls is None else _tls(certs, cert=certs / tls["cert"] if "cert" in tls else None)
    with _session(agent, extra, protocol=protocol) as session:
        assert _try_to_drive(session) == [], intruder
        assert not any(r.ok for r in session.liveliness().get(KEYS.agent_alive, timeout=0.5))
    assert robot.sim_truth() == before and not robot.state().base_moving
    refusal = _log_after(log_path, start, words)
    assert "zenoh_link_tls" in refusal and words in refusal, f"{intruder}: no refusal in the agent's log"


def test_an_observer_sees_the_telemetry_and_cannot_drive(secured, certs):
    agent, robot, log_path = secured
    start, before = len(log_path.read_text()), robot.sim_truth()
    with _session(agent, {}, config=certs / "zenoh-observer.json5") as session:
        odometry = session.declare_subscriber(KEYS.odometry, zenoh.handlers.FifoChannel(64))
        pantilt = session.declare_subscriber(KEYS.pantilt, zenoh.handlers.FifoChannel(64))
        assert _try_to_drive(session) == []
        session.put(KEYS.heartbeat, b"not a heartbeat either")
        time.sleep(0.5)
        assert odometry.try_recv() is not None and pantilt.try_recv() is not None  # what it may see, it sees
    assert robot.sim_truth() == before and not robot.state().base_moving
    refusal = _log_after(log_path, start, f"on {KEYS.move} (peer")
    assert f"access control dropped Declare Queryable (egress) on {KEYS.move}" in refusal
    assert "CertCommonName(observer)" in refusal


def test_the_robot_config_refuses_a_plain_listener(certs, tmp_path):
    """With the robot's config a --listen tcp/... override fails at start instead of serving in the clear."""
    config = TransportConfig(zenoh_config=certs / "zenoh-robot.json5", listen=("tcp/127.0.0.1:0",),
                             multicast_scouting=False).zenoh()
    assert json.loads(config.get_json("listen/endpoints")) == ["tcp/127.0.0.1:0"]  # the flag did override
    with pytest.raises(zenoh.ZError, match="Unsupported protocol: tcp"):
        zenoh.open(config)


@pytest.mark.parametrize("role", sorted(GRANTS))
def test_a_workstation_listens_nowhere_and_speaks_only_tls(certs, role):
    """A peer's default listener (plain TCP on every interface) let a session without a certificate
    publish odometry to the planner and answer its move query in the robot's place."""
    config = TransportConfig(zenoh_config=certs / f"zenoh-{role}.json5", multicast_scouting=False).zenoh()
    assert listen_endpoints(config) == []
    assert json.loads(config.get_json("transport/link/protocols")) == ["tls"]

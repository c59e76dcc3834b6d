"""The robot's access-control list and the warning for a listener open to the network without TLS."""

from __future__ import annotations

import logging

import pytest
import zenoh

from onboard.agent import REQUEST_TYPES
from onboard.secure_transport import (access_control, exposed_without_tls, robot_config, warn_if_exposed,
                                      write_json5)
from shared.keys import RobotKeys
from shared.transport import TransportConfig

KEYS = RobotKeys("pioneer1")


def _granted(role: str) -> dict[str, list[str]]:
    """key expression -> the messages (with their flow) the role may exchange on it."""
    acl = access_control()
    rules = {rule["id"]: rule for rule in acl["rules"]}
    policy = next(p for p in acl["policies"] if p["subjects"] == [role])
    granted: dict[str, list[str]] = {}
    for rule in (rules[r] for r in policy["rules"]):
        for key in rule["key_exprs"]:
            granted.setdefault(key, []).extend(f"{m}/{f}" for m in rule["messages"] for f in rule["flows"])
    return granted


def _allows(role: str, key: str, message: str) -> bool:
    return any(message in messages and zenoh.KeyExpr(expr).includes(zenoh.KeyExpr(key))
               for expr, messages in _granted(role).items())


@pytest.mark.parametrize("key", [getattr(KEYS, kind) for kind in REQUEST_TYPES])  # every queryable the agent has
def test_the_planner_may_query_every_command_and_only_the_observer_may_not(key):
    assert _allows("planner", key, "query/ingress") and _allows("planner", key, "reply/egress")
    assert not _allows("observer", key, "query/ingress") and not _allows("observer", key, "declare_queryable/egress")


def test_the_planner_has_its_heartbeat_and_liveliness_and_the_observer_only_telemetry():
    assert _allows("planner", KEYS.heartbeat, "put/ingress")
    assert _allows("planner", KEYS.planner_alive("ws1"), "liveliness_token/ingress")
    assert _allows("planner", KEYS.agent_alive, "liveliness_query/ingress")
    observer = _granted("observer")
    assert sorted(observer) == ["syt/*/odometry", "syt/*/pantilt"]
    assert all(sorted(messages) == ["declare_subscriber/ingress", "put/egress"] for messages in observer.values())
    assert access_control()["default_permission"] == "deny"


@pytest.mark.parametrize("endpoint,exposed", [
    ("tcp/0.0.0.0:7447", True), ("tcp/[::]:7447", True), ("tcp/192.168.1.10:7447", True),
    ("udp/0.0.0.0:7447", True), ("tcp/robot.local:7447", True),
    ("tcp/127.0.0.1:7447", False), ("tcp/[::1]:7447", False), ("tcp/localhost:7447", False),
    ("tls/0.0.0.0:7447", False), ("quic/0.0.0.0:7447", False), ("unixsock-stream//tmp/syt.sock", False),
    ("tcp/0.0.0.0:7447#iface=eth0", True),
])
def test_which_listeners_are_exposed_without_tls(endpoint, exposed):
    assert exposed_without_tls(endpoint) is exposed


def test_the_agent_warns_when_it_listens_without_tls_off_loopback(caplog):
    caplog.set_level(logging.WARNING)
    assert warn_if_exposed(TransportConfig(listen=("tcp/0.0.0.0:7447",)).zenoh()) == ["tcp/0.0.0.0:7447"]
    assert "listening on tcp/0.0.0.0:7447 without TLS" in caplog.text
    assert warn_if_exposed(TransportConfig().zenoh()) == ["tcp/[::]:0"]  # Zenoh's own default: every interface
    caplog.clear()
    assert warn_if_exposed(TransportConfig(listen=("tcp/127.0.0.1:7447", "tls/127.0.0.1:7448")).zenoh()) == []
    assert caplog.text == ""


def test_the_agent_warns_when_its_tls_listener_lets_anyone_in(caplog, tmp_path):
    """TLS encrypts; only client certificates and the access-control list say who may drive."""
    caplog.set_level(logging.WARNING)
    assert warn_if_exposed(TransportConfig(listen=("tls/0.0.0.0:7448",)).zenoh()) == ["tls/0.0.0.0:7448"]
    assert "with TLS but without client certificates" in caplog.text
    caplog.clear()
    robot = write_json5(tmp_path / "robot.json5", robot_config(tmp_path), "the robot")
    assert warn_if_exposed(TransportConfig(zenoh_config=robot).zenoh()) == []  # make-certs' config
    assert caplog.text == ""

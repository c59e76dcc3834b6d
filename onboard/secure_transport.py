"""The robot's link secured: Zenoh configurations for mutual TLS with an access-control list, and a check for exposure.

The robot listens on TLS only and asks every peer for a client certificate signed by the robot's CA. Its
access-control list (enforced by the robot's own Zenoh node, default deny) matches the certificate's common
name, which is the peer's role (see ``onboard.certificates``):

- ``planner`` may query the commands (move, stop, look, capture, state, info, sim/**), subscribe to the
  telemetry, publish heartbeats and hold its liveliness token, and see the agent's;
- ``observer`` may subscribe to odometry and pan/tilt, and nothing else.

Flows are the robot's: ``ingress`` is what a peer sends the robot, ``egress`` what the robot sends it.
Keys are ``shared.keys``'s leaves under ``syt/*/`` (any robot id).
"""

from __future__ import annotations

import ipaddress
import json
import logging
from pathlib import Path

import zenoh

log = logging.getLogger(__name__)

ROBOT_PORT = 7447
COMMANDS = ("move", "stop", "look", "capture", "state", "info", "sim/**")
TELEMETRY = ("odometry", "pantilt")
SECURE_PROTOCOLS = ("tls", "quic")  # protocols that authenticate and encrypt
_LOCAL_PROTOCOLS = ("unixsock-stream", "unixpipe", "vsock", "serial")  # never reachable over a network


def _rule(rule_id: str, messages: list[str], flow: str, leaves: tuple[str, ...]) -> dict:
    return {"id": rule_id, "messages": messages, "flows": [flow], "permission": "allow",
            "key_exprs": [f"syt/*/{leaf}" for leaf in leaves]}


# One rule per direction, so that a peer may never, e.g., declare a queryable of its own on "move".
_RULES = {
    "commands-in": _rule("commands-in", ["query"], "ingress", COMMANDS),
    "commands-out": _rule("commands-out", ["declare_queryable", "reply"], "egress", COMMANDS),
    "telemetry-in": _rule("telemetry-in", ["declare_subscriber"], "ingress", TELEMETRY),
    "telemetry-out": _rule("telemetry-out", ["put"], "egress", TELEMETRY),
    "heartbeat-in": _rule("heartbeat-in", ["put"], "ingress", ("heartbeat",)),
    "heartbeat-out": _rule("heartbeat-out", ["declare_subscriber"], "egress", ("heartbeat",)),
    "planner-token-in": _rule("planner-token-in", ["liveliness_token", "reply"], "ingress", ("planner/*",)),
    "planner-token-out": _rule("planner-token-out", ["declare_liveliness_subscriber", "liveliness_query"],
                               "egress", ("planner/*",)),
    "agent-token-in": _rule("agent-token-in", ["declare_liveliness_subscriber", "liveliness_query"],
                            "ingress", ("agent",)),
    "agent-token-out": _rule("agent-token-out", ["liveliness_token", "reply"], "egress", ("agent",)),
}
GRANTS = {  # role (certificate common name) -> its rules
    "planner": tuple(_RULES),
    "observer": ("telemetry-in", "telemetry-out"),
}


def access_control() -> dict:
    """The robot's ``access_control`` section: each role its rules, anyone else nothing."""
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": list(_RULES.values()),
        "subjects": [{"id": role, "cert_common_names": [role]} for role in GRANTS],
        "policies": [{"id": role, "rules": list(rules), "subjects": [role]} for role, rules in GRANTS.items()],
    }


def robot_config(cert_dir: Path, listen: str = f"tls/0.0.0.0:{ROBOT_PORT}") -> dict:
    """The robot's Zenoh configuration: TLS only, a client certificate required, the access-control list."""
    return {
        "mode": "peer",
        "listen": {"endpoints": [listen]},
        "scouting": {"multicast": {"enabled": False}},
        "transport": {"link": {
            "protocols": ["tls"],  # a plain --listen tcp/... is refused at start rather than served unprotected
            "tls": {
                "root_ca_certificate": str(cert_dir / "ca.pem"),
                "listen_certificate": str(cert_dir / "robot.pem"),
                "listen_private_key": str(cert_dir / "robot.key"),
                "enable_mtls": True,
                "close_link_on_expiration": True,  # a planner whose certificate expires mid-session is cut off
            },
        }},
        "access_control": access_control(),
    }


def client_config(cert_dir: Path, role: str, connect: str) -> dict:
    """A workstation's Zenoh configuration: it dials the robot over TLS with its role's certificate,
    and listens nowhere. (A peer's default listener, plain TCP on every interface, would let anyone
    without a certificate publish telemetry to the planner and answer its commands in the robot's place:
    the robot's access-control list guards the robot, not the planner.)"""
    if role not in GRANTS:
        raise ValueError(f"role {role!r} is not one of {', '.join(GRANTS)}")
    return {
        "mode": "peer",
        "connect": {"endpoints": [connect]},
        "listen": {"endpoints": []},
        "scouting": {"multicast": {"enabled": False}},
        "transport": {"link": {"protocols": ["tls"], "tls": {
            "root_ca_certificate": str(cert_dir / "ca.pem"),
            "connect_certificate": str(cert_dir / f"{role}.pem"),
            "connect_private_key": str(cert_dir / f"{role}.key"),
            "enable_mtls": True,  # without it the connecting side never presents its certificate
            "verify_name_on_connect": True,  # the robot's certificate must name the host dialled
        }}},
    }


def write_json5(path: Path, config: dict, comment: str) -> Path:
    path.write_text(f"// {comment}\n{json.dumps(config, indent=2)}\n")
    return path


def write_configs(out: Path, cert_dir: Path, robot_host: str = "localhost") -> list[Path]:
    """``zenoh-robot.json5`` and one ``zenoh-<role>.json5`` per role in ``out``, naming files in ``cert_dir``."""
    connect = f"tls/{_host_for_endpoint(robot_host)}:{ROBOT_PORT}"
    paths = [write_json5(out / "zenoh-robot.json5", robot_config(cert_dir),
                         "the robot: mutual TLS and access control; written by syt-onboard make-certs")]
    for role in GRANTS:
        paths.append(write_json5(out / f"zenoh-{role}.json5", client_config(cert_dir, role, connect),
                                 f"a {role} dialling the robot; written by syt-onboard make-certs"))
    return paths


def _host_for_endpoint(host: str) -> str:
    try:
        return f"[{host}]" if ipaddress.ip_address(host).version == 6 else host
    except ValueError:
        return host


def listen_endpoints(config: zenoh.Config) -> list[str]:
    """The endpoints a session opened with ``config`` listens on (Zenoh keeps a default per mode)."""
    endpoints = json.loads(config.get_json("listen/endpoints"))
    if isinstance(endpoints, dict):
        endpoints = endpoints.get(json.loads(config.get_json("mode")) or "peer", [])
    return list(endpoints)


def reachable(endpoint: str) -> bool:
    """Whether ``endpoint`` (e.g. ``tcp/0.0.0.0:7447``) can be reached from another machine."""
    protocol, _, address = endpoint.partition("/")
    if protocol in _LOCAL_PROTOCOLS:
        return False
    host = address.split("?", 1)[0].split("#", 1)[0].rpartition(":")[0].strip("[]")
    if host == "localhost":
        return False
    try:
        return not ipaddress.ip_address(host).is_loopback
    except ValueError:
        return True  # a host name: it resolves to whatever the network says


def exposed_without_tls(endpoint: str) -> bool:
    """Whether ``endpoint`` can be reached from another machine unencrypted."""
    return endpoint.partition("/")[0] not in SECURE_PROTOCOLS and reachable(endpoint)


def warn_if_exposed(config: zenoh.Config) -> list[str]:
    """Log a warning for every listening endpoint that strangers on the network could drive the robot
    through: one without TLS, or one with TLS that asks no client certificate or has no access control
    (TLS alone encrypts; it does not say who may drive)."""
    guarded = (json.loads(config.get_json("transport/link/tls/enable_mtls")) is True
               and json.loads(config.get_json("access_control/enabled")) is True)
    exposed = []
    for endpoint in filter(reachable, listen_endpoints(config)):
        if exposed_without_tls(endpoint):
            how = "without TLS"
        elif not guarded:
            how = "with TLS but without client certificates (enable_mtls) and access control"
        else:
            continue
        log.warning("listening on %s %s: anyone who can reach it can drive the robot "
                    "(see README, Security: syt-onboard make-certs and --zenoh-config)", endpoint, how)
        exposed.append(endpoint)
    return exposed

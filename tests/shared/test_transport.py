"""The Zenoh transport flags: the file first, then only the flags given on the command line."""

from __future__ import annotations

import argparse
import json

from shared.transport import DEFAULT_LEASE_MS, TransportConfig, add_transport_args, transport_from_args

FILE = """{
  mode: "client",
  listen: { endpoints: ["tls/0.0.0.0:7447"] },
  connect: { endpoints: ["tls/robot.local:7447"] },
  scouting: { multicast: { enabled: false } },
  transport: { link: { tx: { lease: 1500 } } },
}"""


def _config(tmp_path, *argv: str) -> dict:
    path = tmp_path / "zenoh.json5"
    path.write_text(FILE)
    parser = argparse.ArgumentParser()
    add_transport_args(parser)
    config = transport_from_args(parser.parse_args(["--zenoh-config", str(path), *argv])).zenoh()
    keys = ("mode", "listen/endpoints", "connect/endpoints", "scouting/multicast/enabled", "transport/link/tx/lease")
    return {key: json.loads(config.get_json(key)) for key in keys}


def test_without_flags_the_file_decides(tmp_path):
    assert _config(tmp_path) == {"mode": "client", "listen/endpoints": ["tls/0.0.0.0:7447"],
                                 "connect/endpoints": ["tls/robot.local:7447"],
                                 "scouting/multicast/enabled": False, "transport/link/tx/lease": 1500}


def test_flags_given_override_the_file(tmp_path):
    assert _config(tmp_path, "--mode", "peer", "--listen", "tls/127.0.0.1:9000", "--connect", "tcp/10.0.0.2:7447",
                   "--lease-ms", "800") == {
        "mode": "peer", "listen/endpoints": ["tls/127.0.0.1:9000"], "connect/endpoints": ["tcp/10.0.0.2:7447"],
        "scouting/multicast/enabled": False, "transport/link/tx/lease": 800}


def test_without_a_file_the_lease_is_the_projects_and_zenoh_keeps_its_defaults():
    config = TransportConfig().zenoh()
    assert json.loads(config.get_json("transport/link/tx/lease")) == DEFAULT_LEASE_MS
    assert config.get_json("mode") == "null"  # Zenoh's default: peer
    assert json.loads(TransportConfig(multicast_scouting=False).zenoh().get_json("scouting/multicast/enabled")) is False


def test_gossip_connects_nobody_unless_the_file_configures_it(tmp_path):
    autoconnect = "scouting/gossip/autoconnect"
    assert json.loads(TransportConfig().zenoh().get_json(autoconnect)) == {"router": [], "peer": []}
    path = tmp_path / "gossip.json5"
    path.write_text("{ scouting: { gossip: { multihop: true } } }")
    assert json.loads(TransportConfig(zenoh_config=path).zenoh().get_json(autoconnect)) is None  # Zenoh's default


def test_flags_given_on_a_resume_replace_only_their_own_saved_settings(tmp_path):
    """Any flag used to throw the whole saved transport away: `--connect` alone lost the robot's id
    and its TLS file, so the resumed search could not reach the robot; and a flag given at its
    default value (`--robot syt`) was taken for no flag."""
    saved = TransportConfig(robot_id="pioneer1", connect=("tls/robot:7447",), zenoh_config=tmp_path / "tls.json5",
                            multicast_scouting=False, lease_ms=1500)
    parser = argparse.ArgumentParser()
    add_transport_args(parser)
    given = parser.parse_args(["--connect", "tls/10.0.0.9:7447", "--robot", "syt"])
    assert transport_from_args(given, saved) == TransportConfig(
        robot_id="syt", connect=("tls/10.0.0.9:7447",), zenoh_config=tmp_path / "tls.json5",
        multicast_scouting=False, lease_ms=1500)
    assert transport_from_args(parser.parse_args([]), saved) == saved
    assert transport_from_args(parser.parse_args([])) == TransportConfig()


def test_a_lease_zenoh_would_take_but_no_link_survives_is_refused(capsys):
    """A lease of -5 ms became 0: the agent came up and lost every planner at once."""
    import pytest

    parser = argparse.ArgumentParser()
    add_transport_args(parser)
    with pytest.raises(SystemExit):
        parser.parse_args(["--lease-ms", "-5"])
    assert "--lease-ms must lie in [100, 3.6e+06], got -5" in capsys.readouterr().err
    with pytest.raises(ValueError, match="--lease-ms must lie in"):
        TransportConfig(lease_ms=0)


def test_a_malformed_zenoh_config_file_is_named(tmp_path):
    import pytest

    path = tmp_path / ("a-folder-name-long-enough-to-be-cut-short-where-a-value-is-shown" * 2) / "broken.json5"
    path.parent.mkdir()
    path.write_text("{ not json5")
    with pytest.raises(ValueError, match="is not a Zenoh configuration") as refused:
        TransportConfig(zenoh_config=path).zenoh()
    assert str(path) in str(refused.value)


def test_a_session_opens_on_the_config_it_was_given_without_reading_the_file_again(tmp_path):
    import socket

    with socket.socket() as probe:  # a free port, for the file to name
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    path = tmp_path / "zenoh.json5"
    path.write_text(f'{{ listen: {{ endpoints: ["tcp/127.0.0.1:{port}"] }}, scouting: {{ multicast: {{ enabled: false }} }} }}')
    transport = TransportConfig(zenoh_config=path)
    config = transport.zenoh()
    path.unlink()  # what the agent checked is what it runs on, even if the file changes after
    session = transport.open(config)
    try:
        socket.create_connection(("127.0.0.1", port), timeout=2).close()  # it listens where the file said
    finally:
        session.close()

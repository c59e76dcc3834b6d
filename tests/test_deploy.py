"""What deploy/ ships must load as it is."""

import json
from pathlib import Path

import zenoh

from onboard.config import OnboardConfig
from shared.config import load_config
from onboard.secure_transport import write_configs
from shared.transport import DEFAULT_LEASE_MS, TransportConfig

DEPLOY = Path(__file__).resolve().parent.parent / "deploy"


def test_the_robot_config_loads_and_paces_the_simulator():
    config = load_config(OnboardConfig, DEPLOY / "robot" / "onboard.toml")
    assert config.sim.realtime and config.pantilt.pan_max_deg == 159.0


ZENOH_CONFIGS = {"robot/zenoh.json5": "zenoh-robot.json5", "workstation/zenoh.json5": "zenoh-planner.json5",
                 "workstation/zenoh-observer.json5": "zenoh-observer.json5"}  # deploy/ -> what make-certs writes


def test_the_zenoh_configs_load_and_flags_override_them():
    for name in ZENOH_CONFIGS:
        path = DEPLOY / name
        zenoh.Config.from_file(str(path))
        config = TransportConfig(zenoh_config=path, connect=("tls/127.0.0.1:7999",)).zenoh()
        assert "tls/127.0.0.1:7999" in config.get_json("connect/endpoints")
        assert config.get_json("transport/link/tx/lease") == str(DEFAULT_LEASE_MS)


def test_the_zenoh_configs_are_make_certs_own_for_etc_syt_certs(tmp_path):
    """The shipped configs are what make-certs writes for certificates in /etc/syt/certs: mutual TLS, the ACL."""
    write_configs(tmp_path, Path("/etc/syt/certs"), "robot.local")
    for name, generated in ZENOH_CONFIGS.items():
        shipped = zenoh.Config.from_file(str(DEPLOY / name))
        assert str(shipped) == str(zenoh.Config.from_file(str(tmp_path / generated))), name
        assert shipped.get_json("transport/link/tls/enable_mtls") == "true"
    robot = zenoh.Config.from_file(str(DEPLOY / "robot" / "zenoh.json5"))
    assert json.loads(robot.get_json("access_control/default_permission")) == "deny"
    assert json.loads(robot.get_json("access_control/enabled")) is True


def test_the_service_stops_the_agent_with_sigint():
    unit = (DEPLOY / "robot" / "syt-onboard.service").read_text()
    assert "KillSignal=SIGINT" in unit and "--config /etc/syt/onboard.toml" in unit

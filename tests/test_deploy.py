"""What deploy/ ships must load as it is."""

from pathlib import Path

import zenoh

from onboard.config import OnboardConfig
from shared.config import load_config
from shared.transport import TransportConfig

DEPLOY = Path(__file__).resolve().parent.parent / "deploy"


def test_the_robot_config_loads_and_paces_the_simulator():
    config = load_config(OnboardConfig, DEPLOY / "robot" / "onboard.toml")
    assert config.sim.realtime and config.pantilt.pan_max_deg == 159.0


def test_the_zenoh_configs_load_and_flags_override_them():
    for side in ("robot", "workstation"):
        path = DEPLOY / side / "zenoh.json5"
        zenoh.Config.from_file(str(path))
        config = TransportConfig(zenoh_config=path, connect=("tcp/127.0.0.1:7999",)).zenoh()
        assert "tcp/127.0.0.1:7999" in config.get_json("connect/endpoints")
        assert config.get_json("transport/link/tx/lease") == "2000"


def test_the_service_stops_the_agent_with_sigint():
    unit = (DEPLOY / "robot" / "syt-onboard.service").read_text()
    assert "KillSignal=SIGINT" in unit and "--config /etc/syt/onboard.toml" in unit

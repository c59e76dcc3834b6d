"""What deploy/ ships must load as it is."""

import json
import threading
from pathlib import Path

import pytest
import zenoh

from onboard.config import OnboardConfig
from shared.config import load_config
from onboard.secure_transport import write_configs
from shared.transport import DEFAULT_LEASE_MS, TransportConfig

DEPLOY = Path(__file__).resolve().parent.parent / "deploy"


def test_the_robot_config_loads_and_paces_the_simulator():
    config = load_config(OnboardConfig, DEPLOY / "robot" / "onboard.toml")
    assert config.sim.realtime and config.pantilt.pan_max_deg == 159.0


def test_the_robot_config_names_a_pioneer_a_ptu_and_a_uvc_stereo_camera():
    config = load_config(OnboardConfig, DEPLOY / "robot" / "onboard.toml")
    hw = config.hardware
    assert config.backend == "hardware" and (hw.base.port, hw.pantilt.port) == ("/dev/pioneer", "/dev/ptu")
    assert hw.camera.device == "/dev/video0" and hw.camera.calibration == "/etc/syt/stereo.yaml"


def test_udev_names_what_the_config_opens_and_the_service_waits_for():
    config = load_config(OnboardConfig, DEPLOY / "robot" / "onboard.toml")
    rules = [line for line in (DEPLOY / "robot" / "99-syt.rules").read_text().splitlines()
             if line.strip() and not line.startswith("#")]
    unit = (DEPLOY / "robot" / "syt-onboard.service").read_text()
    for port in (config.hardware.base.port, config.hardware.pantilt.port):
        name = port.removeprefix("/dev/")
        [rule] = [r for r in rules if f'SYMLINK+="{name}"' in r]
        assert 'SUBSYSTEM=="tty"' in rule and "ATTRS{idVendor}" in rule and 'TAG+="systemd"' in rule
        assert f"dev-{name}.device" in unit.split("After=")[1].splitlines()[0]
    assert "SupplementaryGroups=dialout video" in unit


@pytest.mark.integration
def test_the_robot_config_drives_the_emulated_robot():
    """The shipped config as it is, with only the device names changed to the emulators'."""
    from onboard.backends import build_robot
    from onboard.emulators.robot import EmulatedRobot
    from onboard.sim.world import load_world

    world = load_world("paper-lab")
    with EmulatedRobot(OnboardConfig(), world, "paper-lab") as emulated:
        ports = emulated.ports()
        config = load_config(OnboardConfig, DEPLOY / "robot" / "onboard.toml", {
            "hardware.base.port": ports["base"], "hardware.pantilt.port": ports["pantilt"],
            "hardware.camera.device": "sim", "hardware.truth": ports["truth"]})
        devices = build_robot(config, world).devices
        try:
            assert devices.backend == "hardware" and devices.base.reading().pose == world.start
            assert devices.pantilt.look(0.2, -0.1, threading.Event()) > 0.0
            assert devices.camera.capture().left.shape == (480, 640, 3)
        finally:
            devices.close()


ZENOH_CONFIGS = {"robot/zenoh.json5": "zenoh-robot.json5", "workstation/zenoh.json5": "zenoh-planner.json5",
                 "workstation/zenoh-observer.json5": "zenoh-observer.json5"}  # deploy/ -> what make-certs writes


def test_the_zenoh_configs_load_and_flags_override_them():
    for name in ZENOH_CONFIGS:
        path = DEPLOY / name
        zenoh.Config.from_file(str(path))
        config = TransportConfig(zenoh_config=path, connect=("tls/127.0.0.1:7999",)).zenoh()
        assert json.loads(config.get_json("connect/endpoints")) == ["tls/127.0.0.1:7999"]  # replaced, not added to
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

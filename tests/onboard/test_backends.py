"""Building the devices from the configuration: mixed real and simulated devices, and a device that
cannot be opened (named, with those already open closed again)."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

from onboard.backends import build_robot
from onboard.config import HardwareConfig, OnboardConfig, PioneerConfig, PtuConfig
from onboard.emulators.robot import EmulatedRobot
from onboard.hardware import arcos
from onboard.hardware.ptu_protocol import PtuError
from onboard.sim.pantilt import SimPanTilt
from onboard.sim.world import load_world

pytestmark = pytest.mark.integration  # the emulated Pioneer runs in real time


def _hardware(**devices) -> OnboardConfig:
    return dataclasses.replace(OnboardConfig(), backend="hardware", hardware=HardwareConfig(**devices))


def test_a_robot_with_only_a_real_base_sees_the_world_from_its_odometry():
    world = load_world("paper-lab")
    with EmulatedRobot(OnboardConfig(), world, "paper-lab") as emulated:
        robot = build_robot(_hardware(base=PioneerConfig(port=emulated.ports()["base"])), world)
        devices = robot.devices
        try:
            assert robot.sim is None and isinstance(devices.pantilt, SimPanTilt)
            before = devices.camera.capture().left
            assert devices.base.move(0.0, 0.5, 0.4, threading.Event()).status == "done"
            assert emulated.truth().pose.y_m == pytest.approx(world.start.y_m + 0.5, abs=0.05)
            after = devices.camera.capture().left  # 0.5 m nearer the centre table
            assert np.abs(before.astype(int) - after.astype(int)).mean() > 5.0
        finally:
            devices.close()


def test_a_device_that_cannot_be_opened_is_named_and_the_others_are_closed(tmp_path):
    world = load_world("paper-lab")
    missing = str(tmp_path / "no-ptu")
    with EmulatedRobot(OnboardConfig(), world, "paper-lab") as emulated:
        config = _hardware(base=PioneerConfig(port=emulated.ports()["base"]), pantilt=PtuConfig(port=missing))
        with pytest.raises(PtuError, match=f"cannot open '{missing}'"):
            build_robot(config, world)
        deadline = time.monotonic() + 2.0
        while emulated.pioneer.snapshot()[0] and time.monotonic() < deadline:
            time.sleep(0.02)
        assert not emulated.pioneer.snapshot()[0]  # the base was closed again: session ended
        assert (arcos.Command.ENABLE, 0) in emulated.pioneer.history()  # motors disabled first


def test_the_agent_exits_1_naming_a_port_that_does_not_open(tmp_path):
    config = tmp_path / "robot.toml"
    config.write_text(f'backend = "hardware"\n[hardware.base]\nport = "{tmp_path / "no-pioneer"}"\n')
    done = subprocess.run([sys.executable, "-m", "onboard.cli", "--config", str(config), "--no-multicast-scouting"],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 1
    assert "cannot start the hardware backend" in done.stderr and "no-pioneer" in done.stderr

"""One contract for every device backend. The serial-hardware backend joins BACKENDS when it exists;
the same tests must then pass against it (on the bench, or against its pseudo-terminal emulators)."""

from __future__ import annotations

import dataclasses
import math
import threading
import time

import pytest

from onboard.config import OnboardConfig, SimConfig
from onboard.devices import Devices
from onboard.sim.robot import build_sim_robot
from onboard.sim.world import load_world


def _sim(realtime: bool) -> Devices:
    config = dataclasses.replace(OnboardConfig(), sim=SimConfig(realtime=realtime))
    return build_sim_robot(config, load_world("paper-lab").with_start(1.5, 2.5, 0.0)).devices


BACKENDS = {"sim": _sim}


@pytest.fixture(params=sorted(BACKENDS))
def devices(request):
    made = BACKENDS[request.param](realtime=False)
    yield made
    made.close()


@pytest.fixture(params=sorted(BACKENDS))
def paced_devices(request):
    made = BACKENDS[request.param](realtime=True)
    yield made
    made.close()


def test_base_moves_and_reports(devices):
    start = devices.base.reading()
    assert not start.moving and not start.stalled
    outcome = devices.base.move(math.radians(90), 0.4, 0.3, threading.Event())
    assert outcome.status == "done" and outcome.distance_m == pytest.approx(0.4, abs=1e-6)
    assert outcome.duration_s == pytest.approx(devices.base.limits.turn_time_s(math.radians(90))
                                               + devices.base.limits.drive_time_s(0.4, 0.3), rel=0.02)
    end = devices.base.reading()
    assert end.pose.y_m - start.pose.y_m == pytest.approx(0.4, abs=0.05) and not end.moving


def test_base_stop_from_another_thread_interrupts_a_motion(paced_devices):
    base = paced_devices.base
    result = []
    mover = threading.Thread(target=lambda: result.append(base.move(0.0, 3.0, 0.3, threading.Event())))
    mover.start()
    time.sleep(0.5)
    assert base.reading().moving
    base.stop()
    mover.join(timeout=2.0)
    assert result and result[0].status == "stopped" and 0.0 < result[0].distance_m < 0.5
    assert not base.reading().moving


def test_pan_tilt_reaches_its_limits(devices):
    limits = devices.pantilt.limits
    duration = devices.pantilt.look(math.radians(limits.pan_max_deg), math.radians(limits.tilt_min_deg), threading.Event())
    head = devices.pantilt.reading()
    assert math.degrees(head.pan_rad) == pytest.approx(limits.pan_max_deg)
    assert math.degrees(head.tilt_rad) == pytest.approx(limits.tilt_min_deg)
    assert duration == pytest.approx(limits.slew_time_s(limits.pan_max_deg, limits.tilt_min_deg), rel=0.02)


def test_camera_gives_a_rectified_pair_of_the_declared_size(devices):
    pair = devices.camera.capture()
    k = devices.camera.intrinsics
    assert pair.left.shape == pair.right.shape == (k.height_px, k.width_px, 3)
    assert pair.left.dtype == pair.right.dtype == "uint8"
    assert devices.camera.mount.baseline_m > 0


def test_clock_advances_with_actions(devices):
    before = devices.clock.now_s()
    devices.base.move(0.0, 0.5, 0.4, threading.Event())
    assert devices.clock.now_s() - before >= devices.base.limits.drive_time_s(0.5, 0.4) * 0.99

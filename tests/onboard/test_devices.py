"""One contract for every device backend, built the way the agent builds it (``onboard.backends``):
the simulator, and the hardware backend through the real serial drivers over the byte-level
emulators on pseudo-terminals (``syt-onboard emulate``'s robot, in this process), its camera
rendering the emulated truth. Move, stop while moving, stall, a refused limit, look, halt, capture
and close: the same tests, the same assertions; only the simulator's exact times are held to a
tighter tolerance than a real-time driver's, which polls."""

from __future__ import annotations

import contextlib
import dataclasses
import math
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass

import numpy as np
import pytest

from offboard.perception.stereo import StereoMatcher
from onboard.backends import build_robot
from onboard.config import HardwareConfig, OnboardConfig, PioneerConfig, PtuConfig, SimConfig
from onboard.devices import DeviceFault, Devices
from onboard.emulators.robot import EmulatedRobot
from onboard.sim.world import load_world
from shared.geometry import Pose2D
from shared.world import World

# paper-lab, facing +x between the west shelf (its face 0.79 m behind) and the centre table
START = (1.5, 2.5, 0.0)  # x, y (m), heading (°)


@dataclass
class Rig:
    devices: Devices
    true_pose: Callable[[], Pose2D]
    rel: float  # relative tolerance of durations: the simulator's are exact, a real-time driver polls
    distance_m: float  # how close a drive ends to its goal


def _world(start: tuple[float, float, float] = START) -> World:
    return load_world("paper-lab").with_start(start[0], start[1], math.radians(start[2]))


@contextlib.contextmanager
def _sim(realtime: bool, start: tuple[float, float, float] = START) -> Iterator[Rig]:
    config = dataclasses.replace(OnboardConfig(), sim=SimConfig(realtime=realtime))
    robot = build_robot(config, _world(start))
    try:
        yield Rig(robot.devices, lambda: robot.sim.true_pose, 0.02, 1e-6)
    finally:
        robot.devices.close()


@contextlib.contextmanager
def _hardware(realtime: bool, start: tuple[float, float, float] = START) -> Iterator[Rig]:
    """Real time whatever ``realtime`` says: the emulators run on the wall clock."""
    base = OnboardConfig()
    with EmulatedRobot(base, _world(start), "paper-lab") as emulated:
        ports = emulated.ports()
        config = dataclasses.replace(base, backend="hardware", hardware=HardwareConfig(
            PioneerConfig(port=ports["base"]), PtuConfig(port=ports["pantilt"]),
            truth=ports["truth"]))
        robot = build_robot(config, _world(start))
        try:
            yield Rig(robot.devices, lambda: emulated.truth().pose, 0.25, 0.03)
        finally:
            robot.devices.close()


BACKENDS = {"sim": _sim, "hardware": pytest.param(_hardware, marks=pytest.mark.integration)}


@pytest.fixture(params=list(BACKENDS.values()), ids=list(BACKENDS))
def rig(request) -> Iterator[Rig]:
    with request.param(realtime=False) as made:
        yield made


@pytest.fixture(params=list(BACKENDS.values()), ids=list(BACKENDS))
def paced_rig(request) -> Iterator[Rig]:
    with request.param(realtime=True) as made:
        yield made


def _in_thread(call: Callable[[], object]) -> tuple[threading.Thread, list]:
    result: list = []
    thread = threading.Thread(target=lambda: result.append(call()))
    thread.start()
    return thread, result


def test_base_moves_and_reports(rig):
    devices = rig.devices
    start = devices.base.reading()
    assert not start.moving and not start.stalled
    outcome = devices.base.move(math.radians(90), 0.4, 0.3, threading.Event())
    assert outcome.status == "done" and outcome.distance_m == pytest.approx(0.4, abs=rig.distance_m)
    assert outcome.duration_s == pytest.approx(devices.base.limits.turn_time_s(math.radians(90))
                                               + devices.base.limits.drive_time_s(0.4, 0.3), rel=rig.rel)
    assert _comes_to_rest(rig, within_s=0.5)  # a driver's "done" may leave the last mm/s to the firmware
    end = devices.base.reading()
    assert end.pose.y_m - start.pose.y_m == pytest.approx(0.4, abs=0.05) and not end.moving
    truth = rig.true_pose()
    assert (truth.x_m, truth.y_m) == pytest.approx((1.5, 2.9), abs=0.06)


def test_base_stop_from_another_thread_interrupts_a_motion(paced_rig):
    base = paced_rig.devices.base
    mover, result = _in_thread(lambda: base.move(0.0, 3.0, 0.3, threading.Event()))
    time.sleep(0.8)
    assert base.reading().moving
    base.stop()
    mover.join(timeout=3.0)
    assert result and result[0].status == "stopped" and 0.0 < result[0].distance_m < 0.5
    assert _comes_to_rest(paced_rig)
    assert not base.reading().moving


def test_base_stalls_against_a_shelf(rig):
    outcome = rig.devices.base.move(0.0, -1.5, 0.4, threading.Event())
    assert outcome.status == "stalled" and outcome.distance_m < 1.0
    assert rig.true_pose().x_m == pytest.approx(0.45 + rig.devices.base.limits.radius_m, abs=0.03)


@pytest.mark.parametrize("backend", list(BACKENDS.values()), ids=list(BACKENDS))
def test_a_start_heading_past_a_full_turn_reads_within_a_half_turn(backend):
    """A world may start the robot at 400°; the pose messages carry no more than ±360°."""
    with backend(realtime=False, start=(START[0], START[1], 400.0)) as made:
        assert made.devices.base.reading().pose.heading_rad == pytest.approx(math.radians(40.0))


def test_limits_refuse_what_the_device_cannot_reach(rig):
    """The agent checks every command against these before anything moves (codes ``limit``)."""
    head, base = rig.devices.pantilt.limits, rig.devices.base.limits
    assert head.pan_max_deg <= 159.0 and head.tilt_min_deg >= -47.0  # never wider than the PTU-D46
    assert head.check(head.pan_max_deg + 0.5, 0.0).startswith("pan_deg=")
    assert head.check(0.0, head.tilt_min_deg - 0.5).startswith("tilt_deg=")
    assert head.check(head.pan_max_deg, head.tilt_min_deg) is None
    assert base.max_speed_m_s == OnboardConfig().base.max_speed_m_s


def test_pan_tilt_reaches_its_limits(rig):
    head_limits = rig.devices.pantilt.limits
    pan, tilt = head_limits.pan_max_deg, head_limits.tilt_min_deg
    duration = rig.devices.pantilt.look(math.radians(pan), math.radians(tilt), threading.Event())
    head = rig.devices.pantilt.reading()
    assert math.degrees(head.pan_rad) == pytest.approx(pan, abs=0.06)  # within a PTU position
    assert math.degrees(head.tilt_rad) == pytest.approx(tilt, abs=0.06) and not head.moving
    assert duration == pytest.approx(head_limits.slew_time_s(pan, tilt), rel=rig.rel)


def test_pan_tilt_halts_midway(paced_rig):
    pantilt = paced_rig.devices.pantilt
    looker, result = _in_thread(lambda: pantilt.look(math.radians(120.0), 0.0, threading.Event()))
    time.sleep(0.6)
    pantilt.halt()
    looker.join(timeout=3.0)
    assert result and result[0] < 1.5
    head = pantilt.reading()
    assert 5.0 < math.degrees(head.pan_rad) < 100.0 and not head.moving


def test_a_look_cancelled_before_it_begins_never_moves_the_head(rig):
    """A stop that overtook a queued look has set its flag: the look never began (``LookResult``)."""
    cancelled = threading.Event()
    cancelled.set()
    pantilt = rig.devices.pantilt
    assert pantilt.look(math.radians(90.0), math.radians(20.0), cancelled) == 0.0
    head = pantilt.reading()
    assert (head.pan_rad, head.tilt_rad) == pytest.approx((0.0, 0.0), abs=1e-3) and not head.moving


def test_camera_gives_a_rectified_pair_of_the_declared_size(rig):
    pair = rig.devices.camera.capture()
    k = rig.devices.camera.intrinsics
    assert pair.left.shape == pair.right.shape == (k.height_px, k.width_px, 3)
    assert pair.left.dtype == pair.right.dtype == "uint8"
    assert rig.devices.camera.mount.baseline_m > 0
    # rectified: the real matcher, which searches along rows only, finds most of the scene at a
    # positive disparity (a left image twice, or rows out of line, gives none or nothing)
    disparity = StereoMatcher().disparity(pair.left, pair.right)
    valid = np.isfinite(disparity) & (disparity > 0)
    assert valid.mean() > 0.2 and np.median(disparity[valid]) >= 1.0


def test_the_camera_sees_where_the_robot_truly_looks(rig):
    """Panned to face the north wall the view changes, and panned back it is the first view again
    (up to the sensor's noise): the camera renders the head's angles, not a view that merely
    changes on every capture."""
    def view_at(pan_deg: float) -> np.ndarray:
        rig.devices.pantilt.look(math.radians(pan_deg), 0.0, threading.Event())
        return rig.devices.camera.capture().left.astype(np.int16)

    ahead, north, ahead_again = view_at(0.0), view_at(90.0), view_at(0.0)
    turned = float(np.abs(north - ahead).mean())
    assert turned > 5.0 and float(np.abs(ahead_again - ahead).mean()) < 0.2 * turned


def test_clock_advances_with_actions(rig):
    before = rig.devices.clock.now_s()
    rig.devices.base.move(0.0, 0.5, 0.4, threading.Event())
    assert rig.devices.clock.now_s() - before >= rig.devices.base.limits.drive_time_s(0.5, 0.4) * (1 - rig.rel)


def test_close_stops_a_moving_base(paced_rig):
    devices = paced_rig.devices
    mover, result = _in_thread(lambda: _move_or_fault(devices))
    time.sleep(0.8)
    devices.close()
    mover.join(timeout=3.0)
    assert result and result[0] in ("stopped", "fault")
    assert _comes_to_rest(paced_rig)


def _comes_to_rest(rig: Rig, within_s: float = 2.0) -> bool:
    """The true pose stops changing within ``within_s`` (a Pioneer decelerates at 0.3 m/s²)."""
    deadline = time.monotonic() + within_s
    last = rig.true_pose()
    while time.monotonic() < deadline:
        time.sleep(0.25)
        now = rig.true_pose()
        if now == last:
            return True
        last = now
    return False


def _move_or_fault(devices: Devices) -> str:
    """A long drive's end: stopped, or a fault once the port is gone."""
    try:
        return devices.base.move(0.0, 3.0, 0.3, threading.Event()).status
    except DeviceFault:
        return "fault"


def test_closing_goes_on_past_a_device_that_fails_to_close(caplog):
    closed = []

    class Part:
        def __init__(self, name: str, fails: bool = False):
            self.name, self.fails = name, fails

        def close(self) -> None:
            closed.append(self.name)
            if self.fails:
                raise OSError(f"{self.name}: the port is gone")

    devices = Devices("hardware", None, Part("base", fails=True), Part("pantilt"), Part("camera"))
    with pytest.raises(OSError, match="base: the port is gone"):
        devices.close()
    assert closed == ["base", "pantilt", "camera"]  # the head and the camera are still let go
    assert "closing the Part failed" in caplog.text

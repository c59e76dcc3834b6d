"""The PTU-D46 driver against the byte-level emulator over a real pseudo-terminal."""

from __future__ import annotations

import math
import os
import threading
import time
from dataclasses import replace
from pathlib import Path

import pytest

from onboard.emulators.ptu import VERSION, PtuEmulator, PtuModel
from onboard.config import PtuConfig
from onboard.hardware.ptu import PtuLink, PtuPanTilt, probe
from onboard.hardware.ptu_protocol import PtuError, parse_integer
from shared.limits import PanTiltLimits

RES_DEG = 185.1428 / 3600


@pytest.fixture
def emulator():
    with PtuEmulator(PtuModel(calibration_s=0.1)) as emu:
        yield emu


def config(emulator: PtuEmulator, **changes) -> PtuConfig:
    return replace(PtuConfig(port=emulator.device_path, reply_timeout_s=0.2, startup_timeout_s=5.0), **changes)


@pytest.fixture
def head(emulator):
    pantilt = PtuPanTilt(config(emulator))
    yield pantilt
    pantilt.close()


def test_initialises_after_the_banner_and_reads_the_units_limits(emulator, head):
    m = emulator.machine
    assert not m.echo and m.terse and m.enforce_limits
    assert head.limits.pan_max_deg == pytest.approx(3090 * RES_DEG)  # the unit's, inside the configured 159
    assert head.limits.pan_min_deg == pytest.approx(-3090 * RES_DEG)
    assert head.limits.tilt_min_deg == pytest.approx(-907 * RES_DEG)
    assert head.limits.tilt_max_deg == 31.0  # the configured one, inside the unit's 31.06
    assert m.pan.speed == round(60.0 / RES_DEG) and m.pan.accel == round(300.0 / RES_DEG)
    assert head.reading().pan_rad == 0.0 and not head.reading().moving


def test_look_awaits_arrival(emulator, head):
    elapsed = head.look(math.radians(20.0), math.radians(-10.0), threading.Event())
    expected = PanTiltLimits().slew_time_s(20.0, 10.0)
    assert expected * 0.9 < elapsed < expected + 0.5
    for reading in (head.reading(), emulator.reading()):
        assert math.degrees(reading.pan_rad) == pytest.approx(20.0, abs=RES_DEG)
        assert math.degrees(reading.tilt_rad) == pytest.approx(-10.0, abs=RES_DEG)
        assert not reading.moving


def test_speed_is_set_on_the_unit_and_a_look_where_it_is_takes_no_time(emulator, head):
    head.set_speed(30.0, 20.0)
    assert emulator.machine.pan.speed == round(30.0 / RES_DEG)
    assert emulator.machine.tilt.speed == round(20.0 / RES_DEG)
    assert (head.limits.pan_speed_deg_s, head.limits.tilt_speed_deg_s) == (30.0, 20.0)
    elapsed = head.look(math.radians(15.0), 0.0, threading.Event())
    assert elapsed == pytest.approx(PanTiltLimits(pan_speed_deg_s=30.0).slew_time_s(15.0, 0.0), abs=0.25)
    assert head.look(math.radians(15.0), 0.0, threading.Event()) == 0.0


def test_halt_from_another_thread_stops_the_look(emulator, head):
    threading.Timer(0.4, head.halt).start()
    elapsed = head.look(math.radians(120.0), 0.0, threading.Event())
    assert 0.35 < elapsed < 1.0
    time.sleep(0.1)
    stopped = emulator.reading()
    assert not stopped.moving and 5.0 < math.degrees(stopped.pan_rad) < 40.0
    assert head.reading().pan_rad == pytest.approx(stopped.pan_rad, abs=math.radians(RES_DEG))


def test_cancel_halts_the_unit(emulator, head):
    cancel = threading.Event()
    threading.Timer(0.3, cancel.set).start()
    head.look(0.0, math.radians(-40.0), cancel)
    assert not emulator.reading().moving and -30.0 < math.degrees(emulator.reading().tilt_rad) < -1.0


def test_unprompted_limit_event_fails_the_look(emulator, head):
    threading.Timer(0.2, emulator.inject, (b"!P\r\n",)).start()
    with pytest.raises(PtuError, match=r"^look: the pan axis hit its limit \(!P\)"):
        head.look(math.radians(60.0), 0.0, threading.Event())
    assert not emulator.reading().moving


def test_a_refused_command_names_it(emulator):
    too_fast = PanTiltLimits(pan_speed_deg_s=400.0)  # above the unit's upper speed limit PU
    with pytest.raises(PtuError, match=r"^PS: refused by the unit: PS7778: .*upper speed limit PU 5800"):
        PtuPanTilt(config(emulator), too_fast)


def test_a_resolution_of_zero_from_the_unit_is_a_ptu_error_naming_it(emulator):
    with emulator._lock:  # every conversion divides by it: a ZeroDivisionError escaped the agent's start-up
        emulator.machine.model = replace(emulator.machine.model, resolution_arcsec=0.0)
    with pytest.raises(PtuError, match=r"^PR: the unit reports a resolution of 0 arc-seconds a position"):
        PtuPanTilt(config(emulator))


def test_move_timeout_halts_and_names_the_look(emulator):
    head = PtuPanTilt(config(emulator, move_timeout_s=0.5))
    try:
        with emulator._lock:  # the pan axis jams: it creeps at 1 position a second, whatever the speed set
            emulator.machine.pan.speed = 1.0
        with pytest.raises(PtuError, match=r"^look: the head did not reach its goal within \d+\.\d+ s of slewing "
                                           r"and 0.5 s more"):
            head.look(math.radians(150.0), 0.0, threading.Event())
        assert not emulator.reading().moving
    finally:
        head.close()


def test_a_slow_heads_long_sweep_is_given_its_slewing_time(emulator):
    slow = PanTiltLimits(pan_speed_deg_s=40.0, tilt_speed_deg_s=40.0)  # 100° take 2.5 s, the timeout 0.5 s
    head = PtuPanTilt(config(emulator, move_timeout_s=0.5), slow)
    try:
        took = head.look(math.radians(100.0), 0.0, threading.Event())
        assert took > 2.0 and head.reading().pan_rad == pytest.approx(math.radians(100.0), abs=math.radians(0.1))
    finally:
        head.close()


def test_close_halts_and_releases_the_port(emulator, head):
    outcome = []

    def look() -> None:
        try:
            outcome.append(head.look(math.radians(-150.0), 0.0, threading.Event()))
        except PtuError as exc:
            outcome.append(exc)

    worker = threading.Thread(target=look)
    worker.start()
    time.sleep(0.3)
    held = _descriptors_on(emulator.device_path)  # the driver's, and the emulator's own hold on its pty
    head.close()
    worker.join(timeout=2.0)
    time.sleep(0.05)
    assert not emulator.reading().moving and math.degrees(emulator.reading().pan_rad) < -1.0
    assert len(outcome) == 1  # the look ended: halted, or told the unit was closed
    assert _descriptors_on(emulator.device_path) == held - 1  # the driver's port is released
    head.close()  # a second close does nothing


def _descriptors_on(device: str) -> int:
    """How many of this process's file descriptors are open on ``device`` (Linux's /proc)."""
    path = os.path.realpath(device)
    return sum(1 for fd in Path("/proc/self/fd").iterdir() if _target(fd) == path)


def _target(fd: Path) -> str | None:
    try:
        return os.readlink(fd)
    except OSError:  # closed between listing and reading
        return None


def test_silent_port_is_a_clear_error():
    silent = PtuEmulator()  # a pty with nothing serving it
    try:
        with pytest.raises(PtuError, match=r"^ED: the unit on .* did not answer within 0.3 s"):
            PtuPanTilt(replace(PtuConfig(port=silent.device_path), reply_timeout_s=0.1, startup_timeout_s=0.3))
    finally:
        silent.close()
    with pytest.raises(PtuError, match=r"^open: cannot open '/nonexistent/ptu'"):
        PtuPanTilt(PtuConfig(port="/nonexistent/ptu"))


def test_an_answer_that_comes_too_late_is_not_taken_for_the_next_commands():
    master, slave = os.openpty()
    stop = threading.Event()

    def unit() -> None:  # answers PP (the pan) 0.35 s late, after the driver gave up on it; TP at once
        while not stop.is_set():
            try:
                asked = os.read(master, 64)
            except OSError:  # the test closed the pty
                return
            if asked.startswith(b"PP"):
                time.sleep(0.35)
                os.write(master, b"* 1200\r\n")
            elif asked.startswith(b"TP"):
                os.write(master, b"* -300\r\n")

    threading.Thread(target=unit, daemon=True).start()
    link = PtuLink(os.ttyname(slave), 9600, reply_timeout_s=0.2)
    try:
        with pytest.raises(PtuError, match="^PP: no answer"):
            link.transact("PP")
        assert parse_integer(link.transact("TP"), "TP") == -300  # not the pan's 1200, arriving meanwhile
    finally:
        stop.set()
        link.close()
        os.close(slave)
        os.close(master)

def test_a_port_gone_under_a_flush_is_a_ptu_error_naming_it():
    link = PtuLink("loop://", 9600, reply_timeout_s=0.2)
    link.close()  # as when the USB adapter is pulled: pyserial raises its own error, not the driver's
    with pytest.raises(PtuError, match="^flush: cannot flush loop://"):
        link.flush()

def test_probe_reports_the_version(emulator):
    assert probe(emulator.device_path) == {"device": "ptu-d46", "port": emulator.device_path, "version": VERSION}

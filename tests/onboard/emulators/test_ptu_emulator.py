"""The PTU-D46 emulator's state machine, with byte strings and explicit time, and on a real pty."""

from __future__ import annotations

import math
import os
import select
import time

import pytest

from onboard.emulators.ptu import BANNER, PtuEmulator, PtuMachine, PtuModel
from shared.limits import PanTiltLimits


def ready_machine() -> PtuMachine:
    machine = PtuMachine(PtuModel(calibration_s=0.5))
    assert machine.power_up(0.0) == BANNER
    return machine


def test_deaf_while_calibrating_then_echoes_until_ed():
    machine = ready_machine()
    assert machine.receive(b"V ", 0.1) == b""  # self-calibrating
    assert machine.receive(b"PP ", 1.0) == b"PP * Current pan position is 0\r\n"
    assert machine.receive(b"ED ", 1.0) == b"ED *\r\n"
    assert machine.receive(b"FT ", 1.0) == b"*\r\n"
    assert machine.receive(b"PN PX TN TX PR ", 1.0) == b"* -3090\r\n* 3090\r\n* -907\r\n* 604\r\n* 185.1428\r\n"
    assert machine.receive(b"V\r", 1.0).startswith(b"* Pan-Tilt Controller")


def terse(machine: PtuMachine, now: float = 1.0) -> PtuMachine:
    machine.receive(b"ED FT ", now)
    return machine


def test_commands_split_across_chunks_and_unknown_ones_named():
    machine = terse(ready_machine())
    assert machine.receive(b"P", 1.0) == b""
    assert machine.receive(b"S500 ", 1.0) == b"*\r\n"
    assert machine.receive(b"PS ", 1.0) == b"* 500\r\n"
    assert machine.receive(b"QQ ", 1.0) == b"! Illegal command QQ\r\n"
    assert machine.receive(b"PN5 ", 1.0) == b"! Illegal argument: PN takes none\r\n"
    assert machine.receive(b"PS9000 ", 1.0).startswith(b"! PS9000: pan speed must be 1 .. the upper speed limit PU")


def test_out_of_range_refused_naming_the_limit():
    machine = terse(ready_machine())
    assert machine.receive(b"PP4000 ", 1.0) == b"! PP4000: pan position 4000 is outside the limits PN -3090 .. PX 3090\r\n"
    assert machine.receive(b"TP-1000 ", 1.0) == b"! TP-1000: tilt position -1000 is outside the limits TN -907 .. TX 604\r\n"
    assert not machine.moving


def test_slew_follows_the_ptu_d46_trapezoid_and_a_awaits_it():
    slew = PanTiltLimits()
    machine = terse(ready_machine())
    target_deg = 90.0
    target = round(target_deg * 3600 / 185.1428)
    assert machine.receive(f"PP{target} A PP ".encode(), 1.0) == b"*\r\n"  # A defers, PP waits
    expected_s = slew.slew_time_s(target_deg, 0.0) - slew.settle_s
    halfway = machine.advance(1.0 + expected_s / 2)
    assert halfway == b""
    assert machine.moving and 0.3 < math.degrees(machine.reading().pan_rad) / target_deg < 0.7
    out = machine.advance(1.0 + expected_s * 1.02)
    assert out == f"*\r\n* {target}\r\n".encode()
    assert not machine.moving and math.degrees(machine.reading().pan_rad) == pytest.approx(90.0, abs=0.03)


def test_halt_stops_where_the_axis_is():
    machine = terse(ready_machine())
    machine.receive(b"TP600 ", 1.0)
    machine.advance(1.3)
    assert machine.receive(b"H ", 1.3) == b"*\r\n"
    stopped = machine.receive(b"TP ", 1.3)
    machine.advance(3.0)
    assert machine.receive(b"TP ", 3.0) == stopped
    assert 0 < int(stopped[2:]) < 600


def test_limits_disabled_the_axis_runs_into_its_stop_and_says_so():
    machine = terse(ready_machine())
    assert machine.receive(b"LD TP-3000 ", 1.0) == b"*\r\n*\r\n"
    out = b"".join(machine.advance(1.0 + 0.1 * i) for i in range(1, 40))
    assert out == b"!T\r\n"
    assert machine.receive(b"TP ", 5.0) == b"* -907\r\n"


def test_slaved_moves_start_on_a():
    machine = terse(ready_machine())
    assert machine.receive(b"S PP100 TP100 ", 1.0) == b"*\r\n*\r\n*\r\n"
    machine.advance(2.0)
    assert not machine.moving
    assert machine.receive(b"A ", 2.0) == b""
    assert machine.advance(4.0) == b"*\r\n"
    assert machine.receive(b"PP TP ", 4.0) == b"* 100\r\n* 100\r\n"


def read_until(fd: int, ending: bytes, timeout_s: float = 2.0) -> bytes:
    data, deadline = b"", time.monotonic() + timeout_s
    while not data.endswith(ending) and time.monotonic() < deadline:
        if select.select([fd], [], [], 0.05)[0]:
            data += os.read(fd, 1024)
    return data


def test_emulator_serves_a_real_pty_and_exposes_the_head():
    with PtuEmulator(PtuModel(calibration_s=0.05)) as emulator:
        fd = os.open(emulator.device_path, os.O_RDWR | os.O_NOCTTY)
        try:
            assert read_until(fd, b"Initializing...\r\n") == BANNER
            time.sleep(0.1)  # past the emulated self-calibration
            os.write(fd, b"ED FT PP500 ")
            assert read_until(fd, b"*\r\n*\r\n*\r\n") == b"ED *\r\n*\r\n*\r\n"
            assert emulator.reading().moving
            deadline = time.monotonic() + 3.0
            while emulator.reading().moving and time.monotonic() < deadline:
                time.sleep(0.02)
            assert math.degrees(emulator.reading().pan_rad) == pytest.approx(500 * 185.1428 / 3600)
        finally:
            os.close(fd)


def test_reset_rehomes_deaf_meanwhile_then_answers():
    machine = terse(ready_machine())
    machine.receive(b"PP300 ", 1.0)
    machine.advance(3.0)
    assert machine.receive(b"R PP ", 3.0) == b""  # re-homing; PP waits for it
    assert machine.receive(b"V ", 3.2) == b""  # deaf while calibrating
    assert machine.advance(3.6) == b"*\r\n* 0\r\n"

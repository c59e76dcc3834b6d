"""The emulated Pioneer firmware, driven packet by packet on an explicit clock (no pty, no waiting)."""

from __future__ import annotations

import math
import pytest

from onboard.emulators.pioneer import PioneerEmulatorConfig, PioneerServerState
from onboard.hardware import arcos
from onboard.hardware.arcos import Command, build_packet


class Robot:
    """The firmware plus an explicit clock; ``send`` returns the parsed replies."""

    def __init__(self, room_base, subtype: str = "p3dx"):
        self.base = room_base()
        self.state = PioneerServerState(self.base, PioneerEmulatorConfig(subtype=subtype))
        self.now = 0.0
        self.sips: list[arcos.Sip] = []

    def send(self, command: int, arg: int | None = None) -> list[arcos.Packet]:
        replies = self.state.receive(arcos.parse_packet(build_packet(command, arg)), self.now)
        return [arcos.parse_packet(r) for r in replies]

    def run(self, seconds: float, keep_alive: bool = True) -> None:
        """Let time pass; a client sends PULSE every 0.5 s unless told to go silent."""
        end = self.now + seconds
        while self.now < end - 1e-9:
            self.now = min(end, self.now + 0.05)
            if keep_alive and round(self.now / 0.05) % 10 == 0:
                self.send(Command.PULSE)
            self.sips += [arcos.parse_sip(arcos.parse_packet(s)) for s in self.state.step(self.now)]

    def connect(self) -> None:
        assert [p.id for p in self.send(Command.SYNC0) + self.send(Command.SYNC1)] == [0, 1]
        identity = self.send(Command.SYNC2)
        assert arcos.parse_sync2(identity[0].payload) == arcos.RobotIdentity("Pioneer", "Pioneer", self.state.config.subtype)
        self.send(Command.OPEN, 1)
        self.send(Command.ENABLE, 1)


def test_no_sip_before_open_then_every_100_ms(room_base):
    robot = Robot(room_base)
    robot.run(0.5)
    assert robot.sips == []
    assert robot.send(Command.SYNC2) == []  # out of order: no identity before SYNC0 and SYNC1
    robot.connect()
    robot.run(1.0)
    assert 9 <= len(robot.sips) <= 11
    assert robot.sips[-1].motors_enabled and not robot.sips[-1].moving


def test_vel_drives_and_reports_odometry_in_dist_conv_units(room_base):
    robot = Robot(room_base)  # p3dx: 0.485 mm per unit
    robot.connect()
    robot.send(Command.VEL, 300)
    robot.run(2.0)
    sip = robot.state.sip()
    assert sip.moving and sip.speed_mm_s == pytest.approx(300, abs=1)
    true_x_mm = (robot.base.true_pose.x_m - 1.5) * 1000
    assert sip.x_raw * 0.485 == pytest.approx(true_x_mm, abs=2)
    assert true_x_mm == pytest.approx(300 * 2.0 - 0.5 * 300 ** 2 / 300, abs=30)  # ramp at 300 mm/s²


def test_head_turns_to_the_heading_and_holds(room_base):
    robot = Robot(room_base, subtype="p3dx-sh")
    robot.connect()
    robot.send(Command.HEAD, 90)
    robot.run(4.0)
    assert robot.sips[-1].theta_rad == pytest.approx(math.pi / 2, abs=math.radians(0.5))
    assert not robot.sips[-1].moving
    assert robot.base.true_pose.heading_rad == pytest.approx(math.pi / 2, abs=math.radians(0.5))


def test_move_drives_a_distance(room_base):
    robot = Robot(room_base, subtype="p3dx-sh")
    robot.connect()
    robot.send(Command.MOVE, 400)
    robot.run(4.0)
    assert robot.sips[-1].x_raw == pytest.approx(400, abs=3) and not robot.sips[-1].moving


def test_driving_into_a_wall_sets_the_stall_flags(room_base):
    robot = Robot(room_base, subtype="p3dx-sh")
    robot.connect()
    robot.send(Command.SETV, 1000)
    robot.send(Command.VEL, 1000)
    robot.run(6.0)  # 4.24 m to the wall
    assert robot.sips[-1].left_stall and robot.sips[-1].right_stall
    assert robot.base.true_pose.x_m == pytest.approx(6.0 - 0.26, abs=0.01)
    robot.send(Command.VEL, 0)
    robot.run(4.0)
    assert not robot.sips[-1].stalled


def test_watchdog_halts_after_2_s_and_resumes_the_last_motion(room_base):
    robot = Robot(room_base, subtype="p3dx-sh")
    robot.connect()
    robot.send(Command.RVEL, 30)
    robot.run(1.9, keep_alive=False)
    assert robot.sips[-1].turn_rate_rad_s == pytest.approx(math.radians(30), rel=0.05)
    robot.run(1.5, keep_alive=False)
    assert robot.state.watchdog_tripped and not robot.sips[-1].moving
    robot.send(Command.PULSE)
    robot.run(1.0)
    assert not robot.state.watchdog_tripped
    assert robot.sips[-1].turn_rate_rad_s == pytest.approx(math.radians(30), rel=0.05)


def test_close_ends_the_session_and_stops(room_base):
    robot = Robot(room_base, subtype="p3dx-sh")
    robot.connect()
    robot.send(Command.VEL, 200)
    robot.run(1.0)
    robot.send(Command.CLOSE, 1)
    count = len(robot.sips)
    robot.run(1.0)
    assert len(robot.sips) == count and not robot.state.open
    assert not robot.base.reading().moving


def test_vel2_sets_both_wheels(room_base):
    robot = Robot(room_base, subtype="p3dx-sh")
    robot.connect()
    robot.send(Command.VEL2, (5 << 8) | 10)  # left 100 mm/s, right 200 mm/s
    robot.run(2.0)
    sip = robot.sips[-1]
    assert (sip.left_mm_s, sip.right_mm_s) == (pytest.approx(100, abs=2), pytest.approx(200, abs=2))


def test_an_unknown_subtype_is_refused():
    with pytest.raises(arcos.ArcosError, match="subtype"):
        PioneerEmulatorConfig(subtype="roomba")

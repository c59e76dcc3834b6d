"""The planner's handle on the robot: how long it waits for a motion before giving up on the robot."""

from __future__ import annotations

import dataclasses

import pytest

from offboard.robot import robot_client
from offboard.robot.robot_client import RobotClient
from shared import messages as m
from shared.geometry import HeadMount, Intrinsics
from shared.limits import BaseLimits, CameraTiming, PanTiltLimits
from shared.transport import TransportConfig


def test_move_to_waits_as_long_as_the_farthest_waypoint_the_robot_accepts(monkeypatch):
    """The wait assumed no waypoint beyond 30 m: at 90 m on a robot that accepts 100 m, the planner gave
    up on a robot still driving and said it was not running."""
    base = dataclasses.replace(BaseLimits(), max_distance_m=100.0)
    info = m.Info("i", "syt", "sim", base, PanTiltLimits(), CameraTiming(),
                  m.IntrinsicsMsg.from_intrinsics(Intrinsics.from_fov(640, 480, 66.0)),
                  m.MountMsg.from_mount(HeadMount()), 1000)
    waits = []

    def request(session, key, command, expected, timeout_s, sender):  # a robot that only says what it is
        if expected is m.Info:
            return info
        waits.append(timeout_s)

    monkeypatch.setattr(robot_client, "request", request)
    with TransportConfig(multicast_scouting=False).open() as session, RobotClient(session, "syt") as robot:
        robot.move_to(90.0, 0.0)
    assert waits[0] > base.drive_time_s(90.0) + base.turn_time_s(3.1416)
    assert waits[0] == pytest.approx(2 * (base.drive_time_s(100.0) + base.turn_time_s(3.14159265)) + 10.0, rel=1e-3)

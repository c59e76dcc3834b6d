"""The simulated base's physics: what it runs into."""

from __future__ import annotations

import threading

import pytest

from onboard.config import OdometryNoise
from onboard.sim.base import SimBase
from onboard.sim.clock import SimClock
from onboard.sim.world import load_world
from shared.geometry import Pose2D
from shared.limits import BaseLimits


def test_a_target_on_the_floor_stops_the_base_as_furniture_does():
    """``hand/floor``'s target, a 0.25 m box on the floor at (3.0, 2.5), is an obstacle to the base:
    the world checks count it as one, and so does the simulator."""
    limits = BaseLimits()
    base = SimBase(load_world("hand/floor"), limits, SimClock(), OdometryNoise(0.0, 0.0, 0.0))
    assert base.collides(3.0, 2.5)
    assert base.teleport(Pose2D(1.5, 2.5, 0.0)) is None
    outcome = base.move(0.0, 2.0, 0.5, threading.Event())
    assert outcome.status == "stalled"
    assert base.true_pose.x_m == pytest.approx(3.0 - 0.125 - limits.radius_m, abs=0.01)


def test_a_new_runs_target_on_the_floor_blocks_where_it_now_stands_not_where_it_was():
    """``sim_reset`` moved the rendered target, but the base kept running into the old one."""
    from onboard.backends import build_robot
    from onboard.config import OnboardConfig

    robot = build_robot(OnboardConfig(), load_world("hand/floor"))
    base = robot.devices.base
    try:
        assert robot.sim.reset(Pose2D(1.5, 2.5, 0.0), (3.5, 1.5, 0.0), 90.0, seed=1) is None
        assert base.collides(3.5, 1.5) and not base.collides(3.0, 2.5)
        assert robot.sim.reset(Pose2D(3.0, 2.5, 0.0), (3.5, 1.5, 0.0), 90.0, seed=2) is None  # where it was: free
        assert base.true_pose.x_m == 3.0 and base.collides(3.5, 1.5)
    finally:
        robot.devices.close()

"""The search in one process against a simulator subprocess over Zenoh: what it believes of the
robot's head after a move the navigator drove."""

from __future__ import annotations

import math

import pytest

from offboard.planning.planner import Decision

pytestmark = pytest.mark.integration


def test_after_a_move_that_fails_the_search_knows_the_head_points_where_the_navigator_left_it(lab_search):
    search, robot = lab_search, lab_search.robot  # the robot at (4.5, 0.6) facing north, the centre table 1.7 m ahead
    search._look(Decision("look", "west, up", azimuth_rad=math.pi, tilt_rad=math.radians(30.0), setting=0))
    looked = search._pan_tilt
    assert looked == pytest.approx((math.radians(90.0), math.radians(30.0)))
    # a goal inside the table: the navigator drives toward it, looking ahead, until its map shows it blocked
    search._move(Decision("move", "into the table", position_m=(4.5, 2.5), setting=0))
    assert search.state.unreachable == [(4.5, 2.5)] and search.state.distance_m > 0.3
    head = robot.state()
    assert search._pan_tilt == pytest.approx((math.radians(head.pan_deg), math.radians(head.tilt_deg)), abs=1e-3)
    assert search._pan_tilt != pytest.approx(looked, abs=1e-2)  # the navigator turned it, to look ahead or for the map

"""The search's bookkeeping of the settings looked at from where the robot stands."""

from __future__ import annotations

import math

import pytest

from offboard.search.loop import SearchState, same_view
from shared.geometry import HeadMount, Pose2D

HERE = (2.0, 3.0)


def test_a_setting_is_taken_once_from_a_position():
    state = SearchState()
    state.took(3, at_m=HERE)
    assert state.taken == {3} and state.views == [(2.0, 3.0, 3)]


def test_moving_makes_every_setting_new_again_but_keeps_the_views_taken_for_when_the_robot_comes_back():
    state = SearchState()
    state.took(5, at_m=HERE)
    state.took(2, at_m=HERE)
    state.moved()
    assert not state.taken and state.views == [(2.0, 3.0, 5), (2.0, 3.0, 2)]


def test_a_glance_repeats_a_view_only_from_the_same_camera_pose_and_direction():
    mount = HeadMount()
    here = mount.camera_in_world(Pose2D(2.0, 3.0, 0.5), 0.0, math.radians(-25.0))
    assert same_view(here, mount.camera_in_world(Pose2D(2.01, 3.0, 0.5), 0.0, math.radians(-25.0)))
    assert not same_view(here, mount.camera_in_world(Pose2D(2.0, 3.0, 0.5), math.radians(5.0), math.radians(-25.0)))
    assert not same_view(here, mount.camera_in_world(Pose2D(2.0, 3.0, 0.5), 0.0, math.radians(-20.0)))
    assert not same_view(here, mount.camera_in_world(Pose2D(2.1, 3.0, 0.5), 0.0, math.radians(-25.0)))


@pytest.mark.integration
def test_a_move_that_went_nowhere_makes_no_setting_new_again(lab_search):
    """A move that ends unreachable without driving once cleared the settings taken, so the same view
    was taken again and counted as new evidence."""
    from offboard.planning.planner import Decision

    pose = lab_search._pose()
    lab_search.state.took(5, at_m=(pose.x_m, pose.y_m))
    lab_search._move(Decision("move", "a goal inside the wall", position_m=(-5.0, -5.0), setting=0))
    assert lab_search.state.unreachable and lab_search.state.distance_m < 0.05
    assert 5 in lab_search.state.taken

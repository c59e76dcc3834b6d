"""The search's bookkeeping of the settings looked at from where the robot stands."""

from __future__ import annotations

import math

from offboard.search.loop import SearchState, same_view
from shared.geometry import HeadMount, Pose2D

HERE = (2.0, 3.0)


def test_a_setting_is_taken_once_from_a_position():
    state = SearchState()
    state.took(3, located=False, at_m=HERE)
    assert state.taken == {3} and state.views == [(2.0, 3.0, 3)]


def test_a_located_detection_is_confirmed_from_the_same_view_once_and_only_once():
    state = SearchState()
    state.took(5, located=True, at_m=HERE)
    assert 5 not in state.taken and not state.views  # free to look again: a second image confirms it
    state.took(5, located=True, at_m=HERE)
    assert 5 in state.taken and state.views == [(2.0, 3.0, 5)]  # a third image would say nothing new


def test_moving_makes_every_setting_new_again_but_keeps_the_views_taken_for_when_the_robot_comes_back():
    state = SearchState()
    state.took(5, located=True, at_m=HERE)
    state.took(5, located=True, at_m=HERE)
    state.took(2, located=False, at_m=HERE)
    state.moved()
    assert not state.taken and state.views == [(2.0, 3.0, 5), (2.0, 3.0, 2)]
    state.took(5, located=True, at_m=HERE)
    assert 5 not in state.taken


def test_a_glance_repeats_a_view_only_from_the_same_camera_pose_and_direction():
    mount = HeadMount()
    here = mount.camera_in_world(Pose2D(2.0, 3.0, 0.5), 0.0, math.radians(-25.0))
    assert same_view(here, mount.camera_in_world(Pose2D(2.01, 3.0, 0.5), 0.0, math.radians(-25.0)))
    assert not same_view(here, mount.camera_in_world(Pose2D(2.0, 3.0, 0.5), math.radians(5.0), math.radians(-25.0)))
    assert not same_view(here, mount.camera_in_world(Pose2D(2.0, 3.0, 0.5), 0.0, math.radians(-20.0)))
    assert not same_view(here, mount.camera_in_world(Pose2D(2.1, 3.0, 0.5), 0.0, math.radians(-25.0)))

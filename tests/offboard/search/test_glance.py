"""The search in one process against a simulator subprocess over Zenoh: which frames toward the motion
it searches (a glance), and which images, glances or looks, it skips as a view it has already searched."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from conftest import saved_and_read, search_on
from offboard.planning.planner import Decision
from offboard.perception.stereo import StereoMatcher
from offboard.search import checkpoint

pytestmark = pytest.mark.integration


def _glance_at(search, pan_deg: float, heading_correction_deg: float = 0.0) -> None:
    search.robot.look(pan_deg, -25.0)
    capture = search.robot.capture()
    pose = search.tracker.world_pose(capture.pose.to_pose())
    pose = replace(pose, heading_rad=pose.heading_rad + math.radians(heading_correction_deg))
    search._glance(capture, pose, StereoMatcher(search.config.stereo).disparity(capture.left, capture.right))


def test_a_view_is_glanced_at_once_however_a_scan_match_has_moved_the_pose_since(lab_search):
    _glance_at(lab_search, 0.0)
    _glance_at(lab_search, 0.0, heading_correction_deg=4.0)  # the same camera, placed 4° off by a match in between
    assert lab_search.state.glances == 1
    _glance_at(lab_search, 10.0)  # the head turned: a new view
    assert lab_search.state.glances == 2


def test_a_resumed_search_remembers_the_views_it_glanced_at(lab_search, tmp_path):
    """A move stopped on the way by a weak detection begins again where it stopped, its first frame
    the same view: resumed from a checkpoint, the search must still know it has searched it."""
    _glance_at(lab_search, 0.0)
    resumed = search_on(lab_search.robot)
    checkpoint.restore(resumed, saved_and_read(tmp_path, lab_search))
    _glance_at(resumed, 0.0)
    assert resumed.state.glances == 1
    _glance_at(resumed, 10.0)
    assert resumed.state.glances == 2


def test_a_look_that_repeats_a_view_is_an_action_that_changes_neither_belief_nor_map(lab_search):
    """The oracle used to look up to three times from where it stood at the same angles: the same image
    each time, counted as new evidence (a weak detection confirmed by itself)."""
    look = Decision("look", "test", azimuth_rad=0.0, tilt_rad=0.0, setting=0)
    lab_search._look(look)
    belief, odds = lab_search.belief.target_prob.copy(), lab_search.occupancy.log_odds.copy()
    lab_search._look(look)  # the same pose and angles: the same image
    assert lab_search.state.actions == 2 and lab_search.state.look_log[-1]["realised_p"] == 0.0
    assert np.array_equal(lab_search.belief.target_prob, belief)
    assert np.array_equal(lab_search.occupancy.log_odds, odds)
    lab_search._look(replace(look, azimuth_rad=math.radians(40.0)))  # another view: news
    assert not np.array_equal(lab_search.belief.target_prob, belief)

"""The search in one process against a simulator subprocess over Zenoh: which frames toward the motion
it searches (a glance), and which it skips as a view it has already searched."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest

from offboard.perception.stereo import StereoMatcher

pytestmark = pytest.mark.integration


def test_a_view_is_glanced_at_once_however_a_scan_match_has_moved_the_pose_since(lab_search):
    search, robot = lab_search, lab_search.robot
    stereo = StereoMatcher(search.config.stereo)

    def glance_at(pan_deg: float, heading_correction_deg: float = 0.0) -> None:
        robot.look(pan_deg, -25.0)
        capture = robot.capture()
        pose = search.tracker.world_pose(capture.pose.to_pose())
        pose = replace(pose, heading_rad=pose.heading_rad + math.radians(heading_correction_deg))
        search._glance(capture, pose, stereo.disparity(capture.left, capture.right))

    glance_at(0.0)
    glance_at(0.0, heading_correction_deg=4.0)  # the same camera, placed 4° off by a match in between
    assert search.state.glances == 1
    glance_at(10.0)  # the head turned: a new view
    assert search.state.glances == 2

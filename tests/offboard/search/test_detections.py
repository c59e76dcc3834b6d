"""What a detection does to the search in one process against a simulator subprocess over Zenoh:
where it places the target, and when that counts as found."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from offboard.perception.detection.detector import Detection, shipped_table
from offboard.planning.priors import HintBox, hints

pytestmark = pytest.mark.integration


def test_a_detection_without_depth_is_placed_on_its_rays_not_where_a_strong_prior_alone_points(lab_search):
    """The paper-lab robot looks along +y from (4.5, 0.6); a hint box behind it holds nearly all the
    belief. Judged at the belief's likeliest cube anywhere, a weak detection without depth in front
    of the robot made that box, never seen, the find."""
    search = lab_search
    grid = search.occupancy.grid
    search.belief.set_prior(hints(grid, (HintBox((0.2, 0.2, 0.7), (0.5, 0.5, 1.0), 1.0),)), prob_outside=0.02)
    capture = search.robot.capture()
    obs = search.perception.observe(capture, search.tracker.world_pose(capture.pose.to_pose()), None)
    box = (300.0, 220.0, 340.0, 260.0)
    corners = np.array([[box[0], box[1]], [box[2], box[1]], [box[2], box[3]], [box[0], box[3]]])
    obs = replace(obs, detection=Detection.from_corners("sift", corners, 12.0, confident=False), target_m=None)
    _, found = search._interpret(obs, search.detectors["sift"][1])
    assert not found, search.state.estimate_m
    camera = obs.camera_in_world
    ray = (search.state.estimate_m - camera.translation) @ camera.rotation  # in the camera's frame
    u, v = obs.intrinsics.project(ray)
    assert ray[2] > 0 and box[0] - 5 <= u <= box[2] + 5 and box[1] - 5 <= v <= box[3] + 5, (u, v)


def test_the_search_plans_and_updates_with_a_sectors_rate_not_its_centres(lab_search):
    search = lab_search
    measured = shipped_table("sift")
    assert search.belief.facing_sectors == 8
    sectors = measured.for_sectors(8)
    assert sectors.facing_edges_deg[-1] > measured.facing_edges_deg[-1]  # a sector's near edge shows past 90°
    for table in (search.planner.table, search.detectors["sift"][1]):
        assert np.array_equal(table.facing_edges_deg, sectors.facing_edges_deg)
        assert np.array_equal(table.rate, sectors.rate)

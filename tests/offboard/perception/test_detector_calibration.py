"""``calibrate-detector``'s measurement: views spread over each cell, rates pooled where detection
varies smoothly, and a real calibration on a simulated robot."""

from __future__ import annotations

import numpy as np
import pytest

from offboard.perception import calibration
from offboard.perception.calibration import CalibrationGrid, pooled_rate, view_angles
from offboard.perception.detection.detector import make_detector
from offboard.perception.detection.target_model import TargetModel
from conftest import bundled_picture, running_agent


def test_a_rate_pools_the_cells_around_it_and_counts_one_miss_more_than_seen():
    hits, views = np.zeros((4, 4, 4)), np.ones((4, 4, 4))
    hits[:, :, :2] = 1  # every view up to some facing angle found the target, none beyond
    rate = pooled_rate(hits, views)
    assert rate[1, 1, 1] == pytest.approx(18 / 28)  # 27 views around it, 18 of them hits, one miss more
    assert rate[1, 1, 2] == pytest.approx(9 / 28) and rate[1, 1, 3] == 0.0  # the next bin borrows across the edge
    assert rate[0, 0, 0] == pytest.approx(8 / 9)  # a corner has fewer neighbours


def test_a_cells_views_are_its_centre_mirrored_then_spread_over_it():
    grid = CalibrationGrid()
    index = (4, 2, 3)
    centre = tuple((edges[i] + edges[i + 1]) / 2 for edges, i in
                   zip((grid.distance_edges_m, grid.off_axis_edges_deg, grid.facing_edges_deg), index))
    rng = np.random.default_rng(0)
    views = [view_angles(grid, index, centre, sample, rng) for sample in range(6)]
    assert views[0] == centre and views[1] == (centre[0], -centre[1], -centre[2])
    assert len(set(views)) == 6  # a view rendered again would measure nothing new
    for sample, (d, o, f) in enumerate(views[2:], start=2):
        assert np.sign(o) == np.sign(f) == (1 if sample % 2 == 0 else -1)
        assert grid.distance_edges_m[4] <= d <= grid.distance_edges_m[5]
        assert grid.off_axis_edges_deg[2] <= abs(o) <= grid.off_axis_edges_deg[3]
        assert grid.facing_edges_deg[3] <= abs(f) <= grid.facing_edges_deg[4]


def test_a_small_calibration_on_a_simulated_robot_finds_the_target_head_on_and_not_edge_on(tmp_path):
    bundled_picture(tmp_path)
    size = (0.23, 0.23, 0.23)
    world = tmp_path / "calibration.toml"
    world.write_text(calibration.calibration_world("target.png", size, 1.2))
    grid = CalibrationGrid(distance_edges_m=(1.0, 1.5), off_axis_edges_deg=(0.0, 7.0),
                           facing_edges_deg=(0.0, 40.0, 80.0, 120.0), samples=3, negatives=2)
    with running_agent(tmp_path, "--world", str(world)) as (_, robot):
        info = robot.info()
        detector = make_detector("sift", TargetModel.from_files([tmp_path / "target.png"], size),
                                 info.intrinsics.to_intrinsics())
        tally = calibration.calibrate(robot, detector, grid, calibration.face_centre(size, info.mount.height_m), size[1])
    assert tally.views.tolist() == [[[3, 3, 3]]] and tally.negative_views == 2
    assert tally.hits[0, 0, 0] == 3 and tally.hits[0, 0, 2] == 0  # head-on at 1-1.5 m; from behind (80-120°)
    table = calibration.to_table("sift", grid, tally, 0.23)
    assert table.face_size_m == 0.23
    assert table.rate[0, 0, 0] == pytest.approx((3 + tally.hits[0, 0, 1]) / 7)  # with its facing neighbour's views


def test_neighbours_across_a_cliff_in_facing_angle_predict_a_cell_worse_than_those_beside_it():
    hits, views = np.zeros((4, 4, 3)), np.full((4, 4, 3), 2.0)
    hits[:, :, 0] = 2  # seen head-on every time, never from the side
    beside = calibration.held_out_log_loss(hits, views, across_facing=False)
    across = calibration.held_out_log_loss(hits, views)
    assert beside < 0.1 < 0.2 < across  # pooled across the cliff, the 1st facing bin borrows a third of the 0th's rate

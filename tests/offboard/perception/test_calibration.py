"""Where ``calibrate-detector`` stands the robot, and in which cell of the table a view counts."""

from __future__ import annotations

import math

import numpy as np
import pytest

from offboard.perception.calibration import CalibrationGrid, Tally, _cells, viewpoint
from offboard.perception.detectability import cell_indices, view_geometry
from shared.geometry import HeadMount, Pose2D
from shared.limits import PanTiltLimits

MOUNT = HeadMount()
TILT = (PanTiltLimits().tilt_min_deg, PanTiltLimits().tilt_max_deg)
NORMAL = np.array([1.0, 0.0, 0.0])  # the calibration target's picture faces +x


def test_view_geometry_reads_distance_and_both_angles():
    camera = MOUNT.camera_in_world(Pose2D(0.0, 0.0, 0.0), 0.0, 0.0)  # looking along +x
    eye = camera.translation
    d, o, f = view_geometry(camera, eye + [2.0, 0.0, 0.0], -NORMAL)
    assert (d, o, f) == pytest.approx((2.0, 0.0, 0.0), abs=1e-6)
    d, o, f = view_geometry(camera, eye + [2.0, 2.0, 0.0], -NORMAL)  # 45° to the side, face turned 45° away
    assert (d, o, f) == pytest.approx((math.hypot(2, 2), 45.0, 45.0), abs=1e-6)
    d, o, f = view_geometry(camera, eye + [2.0, 0.0, -2.0], -NORMAL)  # 45° below: the face is foreshortened
    assert (o, f) == pytest.approx((45.0, 45.0), abs=1e-6)


@pytest.mark.parametrize("height", CalibrationGrid().face_heights_m)
def test_a_view_lands_where_it_was_aimed_whenever_the_head_can_aim_there(height):
    face = np.array([0.715, 5.5, height])
    reach = -TILT[0] if height < MOUNT.height_m else TILT[1]  # how far the head tilts toward the face
    feasible = aimed = 0
    for d, o, f in _cells(CalibrationGrid()):
        if d <= abs(height - MOUNT.height_m) + 0.05:
            continue  # too near to stand
        elevation = math.degrees(math.asin(abs(height - MOUNT.height_m) / d))
        if f < elevation + 1.0:
            continue  # a face is foreshortened by the elevation: it cannot be seen more squarely
        pose, tilt = viewpoint(d, o, f, face, MOUNT, TILT)
        got = view_geometry(MOUNT.camera_in_world(pose, 0.0, math.radians(tilt)), face, NORMAL)
        assert got[0] == pytest.approx(d, abs=0.01) and got[2] == pytest.approx(f, abs=1.0)
        feasible += 1
        if o >= max(0.0, elevation - reach) + 1.0:  # what the tilt cannot reach stays off the axis
            assert got[1] == pytest.approx(o, abs=1.0)
            aimed += 1
    assert aimed > 0.7 * feasible > 300


def test_a_face_nearer_than_its_height_off_the_camera_cannot_be_seen_that_near():
    assert viewpoint(0.4, 0.0, 45.0, np.array([0.7, 5.5, 0.55]), MOUNT, TILT) is None
    assert viewpoint(1.0, 0.0, 45.0, np.array([0.7, 5.5, 0.55]), MOUNT, TILT) is not None


def test_a_view_counts_in_the_cell_of_its_true_geometry_or_nowhere():
    grid = CalibrationGrid()
    edges = tuple(np.array(e) for e in (grid.distance_edges_m, grid.off_axis_edges_deg, grid.facing_edges_deg))
    index, inside = cell_indices(edges, (1.3, 10.0, 55.0))
    assert inside and tuple(int(i) for i in index) == (4, 1, 5)
    assert not cell_indices(edges, (0.1, 10.0, 55.0))[1]  # nearer than the table
    assert not cell_indices(edges, (1.3, 40.0, 55.0))[1]  # off the table's widest angle


def test_the_heights_tallies_add_up():
    one = Tally(np.ones((2, 1, 1), int), np.full((2, 1, 1), 2), 1, 10, [5.0])
    two = Tally(np.zeros((2, 1, 1), int), np.full((2, 1, 1), 3), 0, 20, [7.0, 9.0])
    both = Tally.merged([one, two])
    assert both.hits.tolist() == [[[1]], [[1]]] and both.views.tolist() == [[[5]], [[5]]]
    assert (both.false_positives, both.negative_views, both.detect_ms) == (1, 30, [5.0, 7.0, 9.0])

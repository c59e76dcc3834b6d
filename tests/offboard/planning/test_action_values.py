"""Expected detection of every action (eq. 1) and covering of every position, on hand-placed masses."""

from __future__ import annotations

import math

import numpy as np
import pytest

from offboard.perception.detectability import DetectabilityTable
from offboard.perception.occupancy import OccupancyGrid
from offboard.perception.voxel_grid import VoxelGrid
from offboard.planning.action_values import ActionGeometry, CameraSettings, block_centers, evaluate
from offboard.planning.belief import TargetBelief
from offboard.planning.sensed_sphere import SphereBins, sensed_spheres
from shared.geometry import HeadMount, Intrinsics

K = Intrinsics.from_fov(640, 480, 66.0)
MOUNT = HeadMount()  # head 1.2 m above the floor
ROOM = VoxelGrid((4.0, 4.0, 2.5), 0.05)
BINS = SphereBins()
SETTINGS = CameraSettings.from_fov(K)


def _belief(*points_m: tuple[float, float, float], weights=None) -> TargetBelief:
    """All the probability in the 0.1 m blocks holding ``points_m`` (by ``weights``), facing the camera."""
    belief = TargetBelief(ROOM, facing_sectors=1, prob_outside=0.0, coarse_factor=2)
    prior = np.zeros(ROOM.shape)
    for (i, j, k), w in zip(np.floor(np.array(points_m) / 0.1).astype(int) * 2, weights or [1.0] * len(points_m)):
        prior[i:i + 2, j:j + 2, k:k + 2] = w
    belief.set_prior(prior, prob_outside=0.0)
    return belief


def _values(belief, positions, occupancy=None, table=None, heavy=None):
    table = table or DetectabilityTable.nominal()
    geometry = ActionGeometry(belief, np.array(positions, float), SETTINGS, MOUNT, K, table, BINS)
    rows = np.arange(len(positions))
    toward = None if heavy is None else block_centers(belief)[heavy]
    spheres = sensed_spheres(occupancy or OccupancyGrid(ROOM), geometry.cameras_m(rows), BINS, table.range_m[1], toward)
    return evaluate(geometry, rows, belief, spheres, heavy=heavy)


def test_inputs_that_do_not_match_the_rows_are_refused():
    """The kernel read past its arrays: the sums came out wrong, silently."""
    belief = _belief((2.25, 1.55, 1.25))
    table = DetectabilityTable.nominal()
    geometry = ActionGeometry(belief, np.array([[1.0, 1.0], [1.5, 1.0]]), SETTINGS, MOUNT, K, table, BINS)
    occupancy, far = OccupancyGrid(ROOM), table.range_m[1]
    two, heavy = np.arange(2), np.array([5, 9])
    spheres = sensed_spheres(occupancy, geometry.cameras_m(two), BINS, far, block_centers(belief)[heavy])
    with pytest.raises(ValueError, match="spheres.radius_m"):
        evaluate(geometry, two[:1], belief, spheres)  # two spheres for one row
    with pytest.raises(ValueError, match="spheres.radius_m"):
        evaluate(geometry, two, belief, sensed_spheres(occupancy, geometry.cameras_m(two[:1]), BINS, far))
    for other in (SphereBins(az_count=24), SphereBins(el_min_rad=math.radians(-60.0))):  # the latter: the same counts
        with pytest.raises(ValueError, match="the spheres' bins .* are not the geometry's"):
            evaluate(geometry, two, belief, sensed_spheres(occupancy, geometry.cameras_m(two), other, far))
    with pytest.raises(ValueError, match="toward_m"):
        evaluate(geometry, two, belief, spheres, heavy=heavy[:1])
    with pytest.raises(ValueError, match="rows"):
        evaluate(geometry, np.array([0, 2]), belief, spheres)
    with pytest.raises(ValueError, match="belief"):
        evaluate(geometry, two, TargetBelief(ROOM, facing_sectors=2, coarse_factor=2), spheres)
    assert evaluate(geometry, two, belief, spheres, heavy=heavy).find_prob.shape == (2, len(SETTINGS))


def _table(off_axis_bins: int) -> DetectabilityTable:
    nominal = DetectabilityTable.nominal()
    shape = (len(nominal.distance_edges_m) - 1, off_axis_bins, len(nominal.facing_edges_deg) - 1)
    return DetectabilityTable("fine", nominal.distance_edges_m, np.linspace(0.0, 45.0, off_axis_bins + 1),
                              nominal.facing_edges_deg, np.full(shape, 0.9), np.zeros(shape, int), 0.0, 1.0)


def test_a_table_with_more_bins_than_the_geometry_holds_is_refused():
    """int8 off-axis bins wrapped the indices past 127 negative: read as out of view."""
    belief = _belief((2.25, 1.55, 1.25))
    with pytest.raises(ValueError, match="200 off-axis bins"):
        ActionGeometry(belief, np.array([[1.0, 1.0]]), SETTINGS, MOUNT, K, _table(200), BINS)
    geometry = ActionGeometry(belief, np.array([[1.0, 1.0]]), SETTINGS, MOUNT, K, _table(128), BINS)
    assert geometry.off_axis_bin.max() > 100


def _bin_axis(direction: np.ndarray) -> np.ndarray:
    """The central axis of the sensed sphere's bin holding ``direction``: 48 azimuths from −180°,
    18 elevations from −75° to 60°."""
    az = math.atan2(direction[1], direction[0])
    el = math.asin(direction[2] / np.linalg.norm(direction))
    step_az, step_el = 2 * math.pi / BINS.az_count, (BINS.el_max_rad - BINS.el_min_rad) / BINS.el_count
    az = -math.pi + (math.floor((az + math.pi) / step_az) + 0.5) * step_az
    el = BINS.el_min_rad + (math.floor((el - BINS.el_min_rad) / step_el) + 0.5) * step_el
    return np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])


@pytest.mark.parametrize("target", [(2.25, 1.55, 1.65), (0.25, 1.45, 0.95), (1.35, 2.45, 1.95)])
def test_a_block_behind_what_stands_on_its_bins_axis_is_worth_nothing_when_no_block_is_heavy(target):
    """Without heavy blocks the sphere bins decide: one cube on the axis of the target's bin hides
    it. Caught bin axes half a bin off, elevation's sign flipped, the axes' grid transposed and
    atan2's arguments swapped (each reads another direction's radius)."""
    belief = _belief(target)
    camera = np.array([1.0, 1.0, MOUNT.height_m])
    offset = block_centers(belief)[np.argmax(belief.coarse_mass().reshape(-1))] - camera
    blocker = OccupancyGrid(ROOM)
    with blocker.edit() as (log_odds, observed):
        log_odds[tuple(ROOM.index_of(camera + _bin_axis(offset) * 0.6 * np.linalg.norm(offset)))] = 5.0
        observed[:] = True
    assert _values(belief, [camera[:2]]).find_prob.max() > 0.3
    hidden = _values(belief, [camera[:2]], blocker)
    assert hidden.find_prob.max() == 0.0 and hidden.covering_prob[0] == 0.0


def test_the_17_settings_are_the_reports():
    np.testing.assert_allclose(np.degrees(SETTINGS.azimuth_rad),
                               np.concatenate([-160.0 + 40.0 * np.arange(9), -157.5 + 45.0 * np.arange(8)]))
    np.testing.assert_allclose(np.degrees(SETTINGS.tilt_rad), [0.0] * 9 + [30.0] * 8)


def test_a_short_last_block_is_centred_on_its_cubes():
    grid = VoxelGrid((4.1, 0.3, 0.25), 0.05)  # 82 × 6 × 5 cubes: blocks of 4, the last ones of 2, 2 and 1
    belief = TargetBelief(grid, coarse_factor=4)
    block = (grid.centers() / 0.2).astype(int).reshape(-1, 3)  # each cube's block
    flat = np.ravel_multi_index(block.T, belief.coarse_shape)
    centres = grid.centers().reshape(-1, 3)
    mean = np.stack([np.bincount(flat, centres[:, a]) / np.bincount(flat) for a in range(3)], axis=1)
    np.testing.assert_allclose(block_centers(belief), mean)


def test_mass_nearer_than_the_detectors_range_is_not_scored():
    """The rate just inside the near limit is too small to count in the range (0.04 < 0.05)."""
    nominal = DetectabilityTable.nominal()
    rate = nominal.rate.copy()
    rate[1] = 0.04  # 0.25-0.5 m
    table = DetectabilityTable("near", nominal.distance_edges_m, nominal.off_axis_edges_deg, nominal.facing_edges_deg,
                               rate, nominal.samples, 0.0, 1.0)
    assert table.range_m[0] == 0.5
    values = _values(_belief((1.35, 1.05, 1.25)), [(1.0, 1.0)], table=table)  # 0.36 m ahead
    assert values.find_prob.max() == 0.0 and values.covering_prob[0] == 0.0


def test_the_covering_is_the_mass_times_its_best_detectability_summed():
    points = [(2.05, 1.05, 1.25), (1.25, 2.05, 1.45), (0.45, 0.65, 1.05)]
    weights = [0.5, 0.3, 0.2]
    belief = _belief(*points, weights=weights)
    table = DetectabilityTable.nominal()
    camera = np.array([1.0, 1.0, MOUNT.height_m])
    axes = SETTINGS.rotations(MOUNT)[:, :, 2]  # the optical axes
    expected = 0.0
    for w, p in zip(weights, points):
        centre = np.floor(np.array(p) / 0.1) * 0.1 + 0.05
        ray = centre - camera
        distance = np.linalg.norm(ray)
        off_axis = np.degrees(np.arccos(axes @ ray / distance)).min()  # in view: under half the field of view
        expected += w * table.lookup(distance, off_axis, 0.0)
    assert expected > 0.5
    assert _values(belief, [camera[:2]]).covering_prob[0] == pytest.approx(expected)

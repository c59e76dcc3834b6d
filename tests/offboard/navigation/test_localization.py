"""Scan matching and odometry fusion on synthetic maps and scans with known offsets."""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from offboard.navigation.localization import (MatchConfig, OdometryModel, PoseTracker, ScanMatcher, likelihood_field,
                                   map_field, scan_from_disparity, structure_in_view)
from offboard.perception.occupancy import OccupancyGrid
from offboard.perception.voxel_grid import VoxelGrid
from shared.geometry import HeadMount, Intrinsics, Pose2D

RES = 0.05
ROOM = (9.0, 5.0)
BOXES = ((3.9, 2.25, 5.1, 2.75), (7.0, 4.45, 8.0, 5.0), (0.0, 1.2, 0.45, 3.8))  # x0, y0, x1, y1


def box_outlines() -> np.ndarray:
    """Occupied floor cells on the boxes' outlines (what stereo maps of a box: its faces)."""
    occupied = np.zeros((180, 100), bool)
    for x0, y0, x1, y1 in BOXES:
        i0, j0, i1, j1 = (int(round(v / RES)) for v in (x0, y0, x1, y1))
        occupied[i0:i1, j0:j1] = True
        occupied[i0 + 1:i1 - 1, j0 + 1:j1 - 1] = False
    return occupied


def surface_points(step_m: float = 0.01) -> np.ndarray:
    """Points on the walls and on the faces of the boxes (at the outline cells' centres)."""
    pts = [np.stack([np.arange(0, ROOM[0], step_m), np.full(int(ROOM[0] / step_m), y)], 1) for y in (0.0, ROOM[1])]
    pts += [np.stack([np.full(int(ROOM[1] / step_m), x), np.arange(0, ROOM[1], step_m)], 1) for x in (0.0, ROOM[0])]
    h = RES / 2
    for x0, y0, x1, y1 in BOXES:
        xs, ys = np.arange(x0 + h, x1 - h, step_m), np.arange(y0 + h, y1 - h, step_m)
        pts += [np.stack([xs, np.full_like(xs, y)], 1) for y in (y0 + h, y1 - h)]
        pts += [np.stack([np.full_like(ys, x), ys], 1) for x in (x0 + h, x1 - h)]
    return np.concatenate(pts)


def camera_scan(true_pose: Pose2D, rng: np.random.Generator, fov_deg: float = 66.0, noise_m: float = 0.02,
                max_range_m: float = 4.5, n: int = 600) -> np.ndarray:
    """What a forward camera sees of the surfaces (no occlusion), noisy, in the robot frame."""
    pts = surface_points()
    d = pts - (true_pose.x_m, true_pose.y_m)
    bearing = np.angle(np.exp(1j * (np.arctan2(d[:, 1], d[:, 0]) - true_pose.heading_rad)))
    keep = (np.hypot(*d.T) < max_range_m) & (np.abs(bearing) < math.radians(fov_deg / 2))
    pts = pts[keep] + rng.normal(0.0, noise_m, (int(keep.sum()), 2))
    pts = pts[np.linspace(0, len(pts) - 1, min(n, len(pts))).astype(int)]
    c, s = math.cos(true_pose.heading_rad), math.sin(true_pose.heading_rad)
    return (pts - (true_pose.x_m, true_pose.y_m)) @ np.array([[c, -s], [s, c]])


@pytest.mark.parametrize("true_pose,offset", [
    (Pose2D(2.0, 2.5, 0.0), (0.12, -0.08, 3.0)),
    (Pose2D(6.0, 1.5, 2.6), (-0.15, 0.10, -2.5)),
    (Pose2D(3.0, 1.0, 0.9), (0.05, 0.15, 4.0)),
    (Pose2D(6.5, 3.5, -2.0), (-0.2, -0.1, -1.0)),
])
def test_a_displaced_scan_is_pulled_back_onto_the_map(true_pose, offset):
    rng = np.random.default_rng(0)
    field = likelihood_field(box_outlines(), RES)
    scan = camera_scan(true_pose, rng, fov_deg=90.0)
    prior = Pose2D(true_pose.x_m + offset[0], true_pose.y_m + offset[1],
                   true_pose.heading_rad + math.radians(offset[2]))
    result = ScanMatcher().match(scan, prior, field)
    assert result.accepted
    assert math.hypot(result.pose.x_m - true_pose.x_m, result.pose.y_m - true_pose.y_m) < 0.03
    assert abs(math.degrees(result.pose.heading_rad - true_pose.heading_rad)) < 0.75


def test_the_window_reaches_the_heading_error_of_a_half_turn():
    """3 % of a half turn is 5.4°: the robot may be 14° off, and the match must still find it."""
    true_pose = Pose2D(2.0, 2.5, 0.0)
    scan = camera_scan(true_pose, np.random.default_rng(0), fov_deg=90.0)
    prior = Pose2D(2.05, 2.45, math.radians(14.0))
    after_half_turn = np.diag([0.03 ** 2, 0.03 ** 2, math.radians(0.03 * 180.0) ** 2])
    result = ScanMatcher().match(scan, prior, likelihood_field(box_outlines(), RES), after_half_turn)
    assert result.accepted, result.reason
    assert abs(math.degrees(result.pose.heading_rad - true_pose.heading_rad)) < 0.75


def test_the_likelihood_field_is_exact_and_the_same_bits_on_every_call():
    """Distances are the exact Euclidean ones, whatever OpenCV's thread count and the buffers'
    alignment: a scan match can tip on the last bit, and then a repeated run parts from the first.
    (OpenCV's exact transform gave up to 3 distinct fields for one map; opencv/opencv#24082.)"""
    rng = np.random.default_rng(3)
    occupied = np.zeros((200, 200), bool)
    sources = rng.integers(80, 120, (6, 2))
    occupied[sources[:, 0], sources[:, 1]] = True
    config = MatchConfig()
    threads = cv2.getNumThreads()
    try:
        fields, ballast = [], []
        for n in (1, 2, 1, 2):
            cv2.setNumThreads(n)
            ballast.append(np.empty(int(rng.integers(1, 50_000))))  # kept, so the next buffers land elsewhere
            fields.append(likelihood_field(occupied, RES, config, pad_cells=0).values)
    finally:
        cv2.setNumThreads(threads)
    assert all(np.array_equal(f, fields[0]) for f in fields)
    centre = (np.indices(occupied.shape) + 0.5) * RES  # cell centres, metres
    d_source = np.min(np.hypot(*(centre[..., None] - ((sources.T + 0.5) * RES)[:, None, None, :])), axis=-1)
    d_wall = np.minimum(centre, 200 * RES - centre).min(axis=0)
    nearer = d_source < d_wall
    w = config.hit_weight
    exact = np.log(w * np.exp(-0.5 * (d_source / config.sigma_m) ** 2) + 1.0 - w)
    np.testing.assert_allclose(fields[0][nearer], exact[nearer], rtol=0.0, atol=1e-12)


def test_a_single_wall_constrains_only_across_it():
    """Along the wall every pose of the window fits as well: the best one there is arbitrary, and
    the fused pose must not be pulled toward it."""
    field = likelihood_field(np.zeros((180, 100), bool), RES)  # walls only
    true_pose = Pose2D(4.5, 3.5, math.pi / 2)  # facing the north wall, 1.5 m away
    scan = camera_scan(true_pose, np.random.default_rng(1), fov_deg=40.0)
    prior = Pose2D(4.6, 3.6, math.pi / 2)
    result = ScanMatcher().match(scan, prior, field)
    assert result.accepted and abs(result.pose.y_m - 3.5) < 0.03
    sx, sy = np.sqrt(np.diag(result.covariance))[:2]
    assert sx > 3 * sy  # along the wall, the scan says little
    tracker = PoseTracker(prior, covariance=np.diag([0.1 ** 2, 0.1 ** 2, math.radians(2.0) ** 2]))
    assert tracker.correct(prior, result.pose, result.covariance)
    assert tracker.pose.x_m == pytest.approx(4.6, abs=0.005) and tracker.pose.y_m == pytest.approx(3.5, abs=0.01)


def test_too_few_points_or_points_off_the_map_are_not_accepted():
    field = likelihood_field(box_outlines(), RES)
    matcher = ScanMatcher()
    few = camera_scan(Pose2D(2.0, 2.5, 0.0), np.random.default_rng(2))[:20]
    assert not matcher.match(few, Pose2D(2.0, 2.5, 0.0), field).accepted
    junk = np.random.default_rng(3).uniform(0.5, 3.0, (400, 2))  # a cloud in free space
    result = matcher.match(junk, Pose2D(2.0, 2.5, 0.0), field)
    assert not result.accepted and "on the map" in result.reason


def test_scan_from_disparity_projects_a_wall_to_the_floor():
    k = Intrinsics.from_fov(64, 48, 66.0)
    mount = HeadMount()
    depth = 2.0  # a wall 2 m ahead, facing the camera (pan 0, tilt 0)
    disparity = np.full((48, 64), k.fx_px * mount.baseline_m / depth, np.float32)
    config = MatchConfig(stride_px=1, max_points=10_000)
    xy = scan_from_disparity(disparity, k, mount, 0.0, 0.0, config)
    assert np.allclose(xy[:, 0], depth, atol=1e-3)
    half_width = depth * math.tan(math.radians(33.0))
    assert xy[:, 1].min() == pytest.approx(-half_width, abs=0.1)
    assert xy[:, 1].max() == pytest.approx(half_width, abs=0.1)
    # rows whose points lie below band_min_m (the floor) or above band_max_m are dropped
    vertical = depth * np.tan(np.linspace(-k.vfov_rad / 2, k.vfov_rad / 2, 48))
    expected_rows = np.count_nonzero((mount.height_m - vertical >= 0.15) & (mount.height_m - vertical <= 2.2))
    assert abs(xy.shape[0] / 64 - expected_rows) <= 1


def test_map_field_uses_occupied_columns_and_walls():
    occupancy = OccupancyGrid(VoxelGrid((9.0, 5.0, 2.5), RES))
    with occupancy.edit() as (log_odds, _):
        log_odds[80:82, 50:52, 5:20] = 2.0  # a post at (4.05, 2.55), 0.25-1.0 m high
    field = map_field(occupancy)
    on_post, on_wall, free = field.at(np.array([[4.05, 2.55], [0.0, 1.0], [2.0, 1.0]]))
    assert on_post > -0.2 and on_wall > -0.2 and free < -2.0  # the wall lies between two cell centres


# --- fusion ----------------------------------------------------------------------------------------

def test_structure_in_view_counts_what_a_scan_could_match_within_its_range():
    """In the 9 × 5 m room, 1 m from the west wall and facing east, with a 60° camera: straight ahead
    the east wall is 8 m off and the side walls lie outside the view within the scan's 4.5 m, so
    there is nothing to match until a mapped box stands there. Pans count to the left (from +x
    toward +y) and turn with the robot."""
    pans, hfov = np.radians([-90.0, -50.0, 0.0, 50.0, 90.0, 180.0]), math.radians(60.0)
    here = Pose2D(1.0, 2.5, 0.0)
    walls = structure_in_view(likelihood_field(np.zeros((180, 100), bool), RES), here, pans, hfov)
    assert walls[2] == 0 and min(walls[0], walls[4], walls[5]) > 20
    occupied = np.zeros((180, 100), bool)
    occupied[54:58, 80:90] = True  # a 0.5 m face at (2.8, 4.25): 44° to the left, 2.5 m away
    boxed = structure_in_view(likelihood_field(occupied, RES), here, pans, hfov)
    assert boxed[3] >= walls[3] + 20  # seen at 50° to the left, and nowhere else
    assert np.array_equal(np.delete(boxed, 3), np.delete(walls, 3))
    turned = structure_in_view(likelihood_field(occupied, RES), Pose2D(1.0, 2.5, math.pi / 2), pans - math.pi / 2, hfov)
    assert np.array_equal(turned, boxed)


def test_the_target_shift_bounds_the_sweep_of_a_point_at_range():
    tracker = PoseTracker(Pose2D(0.0, 0.0, 0.0), covariance=np.diag([0.04 ** 2, 0.01 ** 2, math.radians(2.0) ** 2]))
    assert tracker.target_shift_m(0.0) == pytest.approx(0.04)
    assert tracker.target_shift_m(3.0) == pytest.approx(0.04 + 3.0 * math.radians(2.0))
    along_diagonal = np.array([[1.0, 0.99], [0.99, 1.0]]) * 0.03 ** 2  # x and y errors move together
    correlated = PoseTracker(Pose2D(0.0, 0.0, 0.0), covariance=np.block([[along_diagonal, np.zeros((2, 1))],
                                                                         [np.zeros((1, 2)), np.eye(1) * 1e-8]]))
    assert correlated.target_shift_m(0.0) == pytest.approx(0.03 * math.sqrt(1.99), rel=1e-3)  # not σx


def test_tracker_maps_odometry_to_world_and_back():
    tracker = PoseTracker(Pose2D(1.0, 1.0, 0.0), world=Pose2D(1.2, 0.9, 0.1))  # an offset transform
    odom = Pose2D(2.0, 1.0, 0.0)
    world = tracker.world_pose(odom)
    assert world.heading_rad == pytest.approx(0.1)
    assert tracker.odom_point((world.x_m, world.y_m)) == pytest.approx((odom.x_m, odom.y_m), abs=1e-9)
    moved = tracker.world_pose(Pose2D(3.0, 1.0, 0.0))  # the correction travels with the robot
    assert (moved.x_m - world.x_m, moved.y_m - world.y_m) == pytest.approx((math.cos(0.1), math.sin(0.1)))


def test_covariance_grows_with_motion_and_shrinks_with_a_match():
    tracker = PoseTracker(Pose2D(0.0, 0.0, 0.0))
    before = np.trace(tracker.covariance[:2, :2])
    tracker.predict(Pose2D(5.0, 0.0, 0.0))
    grown = tracker.covariance.copy()
    assert np.trace(grown[:2, :2]) > before + (0.03 * 5.0) ** 2 * 0.9
    assert grown[1, 1] > grown[0, 0]  # heading drift bends the path sideways: lateral error dominates
    true_pose = Pose2D(5.05, 0.1, 0.01)
    assert tracker.correct(Pose2D(5.0, 0.0, 0.0), true_pose, np.diag([0.02 ** 2, 0.02 ** 2, 0.01 ** 2]))
    assert np.trace(tracker.covariance) < np.trace(grown)
    assert math.hypot(tracker.pose.x_m - 5.05, tracker.pose.y_m - 0.1) < 0.03


def test_an_outlying_match_is_gated_out():
    tracker = PoseTracker(Pose2D(0.0, 0.0, 0.0), model=OdometryModel())
    tracker.predict(Pose2D(1.0, 0.0, 0.0))
    assert not tracker.correct(Pose2D(1.0, 0.0, 0.0), Pose2D(1.8, 0.6, 0.3), np.diag([1e-4, 1e-4, 1e-4]))
    assert tracker.pose == Pose2D(1.0, 0.0, 0.0)


def test_matching_and_fusion_keep_a_drifting_robot_on_track():
    """Drive a square loop with drifting odometry; correct every 0.5 m from a simulated camera scan."""
    rng = np.random.default_rng(5)
    field = likelihood_field(box_outlines(), RES)
    matcher = ScanMatcher()
    truth, odom = Pose2D(2.0, 1.0, 0.0), Pose2D(2.0, 1.0, 0.0)
    tracker = PoseTracker(odom)
    legs = [(0.0, 5.0)] + [(math.pi / 2, 3.0), (math.pi / 2, 5.0)] * 3 + [(math.pi / 2, 3.0)]  # twice round
    for turn, length in legs:
        for i, step in enumerate([0.5] * int(length / 0.5)):
            t = turn if i == 0 else 0.0
            truth = truth.moved(step, t)
            odom = odom.moved(step * 1.03, t * 1.03 + math.radians(1.5) * step)  # a biased base
            tracker.predict(odom)
            result = matcher.match(camera_scan(truth, rng), tracker.pose, field, tracker.covariance)
            if result.accepted:
                tracker.correct(odom, result.pose, result.covariance)
    assert math.hypot(odom.x_m - truth.x_m, odom.y_m - truth.y_m) > 0.5
    assert math.hypot(tracker.pose.x_m - truth.x_m, tracker.pose.y_m - truth.y_m) < 0.08


def test_backing_off_is_not_a_half_turn():
    tracker = PoseTracker(Pose2D(1.0, 1.0, 0.0))
    tracker.predict(Pose2D(0.85, 1.0, 0.0))  # 0.15 m straight back
    assert math.degrees(math.sqrt(tracker.covariance[2, 2])) < 1.0


@pytest.mark.parametrize("jitter", [(-1e-7, 1e-7), (-0.002, 0.002), (0.002, 0.002)])
def test_odometry_jitter_in_place_adds_no_turn(jitter):
    """A base standing still (a look, an in-place turn) reads a millimetre or two off: that has no
    direction the base turned to, and once cost 1.9° of heading σ each time, backwards or forwards."""
    tracker = PoseTracker(Pose2D(1.0, 1.0, 0.0))
    before = math.sqrt(tracker.covariance[2, 2])
    tracker.predict(Pose2D(1.0 + jitter[0], 1.0 + jitter[1], 0.0))
    assert math.degrees(math.sqrt(tracker.covariance[2, 2]) - before) < 0.05

def test_an_unmapped_object_is_not_slid_onto_a_wall():
    """Early in a run the map holds the walls only. A far, compact patch of an object it does not
    hold yet, 0.6 m in front of a wall and off to the side, fits that wall by turning the robot ~7°:
    a ridge of good fits running into the window's heading edge, whose best pose lies just inside it.
    The match is refused. The same patch seen on the wall itself is accepted, its covariance wide
    enough along the ridge (the patch alone cannot tell) to hold the true pose."""
    field = likelihood_field(np.zeros((180, 100), bool), RES)  # walls only
    rng = np.random.default_rng(0)
    pose = Pose2D(4.5, 2.5, 0.0)  # facing the east wall (x = 9), 4.5 m away
    prior_covariance = np.diag([0.05 ** 2, 0.05 ** 2, math.radians(2.0) ** 2])

    def patch(x_m: float) -> np.ndarray:  # 0.5 m wide, stereo-thick, 1.3 m to the left, robot frame
        return np.stack([x_m + rng.uniform(-0.1, 0.1, 400), 1.3 + rng.uniform(0.0, 0.5, 400)], axis=1)

    matcher = ScanMatcher()
    unmapped = matcher.match(patch(3.9), pose, field, prior_covariance)
    assert not unmapped.accepted and "edge" in unmapped.reason
    on_wall = matcher.match(patch(4.5), pose, field, prior_covariance)
    assert on_wall.accepted
    error = np.array([on_wall.pose.x_m - pose.x_m, on_wall.pose.y_m - pose.y_m, on_wall.pose.heading_rad])
    assert error @ np.linalg.solve(on_wall.covariance, error) < 11.3  # χ²(3) at 99 %


def test_map_field_leaves_out_the_floor_noise_layer_below_the_band():
    """The band starts at 0.15 m, a cube boundary: the 0.10-0.15 m layer (stereo noise on the floor)
    is in no scan and must not be in the map (0.15 / 0.05 rounds down to 2.9999999999999996)."""
    occupancy = OccupancyGrid(VoxelGrid((9.0, 5.0, 2.5), RES))
    with occupancy.edit() as (log_odds, _):
        log_odds[40, 50, 2] = 2.0  # 0.10-0.15 m high, at (2.025, 2.525)
        log_odds[120, 50, 3] = 2.0  # 0.15-0.20 m high, at (6.025, 2.525)
    below, in_band = map_field(occupancy).at(np.array([[2.025, 2.525], [6.025, 2.525]]))
    assert below < -2.0 and in_band > -0.2


@pytest.mark.parametrize("bad", ["scan", "prior"])
def test_a_non_finite_scan_or_prior_is_an_error_not_a_refusal(bad):
    scan = camera_scan(Pose2D(2.0, 2.5, 0.0), np.random.default_rng(0))
    prior = Pose2D(2.0, 2.5, 0.0)
    if bad == "scan":
        scan[5, 1] = np.nan
    else:
        prior = Pose2D(math.nan, 2.5, 0.0)
    with pytest.raises(ValueError, match=bad):
        ScanMatcher().match(scan, prior, likelihood_field(box_outlines(), RES))


def test_the_window_widens_to_reach_an_uncertain_prediction():
    """0.4 m off, beyond the default 0.3 m window: a prediction that uncertain is searched 3σ wide."""
    true_pose = Pose2D(2.0, 2.5, 0.0)
    scan = camera_scan(true_pose, np.random.default_rng(0), fov_deg=90.0)
    prior = Pose2D(2.4, 2.5, 0.0)
    uncertain = np.diag([0.15 ** 2, 0.03 ** 2, 1e-4])
    result = ScanMatcher().match(scan, prior, likelihood_field(box_outlines(), RES), uncertain)
    assert result.accepted, result.reason
    assert math.hypot(result.pose.x_m - true_pose.x_m, result.pose.y_m - true_pose.y_m) < 0.03


def test_backing_off_couples_heading_to_position_behind_the_robot():
    """A heading error swings where a drive ends: to the left of the drive direction, which backing
    off points behind the robot, so the position-heading cross-terms change sign."""
    heading = 0.3
    left = np.array([-math.sin(heading), math.cos(heading)])
    forward, backward = (PoseTracker(Pose2D(1.0, 1.0, heading)) for _ in range(2))
    forward.predict(Pose2D(1.0 + 0.5 * math.cos(heading), 1.0 + 0.5 * math.sin(heading), heading))
    backward.predict(Pose2D(1.0 - 0.5 * math.cos(heading), 1.0 - 0.5 * math.sin(heading), heading))
    assert forward.covariance[:2, 2] @ left > 0 > backward.covariance[:2, 2] @ left


def test_the_error_grows_across_the_world_direction_of_travel():
    """Odometry turned a quarter turn from the world: a drive along odometry x runs along world y,
    and the covariance is the odometry-aligned one turned by that quarter turn."""
    aligned = PoseTracker(Pose2D(0.0, 0.0, 0.0))
    turned = PoseTracker(Pose2D(0.0, 0.0, 0.0), world=Pose2D(0.0, 0.0, math.pi / 2))
    aligned.predict(Pose2D(2.0, 0.0, 0.0))
    turned.predict(Pose2D(2.0, 0.0, 0.0))
    rotate = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(turned.covariance, rotate @ aligned.covariance @ rotate.T, atol=1e-12)


def test_a_heading_measured_across_the_half_turn_is_close():
    """Predicted just short of +π, measured just past -π: 0.02 rad apart, not 2π."""
    tracker = PoseTracker(Pose2D(1.0, 1.0, math.pi - 0.01))
    assert tracker.correct(Pose2D(1.0, 1.0, math.pi - 0.01), Pose2D(1.0, 1.0, -math.pi + 0.01),
                           np.diag([1e-4, 1e-4, math.radians(0.5) ** 2]))
    assert abs(math.cos(tracker.pose.heading_rad) + 1.0) < 1e-3


def test_correct_predicts_to_its_own_odometry_reading():
    """A match taken 1 m on, with no predict before it: the prediction to that reading comes first,
    so the match agrees with it instead of lying 1 m off the last one."""
    tracker = PoseTracker(Pose2D(0.0, 0.0, 0.0))
    assert tracker.correct(Pose2D(1.0, 0.0, 0.0), Pose2D(1.01, 0.0, 0.0), np.diag([1e-4, 1e-4, 1e-4]))
    assert tracker.pose.x_m == pytest.approx(1.0, abs=0.02) and tracker.pose.y_m == pytest.approx(0.0, abs=0.01)


@pytest.mark.parametrize("turn_deg", [91.0, 135.0, 170.0, -120.0])
def test_a_turn_past_a_quarter_then_a_drive_is_not_read_as_backing_off(turn_deg):
    """``move_to`` a waypoint behind the base turns in place, then drives forward: one odometry step
    that ends behind where it began. Read as a back-off, the first turn's error never swung the drive
    sideways (a 170° turn gave 6 mm of σ across a 0.6 m drive, 89° gave 28 mm)."""
    def across_sigma(turn: float) -> float:
        tracker = PoseTracker(Pose2D(0.0, 0.0, 0.0))
        heading = math.radians(turn)
        tracker.predict(Pose2D(0.6 * math.cos(heading), 0.6 * math.sin(heading), heading))
        across = np.array([-math.sin(heading), math.cos(heading)])
        return math.sqrt(across @ tracker.covariance[:2, :2] @ across)

    assert across_sigma(turn_deg) > 0.9 * across_sigma(89.0 if turn_deg > 0 else -89.0)

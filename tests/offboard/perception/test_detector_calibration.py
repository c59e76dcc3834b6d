"""``calibrate-detector``'s measurement: views spread over each cell, rates pooled where detection
varies smoothly, and a real calibration on a simulated robot."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from offboard.perception import calibration
from offboard.perception.calibration import CalibrationGrid, pooled_rate, view_angles
from offboard.perception.detection.detector import Detection, make_detector
from offboard.perception.detection.target_model import TargetModel
from shared.geometry import HeadMount, Intrinsics, Pose2D
from conftest import bundled_picture, running_agent

SIZE = (0.23, 0.23, 0.23)
CAMERA = Intrinsics.from_fov(640, 480, 66.0)
MOUNT = HeadMount(forward_m=0.1)  # the left camera 6 cm beside the robot's centre and 10 cm ahead
FACE = calibration.face_centre(SIZE, MOUNT.height_m)


def _seen_by_left_camera(pose: Pose2D) -> tuple[float, float, float]:
    """(distance, signed off-axis angle, signed facing angle) of the face's centre from the left camera."""
    camera = MOUNT.camera_in_world(pose, 0.0, 0.0)
    x, _, z = camera.inverse().apply(FACE[None])[0]  # optical frame: x right, z ahead
    ray = FACE - camera.translation
    return float(np.linalg.norm(ray)), math.degrees(math.atan2(-x, z)), math.degrees(math.atan2(-ray[1], -ray[0]))


def _detection_at(centre_px: np.ndarray) -> Detection:
    corners = centre_px + np.array([[-10.0, -10.0], [10.0, -10.0], [10.0, 10.0], [-10.0, 10.0]])
    return Detection.from_corners("sift", corners, 50.0, True)


@pytest.mark.parametrize("cell", [(0.375, 31.5, 45.0), (0.375, -31.5, -45.0), (1.125, 3.5, 85.0),
                                  (4.0, -17.5, 15.0)])
def test_the_left_camera_sees_the_face_at_the_cells_distance_and_angles(cell):
    pose = calibration.viewpoint(*cell, FACE, MOUNT)
    assert _seen_by_left_camera(pose) == pytest.approx(cell, abs=1e-9)


def test_a_detection_is_on_the_target_within_a_quarter_of_its_width_and_never_under_12_px():
    def hit(distance_m: float, off_px: float) -> bool:
        pose = calibration.viewpoint(distance_m, 0.0, 0.0, FACE, MOUNT)
        truth = np.array([CAMERA.cx_px, CAMERA.cy_px])  # straight ahead
        return calibration.is_true_hit(_detection_at(truth + [off_px, 0.0]), FACE, pose, CAMERA, MOUNT, SIZE[1])

    assert hit(1.0, 27.0) and not hit(1.0, 30.0)  # a quarter of the face: 28.3 px at 1 m
    assert hit(5.0, 11.0) and not hit(5.0, 13.0)  # a quarter is 5.7 px at 5 m: the floor rules


class _ScriptedRobot:
    """A simulated robot that goes anywhere; its detector answers from a script, in view order."""

    def __init__(self):
        self.pose = None

    def info(self):
        return SimpleNamespace(intrinsics=SimpleNamespace(to_intrinsics=lambda: CAMERA),
                               mount=SimpleNamespace(to_mount=lambda: MOUNT))

    def look(self, pan_rad: float, tilt_rad: float) -> None:
        pass

    def sim_teleport(self, x_m: float, y_m: float, heading_deg: float) -> None:
        self.pose = Pose2D(x_m, y_m, math.radians(heading_deg))

    def capture(self):
        return SimpleNamespace(left=np.zeros((CAMERA.height_px, CAMERA.width_px, 3), np.uint8))


class _ScriptedDetector:
    def __init__(self, robot: _ScriptedRobot, script: list[str | None]):
        self.robot, self.script = robot, list(script)

    def detect(self, image: np.ndarray) -> Detection | None:
        answer = self.script.pop(0)
        if answer == "on target":
            camera = MOUNT.camera_in_world(self.robot.pose, 0.0, 0.0)
            return _detection_at(CAMERA.project(camera.inverse().apply(FACE[None]))[0])
        return _detection_at(np.array([30.0, 30.0])) if answer == "elsewhere" else None


def test_a_misplaced_detection_misses_its_cell_and_only_views_without_the_target_make_the_false_positive_rate():
    robot = _ScriptedRobot()
    detector = _ScriptedDetector(robot, ["on target", "elsewhere", "elsewhere", None, None])
    grid = CalibrationGrid(distance_edges_m=(1.0, 1.5), off_axis_edges_deg=(0.0, 7.0), facing_edges_deg=(0.0, 40.0),
                           samples=2, negatives=3)
    tally = calibration.calibrate(robot, detector, grid, FACE, SIZE[1])
    assert tally.views.tolist() == [[[2]]] and tally.hits.tolist() == [[[1]]]
    assert (tally.misplaced, tally.false_positives, tally.negative_views) == (1, 1, 3)
    table = calibration.to_table("sift", grid, tally, 0.23)
    assert table.false_positive_rate == pytest.approx(1 / 3)
    figures = calibration.summary(table, tally)
    assert (figures["false_detections"], figures["misplaced_detections"]) == (2, 1)


class _Draws:
    """A random generator that draws the given numbers, in order."""

    def __init__(self, values: tuple[float, ...]):
        self.values = list(values)

    def uniform(self, low: float, high: float) -> float:
        return self.values.pop(0)


def test_views_without_the_target_keep_it_well_outside_the_left_cameras_view():
    mount = HeadMount()
    face = calibration.face_centre(SIZE, mount.height_m)
    # 1 m in front of the face, 58.5° left of the robot's heading but 56.6° off its left camera's
    # axis: inside the 33° + 25° a view without the target keeps from it
    beside, away = (face[0] + 1.0, face[1], math.radians(180.0 - 58.5)), (4.0, 5.5, 0.0)
    assert calibration._looking_away(_Draws(beside + away), face, CAMERA, mount) == Pose2D(*away)


def test_the_summary_counts_whole_facing_bins_up_to_40_degrees():
    grid = CalibrationGrid()
    shape = (len(grid.distance_edges_m) - 1, len(grid.off_axis_edges_deg) - 1, len(grid.facing_edges_deg) - 1)
    tally = calibration.Tally(np.zeros(shape, int), np.ones(shape, int))
    tally.hits[:, :, 3] = 1  # every view 30-40° off the normal found the target
    figures = calibration.summary(calibration.to_table("sift", grid, tally, 0.23), tally)
    assert figures["views_0_5_to_2_5m_under_45deg"] == 8 * 5 * 4  # 0.5-2.5 m, every off-axis bin, 0-40°
    assert figures["detection_rate_0_5_to_2_5m_under_45deg"] == 0.25


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
    world = tmp_path / "calibration.toml"
    head_m = HeadMount().height_m  # the agent's head
    world.write_text(calibration.calibration_world("target.png", SIZE, head_m))
    grid = CalibrationGrid(distance_edges_m=(1.0, 1.5), off_axis_edges_deg=(0.0, 7.0), samples=3, negatives=2)
    with running_agent(tmp_path, "--world", str(world)) as (_, robot):
        info = robot.info()
        detector = make_detector("sift", TargetModel.from_files([tmp_path / "target.png"], SIZE),
                                 info.intrinsics.to_intrinsics())
        tally = calibration.calibrate(robot, detector, grid, calibration.face_centre(SIZE, head_m), SIZE[1])
    assert tally.views.tolist() == [[[3] * 9]] and tally.negative_views == 2
    assert tally.misplaced == tally.false_positives == 0  # nothing found elsewhere, nor on the posters
    assert tally.hits[0, 0, 0] == 3 and tally.hits[0, 0, 8] == 0  # head-on at 1-1.5 m; not edge-on (80-90°)
    table = calibration.to_table("sift", grid, tally, 0.23)
    assert table.face_size_m == 0.23
    assert table.rate[0, 0, 0] == pytest.approx((3 + tally.hits[0, 0, 1]) / 7)  # with its facing neighbour's views


def test_a_cells_held_out_rate_comes_from_its_neighbours_views_alone():
    hits, views = np.array([[[1.0]], [[0.0]]]), np.ones((2, 1, 1))  # two cells, one view each
    # each predicted by the other alone: 0 / (1 + 1), clipped to 0.02; and 1 / (1 + 1)
    expected = -(math.log(0.02) + math.log(1 - 0.5)) / 2
    assert calibration.held_out_log_loss(hits, views) == pytest.approx(expected)


def test_neighbours_across_a_cliff_in_facing_angle_predict_a_cell_worse_than_those_beside_it():
    hits, views = np.zeros((4, 4, 3)), np.full((4, 4, 3), 2.0)
    hits[:, :, 0] = 2  # seen head-on every time, never from the side
    beside = calibration.held_out_log_loss(hits, views, across_facing=False)
    across = calibration.held_out_log_loss(hits, views)
    assert beside < 0.1 < 0.2 < across  # pooled across the cliff, the 1st facing bin borrows a third of the 0th's rate

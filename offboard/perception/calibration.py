"""``syt-offboard calibrate-detector``: measure a detector's detectability table on simulated views.

The real detector runs on real rendered stereo captures, taken by a simulated robot that the
calibration teleports around a target it has placed itself (the simulator's ``sim/teleport``):
for every cell of distance × angle off the optical axis × angle between the viewing ray and the
face's normal, the robot stands where the target is seen about that way, with its head tilted
toward it, and the detector either finds the target where it is, finds something elsewhere (a
false positive), or nothing. Each view counts in the cell of its true 3D geometry, reckoned as the
planner reckons it (:func:`~offboard.perception.detectability.view_geometry`). Views that look
away from the target — at posters of other pictures — measure the false-positive rate.

The calibration room is written by the calibration itself (a world file in the simulator's format):
a large room with textured walls, distractor posters and the target on a stand. The stand is set
in turn to each of :attr:`CalibrationGrid.face_heights_m`, so the target is seen from above and
below as well as level, as it is on the tables and shelves where targets stand.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from offboard.perception.detectability import DetectabilityTable, cell_indices, view_geometry
from offboard.perception.detection.detector import Detector
from offboard.robot.robot_client import CommandError, RobotClient
from shared.geometry import HeadMount, Intrinsics, Pose2D, RigidTransform, wrap_angle

log = logging.getLogger(__name__)

ROOM_M = (7.5, 11.0, 2.6)
TARGET_XY = (0.6, 5.5)  # on a stand by the west wall, its picture facing +x (into the room)


@dataclass(frozen=True)
class CalibrationGrid:
    distance_edges_m: tuple[float, ...] = tuple(np.round(np.arange(0.25, 6.01, 0.25), 3))
    off_axis_edges_deg: tuple[float, ...] = (0.0, 7.0, 14.0, 21.0, 28.0, 35.0)
    facing_edges_deg: tuple[float, ...] = tuple(float(v) for v in range(0, 91, 10))
    # the picture's centre above the floor: low shelves, tables, the camera's height, high shelves
    # (the bundled suites' targets stand between 0.4 and 2.0 m, their centres 0.12 m higher)
    face_heights_m: tuple[float, ...] = (0.55, 0.85, 1.2, 1.55, 1.95)
    samples: int = 1  # views per cell and height (each with the opposite sign of the angles from the last)
    negatives: int = 200  # views without the target, shared among the heights


@dataclass
class Tally:
    hits: np.ndarray
    views: np.ndarray
    false_positives: int = 0
    negative_views: int = 0
    detect_ms: list[float] = field(default_factory=list)

    @classmethod
    def merged(cls, tallies: list[Tally]) -> Tally:
        """One tally of several (the heights')."""
        return cls(sum(t.hits for t in tallies), sum(t.views for t in tallies),
                   sum(t.false_positives for t in tallies), sum(t.negative_views for t in tallies),
                   [ms for t in tallies for ms in t.detect_ms])


def calibration_world(target_picture: str, target_size_m: tuple[float, float, float], face_height_m: float) -> str:
    """The calibration room in the simulator's world format; the target's centre ``face_height_m`` up."""
    bottom = face_height_m - target_size_m[2] / 2
    x, y = TARGET_XY
    posters = [("astronaut", 7.48, 2.5, 1.3, 180), ("coffee", 7.48, 8.5, 1.3, 180), ("rocket", 3.5, 10.98, 1.4, -90),
               ("hubble", 3.5, 0.02, 1.4, 90)]  # not chelsea: the target's picture is cut from it
    text = ['name = "calibration"', "[room]", f"size = {list(ROOM_M)}", 'texture = "brick"', "",
            "[[obstacle]]", 'name = "stand"', 'kind = "stand"', f"min = [{x - 0.15}, {y - 0.15}, 0.0]",
            f"max = [{x + 0.15}, {y + 0.15}, {bottom:.3f}]", 'texture = "wood"', ""]
    for name, px, py, pz, yaw in posters:
        text += ["[[poster]]", f'name = "{name}"', f'picture = "{name}"', f"center = [{px}, {py}, {pz}]",
                 "size = [0.5, 0.4]", f"yaw_deg = {yaw}", ""]
    text += ["[target]", f'picture = "{target_picture}"', f"size = {list(target_size_m)}",
             f"position = [{x}, {y}, {bottom:.3f}]", "yaw_deg = 0", "", "[robot]", "start = [4.0, 5.5]",
             "heading_deg = 180"]
    return "\n".join(text) + "\n"


def viewpoint(distance_m: float, off_axis_deg: float, facing_deg: float, face_center: np.ndarray,
              mount: HeadMount, tilt_limits_deg: tuple[float, float]) -> tuple[Pose2D, float] | None:
    """Where the robot stands, and how far its head tilts, for its (left) camera to see the face's
    centre (its normal +x) at ``distance_m``, about ``facing_deg`` off its normal and
    ``off_axis_deg`` off the optical axis.

    The head tilts toward the centre as far as its limits allow and pans not at all; the heading
    makes up the rest of the angle off the axis. A face above or below the camera is foreshortened
    by the elevation too, so a facing under the elevation comes out at it. None when the face is
    nearer than its height above or below the camera. The view's true geometry is measured after,
    so the aim need only be close."""
    rise = face_center[2] - mount.height_m
    if distance_m <= abs(rise):
        return None
    flat = math.sqrt(distance_m**2 - rise**2)
    elevation = math.atan2(rise, flat)
    azimuth = math.copysign(math.acos(min(1.0, math.cos(math.radians(facing_deg)) / math.cos(elevation))), facing_deg)
    eye = face_center[:2] + flat * np.array([math.cos(azimuth), math.sin(azimuth)])
    tilt_deg = float(np.clip(math.degrees(elevation), *tilt_limits_deg))  # what it cannot reach stays off the axis
    tilt = math.radians(tilt_deg)
    # the angle between the optical axis (tilted) and the ray (at its elevation), ``sideways`` apart in azimuth:
    # cos(off axis) = cos(tilt) cos(elevation) cos(sideways) + sin(tilt) sin(elevation)
    cos_sideways = (math.cos(math.radians(off_axis_deg)) - math.sin(tilt) * math.sin(elevation)) / \
        (math.cos(tilt) * math.cos(elevation))
    sideways = math.copysign(math.acos(min(1.0, cos_sideways)), off_axis_deg)
    heading = wrap_angle(math.atan2(*(face_center[1::-1] - eye[::-1])) - sideways)
    x, y = eye - Pose2D(0.0, 0.0, heading).to_transform().rotation[:2, :2] @ \
        mount.camera_in_robot(0.0, tilt).translation[:2]  # the robot's centre, not the camera's
    return Pose2D(float(x), float(y), heading), tilt_deg


def is_true_hit(detection, face_center: np.ndarray, camera: RigidTransform, intrinsics: Intrinsics,
                face_width_m: float) -> bool:
    """The detection is on the target: its centre within a quarter of the face's size of the truth."""
    truth = intrinsics.project(camera.inverse().apply(face_center[None]))[0]
    depth = np.linalg.norm(face_center - camera.translation)
    tolerance_px = max(12.0, 0.25 * intrinsics.fx_px * face_width_m / depth)
    return bool(np.all(np.isfinite(truth)) and np.linalg.norm(detection.center_px - truth) <= tolerance_px)


def calibrate(robot: RobotClient, detector: Detector, grid: CalibrationGrid, face_center: np.ndarray,
              face_width_m: float, negatives: int,
              progress: Callable[[int, int], None] = lambda done, total: None) -> Tally:
    """One height's views: every cell ``grid.samples`` times, then ``negatives`` views without the target."""
    info = robot.info()
    intrinsics, mount = info.intrinsics.to_intrinsics(), info.mount.to_mount()
    tilt_limits = (info.pantilt.tilt_min_deg, info.pantilt.tilt_max_deg)
    edges = (np.array(grid.distance_edges_m), np.array(grid.off_axis_edges_deg), np.array(grid.facing_edges_deg))
    shape = tuple(len(e) - 1 for e in edges)
    tally = Tally(np.zeros(shape, int), np.zeros(shape, int))
    cells = _cells(grid)
    total = len(cells) * grid.samples + negatives
    done = 0
    for d, o, f in cells:
        for sample in range(grid.samples):
            sign = 1 if sample % 2 == 0 else -1
            done += 1
            progress(done, total)
            aim = viewpoint(d, sign * o, sign * f, face_center, mount, tilt_limits)
            left = None if aim is None else _capture_at(robot, *aim)
            if left is None:
                continue
            camera = mount.camera_in_world(aim[0], 0.0, math.radians(aim[1]))
            index, inside = cell_indices(edges, view_geometry(camera, face_center, np.array([1.0, 0.0, 0.0])))
            if not inside:
                continue
            found = _timed_detect(detector, left, tally)
            tally.views[index] += 1
            if found is not None and is_true_hit(found, face_center, camera, intrinsics, face_width_m):
                tally.hits[index] += 1
            elif found is not None:
                tally.false_positives += 1
    rng = np.random.default_rng(0)
    while tally.negative_views < negatives:
        pose = _looking_away(rng, face_center, intrinsics)
        left = _capture_at(robot, pose, 0.0)
        done += 1
        progress(done, total)
        if left is None:
            continue
        tally.negative_views += 1
        tally.false_positives += _timed_detect(detector, left, tally) is not None
    return tally


def to_table(name: str, grid: CalibrationGrid, tally: Tally) -> DetectabilityTable:
    rate = pooled_rate(tally.hits, tally.views)
    views = tally.negative_views + int(tally.views.sum())
    return DetectabilityTable(name, np.array(grid.distance_edges_m), np.array(grid.off_axis_edges_deg),
                              np.array(grid.facing_edges_deg), rate, tally.views,
                              tally.false_positives / max(views, 1), float(np.median(tally.detect_ms or [0.0])))


def pooled_rate(hits: np.ndarray, views: np.ndarray) -> np.ndarray:
    """Detection rate per cell from its views and its neighbours' (the 3 × 3 × 3 cells around it:
    detection varies smoothly, and one view a cell says little), counting one miss more than seen:
    hits / (views + 1). So no cell claims certainty (which would let one look rule a place out for
    good) and thinly measured cells lean towards "not detected" (the planner then looks again
    rather than trusting a look that may not work). Cells with no view around them get 0."""
    return _box_sum(hits.astype(float)) / (_box_sum(views.astype(float)) + 1.0)


def _box_sum(values: np.ndarray) -> np.ndarray:
    padded = np.pad(values, 1)
    n0, n1, n2 = values.shape
    return sum(padded[i:i + n0, j:j + n1, k:k + n2] for i in range(3) for j in range(3) for k in range(3))


def _cells(grid: CalibrationGrid) -> list[tuple[float, float, float]]:
    """Every cell's centre: distance, angle off the axis, angle off the normal."""
    centres = [(np.array(e[:-1]) + np.array(e[1:])) / 2
               for e in (grid.distance_edges_m, grid.off_axis_edges_deg, grid.facing_edges_deg)]
    return [(float(d), float(o), float(f)) for d in centres[0] for o in centres[1] for f in centres[2]]


def _capture_at(robot: RobotClient, pose: Pose2D, tilt_deg: float) -> np.ndarray | None:
    try:
        robot.sim_teleport(pose.x_m, pose.y_m, math.degrees(pose.heading_rad))
    except CommandError:  # a wall or the stand is in the way: that view cannot be had
        return None
    robot.look(0.0, tilt_deg)
    return robot.capture().left


def _timed_detect(detector: Detector, image: np.ndarray, tally: Tally):
    started = time.perf_counter()
    found = detector.detect(image)
    tally.detect_ms.append((time.perf_counter() - started) * 1000.0)
    return found


def _looking_away(rng: np.random.Generator, face_center: np.ndarray, intrinsics: Intrinsics) -> Pose2D:
    """A random pose whose view cannot contain the target (pointing well away from it)."""
    while True:
        x, y = rng.uniform(0.5, ROOM_M[0] - 0.5), rng.uniform(0.5, ROOM_M[1] - 0.5)
        heading = rng.uniform(-math.pi, math.pi)
        toward = math.atan2(face_center[1] - y, face_center[0] - x)
        if abs(wrap_angle(heading - toward)) > intrinsics.hfov_rad / 2 + math.radians(25):
            return Pose2D(x, y, heading)


def summary(table: DetectabilityTable, tally: Tally) -> dict:
    """The figures the perception issue asks for, from the measured cells."""
    d = (np.array(table.distance_edges_m[:-1]) >= 0.5) & (np.array(table.distance_edges_m[1:]) <= 2.5)
    f = np.array(table.facing_edges_deg[1:]) <= 45.0
    views = tally.views[d][:, :, f].sum()
    hits = tally.hits[d][:, :, f].sum()
    return {"detector": table.detector, "views": int(tally.views.sum()), "negative_views": tally.negative_views,
            "false_detections": tally.false_positives, "false_positive_rate": round(table.false_positive_rate, 5),
            "detection_rate_0_5_to_2_5m_under_45deg": round(float(hits / max(views, 1)), 4),
            "views_0_5_to_2_5m_under_45deg": int(views), "range_m": list(table.range_m),
            "cost_ms": round(table.cost_ms, 2)}

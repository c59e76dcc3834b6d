"""From one capture to what the planner needs: disparity, the occupancy update, the detection.

The capture's pose is the robot's odometry; the caller passes the corrected world pose (from
:mod:`offboard.navigation.localization`), and every world-frame quantity here is placed with it.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field

import numpy as np

from offboard.perception.detection.detector import Detection, Detector, locate_target
from offboard.perception.occupancy import OccupancyGrid
from offboard.perception.stereo import StereoMatcher
from shared.geometry import Intrinsics, Pose2D, RigidTransform
from shared.messages import Capture

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class Observation:
    capture: Capture
    pose: Pose2D  # corrected world pose at exposure
    camera_in_world: RigidTransform  # the left (reference) camera
    intrinsics: Intrinsics
    baseline_m: float
    disparity: np.ndarray  # float32 px, NaN where invalid
    detection: Detection | None = None
    target_m: np.ndarray | None = None  # world position of the detected face's centre
    timings_ms: dict[str, float] = field(default_factory=dict)


class Perception:
    def __init__(self, occupancy: OccupancyGrid, matcher: StereoMatcher):
        self.occupancy = occupancy
        self.matcher = matcher

    def observe(self, capture: Capture, pose: Pose2D, detector: Detector | None = None,
                update_map: bool = True, disparity: np.ndarray | None = None) -> Observation:
        """Stereo (unless the capture's ``disparity`` is given), then the occupancy update (eq. 5-8),
        then the detector if one is given."""
        timings: dict[str, float] = {}
        intrinsics = capture.intrinsics.to_intrinsics()
        mount = capture.mount.to_mount()
        camera = mount.camera_in_world(pose, math.radians(capture.pan_deg), math.radians(capture.tilt_deg))
        if disparity is None:
            started = time.perf_counter()
            disparity = self.matcher.disparity(capture.left, capture.right)
            timings["stereo_ms"] = _since(started)
        if update_map:
            started = time.perf_counter()
            self.occupancy.integrate_disparity(disparity, intrinsics, mount.baseline_m, camera)
            timings["occupancy_ms"] = _since(started)
        detection = target = None
        if detector is not None:
            started = time.perf_counter()
            detection = detector.detect(capture.left)
            timings["detection_ms"] = _since(started)
            if detection is not None:
                target = locate_target(detection, disparity, intrinsics, mount.baseline_m, camera)
                log.info("%s detection (score %.2f, %s) at %s", detection.detector, detection.score,
                         "confident" if detection.confident else "weak",
                         "unknown depth" if target is None else np.round(target, 2))
        return Observation(capture, pose, camera, intrinsics, mount.baseline_m, disparity, detection, target, timings)


def _since(started: float) -> float:
    return (time.perf_counter() - started) * 1000.0

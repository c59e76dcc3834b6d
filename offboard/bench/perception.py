"""``syt-offboard bench perception --json``: stereo, the occupancy update and both detectors, as medians,
plus the Middlebury motorcycle figures of the stereo.

Images: the stereo runs on a real 640 × 480 pair (a crop of Middlebury's motorcycle, which
scikit-image ships); the occupancy update folds that pair's disparity into the report's 5 cm grid
of a 9 × 5 × 2.5 m room; the detectors run on a 640 × 480 textured image holding the target
(a crop of scikit-image's ``chelsea``), as :func:`offboard.perception.detection.detector.timing_image` makes it.
"""

from __future__ import annotations

import logging

import numpy as np
from skimage.data import chelsea

from offboard.perception.detection.detector import make_detector, timing_image
from offboard.perception.detection.target_model import TargetModel
from offboard.perception.middlebury import evaluate_motorcycle
from offboard.perception.occupancy import OccupancyGrid
from offboard.perception.stereo import StereoMatcher, bench_pair
from offboard.perception.voxel_grid import VoxelGrid
from shared.timing import median_ms
from shared.geometry import HeadMount, Intrinsics, Pose2D

log = logging.getLogger(__name__)

K = Intrinsics.from_fov(640, 480, 66.0)
MOUNT = HeadMount()


def run(repeats: int = 20) -> dict:
    left, right = bench_pair()
    matcher = StereoMatcher()
    figures: dict[str, float] = {"stereo_ms": median_ms(lambda: matcher.disparity(left, right), repeats)}
    disparity = matcher.disparity(left, right)
    occupancy = OccupancyGrid(VoxelGrid((9.0, 5.0, 2.5), 0.05))
    camera = MOUNT.camera_in_world(Pose2D(1.0, 2.5, 0.0), 0.0, 0.0)
    figures["occupancy_update_ms"] = median_ms(
        lambda: occupancy.integrate_disparity(disparity, K, MOUNT.baseline_m, camera), repeats)
    model = TargetModel((np.ascontiguousarray(chelsea()[20:280, 110:370]),), (0.23, 0.23, 0.23))
    image = timing_image(model, K)
    for name in ("sift", "ncc"):
        detector = make_detector(name, model, K)
        figures[f"{name}_ms"] = median_ms(lambda: detector.detect(image), repeats)
    log.info("the Middlebury motorcycle pair")
    motorcycle = evaluate_motorcycle()
    figures["motorcycle_bad2"] = round(motorcycle["motorcycle_bad2"], 4)
    figures["motorcycle_density"] = round(motorcycle["motorcycle_density"], 4)
    figures["stereo_plus_occupancy_ms"] = round(figures["stereo_ms"] + figures["occupancy_update_ms"], 2)
    return figures

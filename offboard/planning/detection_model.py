"""What a detection says about where the target is: a Bayesian observation, not a certainty.

For a look with detection function b(c, f) over its cubes (its footprint), the detector either
stays silent or fires at some place x. Its false-positive rate α is measured (the detectability
table's negatives), and a false detection is taken to be equally likely anywhere in the view
(density u = 1 / cubes in view). Then, relative to "the target is elsewhere or outside" (which
explains a detection only as a false one, α·u), the likelihood of a detection at x is

    for a cube c in the footprint, facing k:  (1 − b(c, k)) + b(c, k) · g(x | c) / (α · u)
    for every other cube, and c_out:          1

where g is where the detection would place a target at c: a Gaussian of the stereo depth's
uncertainty around the located centre, or — when the detected face has no stereo depth — an
equal share of the cubes whose centre projects inside the detected box (the target lies somewhere
along those rays). A miss is the same rule with the second term gone: eq. 4 exactly.

A target in the footprint but far from x "should have been detected there", so it loses mass
(1 − b), as after a miss: a false detection is recoverable, and a weak detector (larger α)
concentrates the belief less.
"""

from __future__ import annotations

import numpy as np

from offboard.perception.voxel_grid import VoxelGrid
from shared.geometry import Intrinsics, RigidTransform


def detection_likelihood(cube_index: np.ndarray, detection_prob: np.ndarray, located: np.ndarray,
                         false_positive_rate: float) -> np.ndarray:
    """Likelihood ratios (n, facing_sectors) of a detection for the footprint's cubes.

    ``located`` (n,): g(x | c) for each footprint cube, summing to 1 over them (where the detection
    puts the target); ``false_positive_rate``: α, > 0.
    """
    b = np.asarray(detection_prob, np.float64)
    if false_positive_rate <= 0:
        raise ValueError("the false-positive rate must be positive: no detector is infallible")
    false_density = false_positive_rate / max(len(cube_index), 1)  # α · u
    return (1.0 - b) + b * (np.asarray(located, np.float64)[:, None] / false_density)


def located_at_point(grid: VoxelGrid, cube_index: np.ndarray, target_m: np.ndarray, sigma_m: float) -> np.ndarray:
    """g(x | c) for a detection located at ``target_m`` (the target's centre) with depth
    uncertainty ``sigma_m``: a Gaussian over the footprint's cubes, normalised over them."""
    centers = grid.center_of(np.stack(np.unravel_index(cube_index, grid.shape), axis=-1))
    d2 = np.sum((centers - np.asarray(target_m)) ** 2, axis=1) / sigma_m**2
    return _normalised(np.where(d2 <= 9.0, np.exp(-0.5 * d2), 0.0))  # nothing within 3 σ: explains nothing


def located_along_rays(grid: VoxelGrid, cube_index: np.ndarray, box_px: tuple[float, float, float, float],
                       camera_in_world: RigidTransform, intrinsics: Intrinsics) -> np.ndarray:
    """g(x | c) for a detection without depth: equal over the footprint cubes whose centre projects
    inside the detected box (its bounding box in the left image)."""
    centers = grid.center_of(np.stack(np.unravel_index(cube_index, grid.shape), axis=-1))
    local = (centers - camera_in_world.translation) @ camera_in_world.rotation  # R^T (c - t)
    z = np.maximum(local[:, 2], 1e-9)
    u = intrinsics.fx_px * local[:, 0] / z + intrinsics.cx_px
    v = intrinsics.fy_px * local[:, 1] / z + intrinsics.cy_px
    x0, y0, x1, y1 = box_px
    inside = (local[:, 2] > 0) & (u >= x0) & (u <= x1) & (v >= y0) & (v <= y1)
    return _normalised(inside.astype(np.float64))


DISPARITY_SIGMA_PX = 0.5  # the matcher's sub-pixel disparity error


def depth_sigma_m(distance_m: float, intrinsics: Intrinsics, baseline_m: float, base_sigma_m: float) -> float:
    """How far the located centre may be off: a floor of ``base_sigma_m`` (the face-to-centre
    offset, the face's size), growing with the square of the distance as stereo depth does."""
    return float(np.hypot(base_sigma_m, distance_m**2 * DISPARITY_SIGMA_PX / (intrinsics.fx_px * baseline_m)))


def _normalised(weight: np.ndarray) -> np.ndarray:
    total = weight.sum()
    return weight / total if total > 0 else weight

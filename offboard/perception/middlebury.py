"""The stereo check on data nobody here made: Middlebury 2014 "motorcycle" with ground truth.

scikit-image ships the pair downsampled 4x (741 x 500) with its ground-truth disparity; pixels
without ground truth are non-finite (``inf`` in the shipped file, NaN per its docstring). Scores
follow the Middlebury convention: *bad2* is the fraction of our valid pixels, among those with
ground truth, that are more than 2 px off; *density* is the fraction of ground-truth pixels where
we give a disparity at all. The plain OpenCV block matcher is scored the same way as a baseline.
"""

from __future__ import annotations

import dataclasses
import functools

import cv2
import numpy as np

from offboard.perception.stereo import StereoConfig, StereoMatcher

# The pair's largest true disparity is 59.9 px: 64 covers it; the room default (128) would only
# search impossible disparities and blind 128 more columns of the OpenCV baseline.
MOTORCYCLE_NUM_DISPARITIES = 64
BAD_THRESHOLD_PX = 2.0


@functools.lru_cache(maxsize=1)
def motorcycle() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(left RGB, right RGB, ground-truth disparity with NaN where unknown), read-only arrays."""
    from skimage.data import stereo_motorcycle

    left, right, truth = stereo_motorcycle()
    truth = np.where(np.isfinite(truth), truth, np.nan).astype(np.float32)
    for array in (left, right, truth):
        array.setflags(write=False)
    return left, right, truth


def answered_errors(disparity: np.ndarray, truth: np.ndarray) -> tuple[int, np.ndarray, np.ndarray]:
    """A disparity map (NaN = no answer) against the truth (NaN or inf = unknown): how many pixels
    have a known truth, the mask of those the map answered, and its errors there (map − truth)."""
    known = np.isfinite(truth)
    answered = known & np.isfinite(disparity)
    return int(known.sum()), answered, disparity[answered] - truth[answered]


def bad2_and_density(bad: int, answered: int, known: int) -> tuple[float, float]:
    """The share of answered pixels off by more than ``BAD_THRESHOLD_PX``, and the share of known ones
    answered; (1, 0) when nothing is answered: a blind matcher scores no better than a wrong one."""
    return (1.0, 0.0) if answered == 0 else (bad / answered, answered / known)


def score(disparity: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """(bad2, density) of one disparity map against its ground truth."""
    known, answered, error = answered_errors(disparity, truth)
    return bad2_and_density(int((np.abs(error) > BAD_THRESHOLD_PX).sum()), int(answered.sum()), known)


def evaluate_motorcycle(config: StereoConfig | None = None) -> dict:
    """Score ``StereoMatcher`` on the pair; without a config, the default with 64 disparities."""
    if config is None:
        config = dataclasses.replace(StereoConfig(), num_disparities=MOTORCYCLE_NUM_DISPARITIES)
    left, right, truth = motorcycle()
    bad2, density = score(StereoMatcher(config).disparity(left, right), truth)
    return {"motorcycle_bad2": bad2, "motorcycle_density": density,
            "num_disparities": config.num_disparities, "block_size": config.block_size,
            "method": config.method}


def evaluate_plain_block_matching(block_size: int = 21) -> dict:
    """The baseline: OpenCV ``StereoBM`` with its default settings (21 px window), no checks of ours."""
    left, right, truth = motorcycle()
    grey = [cv2.cvtColor(image, cv2.COLOR_RGB2GRAY) for image in (left, right)]
    fixed = cv2.StereoBM.create(MOTORCYCLE_NUM_DISPARITIES, block_size).compute(*grey)
    disparity = np.where(fixed >= 0, fixed / 16.0, np.nan)  # fixed point with 4 fractional bits
    bad2, density = score(disparity, truth)
    return {"motorcycle_bad2": bad2, "motorcycle_density": density,
            "num_disparities": MOTORCYCLE_NUM_DISPARITIES, "block_size": block_size,
            "method": "opencv-bm"}

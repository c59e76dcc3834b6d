"""Stereo matching on real and synthetic pairs with known disparity, and disparity -> 3D points."""

from __future__ import annotations

import math
from dataclasses import replace

import cv2
import numpy as np
import pytest
import skimage.data

from offboard.perception.middlebury import evaluate_motorcycle, evaluate_plain_block_matching
from offboard.perception.stereo import (StereoConfig, StereoMatcher, depth_from_disparity,
                             points_from_disparity)
from shared.geometry import Intrinsics

H, W = 240, 320
SMALL = StereoConfig(num_disparities=64)  # the synthetic pairs stay below 64 px
BACKGROUND_D, FOREGROUND_D = 12, 40
ROWS, COLS = slice(60, 180), slice(160, 260)  # the foreground rectangle in the left image


def _texture(name: str, width: int) -> np.ndarray:
    """(H, width) grey photograph, tiled so it is wide enough for any shift."""
    image = getattr(skimage.data, name)()
    return np.tile(image, (1, -(-width // image.shape[1])))[:H, :width]


def _shifted(texture: np.ndarray, d_px: float) -> np.ndarray:
    """The right view of a fronto-parallel plane at disparity d: right(u) = left(u + d)."""
    map_x = np.tile(np.arange(W, dtype=np.float32) + np.float32(d_px), (H, 1))
    map_y = np.tile(np.arange(H, dtype=np.float32)[:, None], (1, W))
    return cv2.remap(texture, map_x, map_y, cv2.INTER_CUBIC)


def _two_planes() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A gravel background at 12 px and a brick rectangle in front at 40 px: (left, right, truth)."""
    back = _texture("gravel", W + BACKGROUND_D)
    front = _texture("brick", W + FOREGROUND_D)
    left = back[:, :W].copy()
    left[ROWS, COLS] = front[ROWS, COLS]
    right = back[:, BACKGROUND_D:BACKGROUND_D + W].copy()
    shifted = slice(COLS.start - FOREGROUND_D, COLS.stop - FOREGROUND_D)
    right[ROWS, shifted] = front[ROWS, COLS]
    truth = np.full((H, W), BACKGROUND_D, np.float32)
    truth[ROWS, COLS] = FOREGROUND_D
    return left, right, truth


def _occluded_strip() -> tuple[slice, slice]:
    """Background left of the rectangle that the rectangle hides from the right camera."""
    return ROWS, slice(COLS.start - (FOREGROUND_D - BACKGROUND_D), COLS.start)


# ------------------------------------------------------------------------------ Middlebury


def test_motorcycle_meets_the_target_and_beats_plain_block_matching():
    ours = evaluate_motorcycle()
    plain = evaluate_plain_block_matching()
    assert ours["motorcycle_bad2"] <= 0.05
    assert ours["motorcycle_density"] >= 0.70
    assert ours["num_disparities"] == 64
    assert plain["motorcycle_bad2"] > ours["motorcycle_bad2"]


def test_sad_mode_gives_a_sane_result_on_the_motorcycle():
    result = evaluate_motorcycle(StereoConfig(method="sad", num_disparities=64, block_size=9))
    assert result["method"] == "sad"
    assert result["motorcycle_bad2"] <= 0.05
    assert result["motorcycle_density"] >= 0.70


# ------------------------------------------------------------------------- synthetic pairs


@pytest.mark.parametrize("d_px", [7.0, 23.5, 41.25])
def test_fronto_parallel_plane_gives_its_disparity(d_px):
    left = _texture("gravel", W + 64)
    disparity = StereoMatcher(SMALL).disparity(left[:, :W].copy(), _shifted(left, d_px))
    valid = np.isfinite(disparity)
    assert valid[:, 70:].mean() > 0.9  # everything but the left strip that has no match
    assert np.median(np.abs(disparity[valid] - d_px)) <= 0.5


def test_default_config_on_a_full_size_rgb_pair():
    texture = np.dstack([_texture("gravel", 700)] * 3)
    left = cv2.resize(texture[:, :640], (640, 480))
    right = cv2.resize(texture[:, 30:670], (640, 480))  # 30 px to the left
    disparity = StereoMatcher().disparity(left, right)
    assert disparity.shape == (480, 640) and disparity.dtype == np.float32
    assert np.isfinite(disparity).mean() > 0.85
    assert np.nanmedian(np.abs(disparity - 30.0)) <= 0.5


def test_two_planes_are_recovered():
    left, right, truth = _two_planes()
    disparity = StereoMatcher(SMALL).disparity(left, right)
    for d_px in (BACKGROUND_D, FOREGROUND_D):
        plane = truth == d_px
        valid = plane & np.isfinite(disparity)
        # Texture validation over SGBM's 5 px window drops the smooth insides of the bricks.
        assert valid.sum() > 0.6 * plane.sum()
        assert np.median(np.abs(disparity[valid] - d_px)) <= 0.5


def test_occluded_strip_fails_the_left_right_check():
    left, right, _ = _two_planes()
    strip = _occluded_strip()
    assert np.isnan(StereoMatcher(SMALL).disparity(left, right)[strip]).mean() > 0.9
    # SAD with uniqueness and speckle filtering off: only the left-right check can reject the strip.
    bare = StereoConfig(method="sad", block_size=9, num_disparities=64, uniqueness_ratio=0,
                        speckle_window_px=0)
    checked = StereoMatcher(bare).disparity(left, right)[strip]
    unchecked = StereoMatcher(replace(bare, lr_max_diff_px=math.inf)).disparity(left, right)[strip]
    assert np.isnan(checked).mean() > 0.9
    assert np.isnan(unchecked).mean() < 0.1  # without the check the matcher invents disparities


def test_untextured_region_is_invalid():
    left = _texture("gravel", W + 64)
    right = _shifted(left, 20.0)
    left = left[:, :W].copy()
    left[80:160, 120:220] = 128
    right[80:160, 100:200] = 128  # the same flat patch on the plane at 20 px
    disparity = StereoMatcher(SMALL).disparity(left, right)
    half = SMALL.block_size // 2  # windows reaching into the texture may still match
    assert np.isnan(disparity[80 + half:160 - half, 120 + half:220 - half]).all()
    assert np.isfinite(disparity[:, 240:]).mean() > 0.9


def test_sad_recovers_two_planes():
    left, right, truth = _two_planes()
    disparity = StereoMatcher(StereoConfig(method="sad", num_disparities=64, block_size=9)).disparity(
        left, right)
    valid = np.isfinite(disparity)
    assert valid.mean() > 0.7
    assert np.median(np.abs(disparity[valid] - truth[valid])) <= 0.5


def test_bad_inputs_are_refused():
    with pytest.raises(ValueError, match="multiple of 16"):
        StereoConfig(num_disparities=100)
    with pytest.raises(ValueError, match="block_size must be odd"):
        StereoConfig(block_size=8)
    matcher = StereoMatcher(SMALL)
    with pytest.raises(ValueError, match="differ in size"):
        matcher.disparity(np.zeros((H, W), np.uint8), np.zeros((H, W + 1), np.uint8))
    with pytest.raises(ValueError, match="must be uint8"):
        matcher.disparity(np.zeros((H, W), np.float32), np.zeros((H, W), np.float32))
    with pytest.raises(ValueError, match="empty"):
        matcher.disparity(np.zeros((0, 0), np.uint8), np.zeros((0, 0), np.uint8))


@pytest.mark.parametrize(("name", "value"), [("texture_threshold", float("nan")), ("lr_max_diff_px", float("nan")),
                                             ("speckle_range_px", float("nan")), ("speckle_range_px", float("inf")),
                                             ("texture_threshold", -1.0)])
def test_a_threshold_that_would_switch_a_check_off_unsaid_is_refused_by_name(name, value):
    """NaN compares false with everything: a NaN texture threshold or left-right tolerance passed
    every pixel, silently. Only the left-right tolerance may be inf, which is how it is switched off."""
    with pytest.raises(ValueError, match=name):
        StereoConfig(**{name: value})
    assert StereoConfig(lr_max_diff_px=float("inf")).lr_max_diff_px == float("inf")


# --------------------------------------------------------------------- disparity to points

K = Intrinsics(640, 480, 500.0, 500.0, 320.0, 240.0)
BASELINE_M = 0.1


def test_known_disparity_gives_the_known_point():
    disparity = np.full((480, 640), np.nan, np.float32)
    disparity[100, 400] = 25.0  # z = 500 * 0.1 / 25 = 2 m
    points = points_from_disparity(disparity, K, BASELINE_M)
    assert len(points) == 1
    assert (points.u_px[0], points.v_px[0], points.d_px[0]) == (400.0, 100.0, 25.0)
    np.testing.assert_allclose(points.xyz_cam_m[0], [0.32, -0.56, 2.0], rtol=1e-6)
    assert points.xyz_cam_m.dtype == np.float32 and points.xyz_cam_m.shape == (1, 3)


def test_points_reproject_onto_their_pixels():
    disparity = np.random.default_rng(1).uniform(10.0, 60.0, (480, 640)).astype(np.float32)
    points = points_from_disparity(disparity, K, BASELINE_M, stride_px=7)
    pixels = K.project(points.xyz_cam_m.astype(np.float64))
    np.testing.assert_allclose(pixels, np.stack([points.u_px, points.v_px], axis=1), atol=1e-3)


def test_stride_subsamples_the_grid():
    disparity = np.full((480, 640), 10.0, np.float32)
    points = points_from_disparity(disparity, K, BASELINE_M, stride_px=4)
    assert len(points) == 120 * 160
    assert set(np.unique(points.u_px)) == set(range(0, 640, 4))
    assert set(np.unique(points.v_px)) == set(range(0, 480, 4))
    np.testing.assert_allclose(points.xyz_cam_m[:, 2], 5.0)


def test_depth_range_and_invalid_pixels_are_dropped():
    disparity = np.array([[500.0, 5.0, 25.0, np.nan, 0.0, -3.0]], np.float32)  # z: 0.1, 10, 2, ...
    points = points_from_disparity(disparity, K, BASELINE_M)
    np.testing.assert_array_equal(points.d_px, [25.0])
    wide = points_from_disparity(disparity, K, BASELINE_M, min_depth_m=0.05, max_depth_m=20.0)
    np.testing.assert_array_equal(wide.d_px, [500.0, 5.0, 25.0])


def test_depth_from_disparity_keeps_nan():
    depth = depth_from_disparity(np.array([25.0, np.nan, 0.0], np.float32), K, BASELINE_M)
    np.testing.assert_allclose(depth[0], 2.0)
    assert np.isnan(depth[1:]).all()

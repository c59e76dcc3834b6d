"""Dense stereo on the head's rectified pair: disparity in the left image, then 3D points.

The default matcher is semi-global matching (OpenCV's ``StereoSGBM``, Hirschmüller 2008: a block
cost aggregated along three directions with penalties on disparity changes).
Sum-of-Absolute-Differences block matching, which the original robot's Triclops used (``StereoBM``:
x-Sobel prefilter, SAD over a square window, uniqueness test), is selectable with ``method =
"sad"``. SAD is about 3 times faster (``stereo_ms`` of ``bench perception``: 30 against 89 ms a
640x480 pair with the checks below, on a 2-core cloud VM) but decides each window alone, and on a
regular pattern seen square-on (a tiled or brick wall) it can lock onto the match one period over.
That is a consistent wrong disparity, far too large, and it survives every check below: a phantom
wall in front of the camera at B / (B + T) of the true depth (baseline B, pattern period T on the
wall), which can close the robot in. SGBM's smoothness penalties pull many such windows to their
neighbours' true disparity. On 900 rendered views of the ``dev`` worlds (``syt-onboard worlds views
--worlds dev --per-world 25``, seeds 0, 1 and 2; ``syt-offboard bench stereo``), SGBM put half as
many pixels too near (0.04-0.07 % of its answers against 0.07-0.13 %) and had phantoms over more
than 2 % of the image in 5 views against SAD's 9. It answers 91 % of the pixels against 86-87 %, but
smooths more across edges: 0.18-0.22 % of its answers are over 2 px off, against 0.11-0.17 %. Both
go through the same validation, which is ours rather than OpenCV's:

- **left-right consistency**: the pair is matched a second time with both images mirrored and
  swapped, which gives the disparity of every *right* pixel; a left pixel survives only if the
  right pixel it lands on points back to it. This removes occlusions and most mismatches, and
  doubles the matching time (see `syt-offboard bench perception` for the figures).
- **texture validation**: windows whose grey-level standard deviation is below a threshold carry
  no signal to match (Triclops' texture validation), so their disparity is dropped.
- **speckle filtering**: small connected islands of disparity (what the checks above leave of a
  mismatch) are dropped.

Both images are padded on the left before matching, because the OpenCV matchers give nothing for
the first ``num_disparities`` columns; without padding a fifth of a 640-px image would be blind.
Disparities are kept in OpenCV's 1/16 px fixed point until the end, which makes every check an
integer array operation. Invalid pixels come out as NaN.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Literal

import cv2
import numpy as np

from offboard.perception.detection.detector import to_grey
from shared.geometry import Intrinsics

log = logging.getLogger("syt.offboard.perception.stereo")

_SUBPIXEL = 16  # OpenCV matchers return disparity * 16 (4 fractional bits)
_INVALID = -_SUBPIXEL  # OpenCV's "no disparity" for minDisparity 0; valid disparities are >= 0


@dataclass(frozen=True)
class StereoConfig:
    """How to match a rectified pair. The defaults suit 640x480 Bumblebee-like pairs of a room."""

    method: Literal["sad", "sgbm"] = "sgbm"  # semi-global, or SAD block matching as on the robot
    num_disparities: int = 128  # search range in px, multiple of 16; f·B/128 = 0.46 m at f 493, B 0.12
    block_size: int = 5  # odd side of the square matching window, px (9 suits sad better)
    texture_threshold: float = 1.0  # min grey-level std (0-255 scale) in the window, else invalid
    uniqueness_ratio: int = 15  # % by which the best cost must beat every non-adjacent disparity
    lr_max_diff_px: float = 1.0  # max |d_left - d_right| for a consistent match; inf disables it
    speckle_window_px: int = 200  # connected regions with fewer pixels than this are dropped
    speckle_range_px: float = 2.0  # max disparity step between neighbours of one region, px
    prefilter_cap: int = 31  # clip of the x-Sobel prefilter: limits the weight of strong edges
    sgbm_penalty_small: int = 8  # SGBM P1 per window pixel: cost of a ±1 px disparity change
    sgbm_penalty_large: int = 32  # SGBM P2 per window pixel: cost of a larger disparity jump

    def __post_init__(self) -> None:
        if self.method not in ("sad", "sgbm"):
            raise ValueError(f"method must be 'sad' or 'sgbm', not {self.method!r}")
        if self.num_disparities <= 0 or self.num_disparities % 16:
            raise ValueError(f"num_disparities must be a positive multiple of 16, not {self.num_disparities}")
        if self.block_size % 2 == 0 or not 5 <= self.block_size <= 255:
            raise ValueError(f"block_size must be odd and in [5, 255], not {self.block_size}")
        if not 1 <= self.prefilter_cap <= 63:
            raise ValueError(f"prefilter_cap must be in [1, 63], not {self.prefilter_cap}")
        thresholds = {"texture_threshold": self.texture_threshold, "uniqueness_ratio": self.uniqueness_ratio,
                      "lr_max_diff_px": self.lr_max_diff_px, "speckle_window_px": self.speckle_window_px,
                      "speckle_range_px": self.speckle_range_px}
        for name, value in thresholds.items():  # NaN fails ">= 0": it would switch a check off unsaid
            if not value >= 0 or (math.isinf(value) and name != "lr_max_diff_px"):
                raise ValueError(f"{name} must be a number of at least 0 (inf only for lr_max_diff_px), not {value}")


class StereoMatcher:
    """Rectified pair -> validated float disparity of the left image."""

    def __init__(self, config: StereoConfig = StereoConfig()) -> None:
        self.config = config
        self._matcher = _create_matcher(config)  # reused for both views: same parameters

    def disparity(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """Rectified RGB (H,W,3 uint8) or grey pair -> float32 disparity in pixels (H,W) in the LEFT
        image; NaN where invalid (no texture, failed left-right check, occluded, speckle)."""
        grey_left, grey_right = to_grey(left), to_grey(right)
        if grey_left.shape != grey_right.shape:
            raise ValueError(f"left {grey_left.shape} and right {grey_right.shape} differ in size")
        if grey_left.size == 0:
            raise ValueError(f"the stereo pair is empty ({grey_left.shape})")
        cfg = self.config
        fixed = self._match(grey_left, grey_right)
        if math.isfinite(cfg.lr_max_diff_px):
            # Mirroring both images and swapping them turns the right view into a left view.
            mirrored = self._match(cv2.flip(grey_right, 1), cv2.flip(grey_left, 1))
            fixed = _left_right_check(fixed, cv2.flip(mirrored, 1), cfg.lr_max_diff_px)
        fixed[_flat(grey_left, cfg.block_size, cfg.texture_threshold)] = _INVALID
        if cfg.speckle_window_px > 0:
            cv2.filterSpeckles(fixed, _INVALID, cfg.speckle_window_px,
                               round(cfg.speckle_range_px * _SUBPIXEL))
        return _to_pixels(fixed)

    def _match(self, left: np.ndarray, right: np.ndarray) -> np.ndarray:
        """Fixed-point disparity (int16, _INVALID where none) over the whole width."""
        pad = self.config.num_disparities  # the matchers skip this many columns on the left
        padded = [cv2.copyMakeBorder(im, 0, 0, pad, 0, cv2.BORDER_REPLICATE) for im in (left, right)]
        return np.ascontiguousarray(self._matcher.compute(*padded)[:, pad:], dtype=np.int16)


def _create_matcher(cfg: StereoConfig) -> cv2.StereoMatcher:
    # OpenCV's own speckle filter and left-right test stay off: ours run once, after all checks.
    if cfg.method == "sad":
        bm = cv2.StereoBM.create(cfg.num_disparities, cfg.block_size)
        bm.setPreFilterCap(cfg.prefilter_cap)
        bm.setTextureThreshold(0)  # texture validation is ours (_flat), in grey levels
        bm.setUniquenessRatio(cfg.uniqueness_ratio)
        bm.setSpeckleWindowSize(0)
        bm.setDisp12MaxDiff(-1)
        return bm
    area = cfg.block_size * cfg.block_size
    return cv2.StereoSGBM.create(
        minDisparity=0, numDisparities=cfg.num_disparities, blockSize=cfg.block_size,
        P1=cfg.sgbm_penalty_small * area, P2=cfg.sgbm_penalty_large * area, disp12MaxDiff=-1,
        preFilterCap=cfg.prefilter_cap, uniquenessRatio=cfg.uniqueness_ratio,
        speckleWindowSize=0, mode=cv2.StereoSGBM_MODE_SGBM_3WAY)


def _left_right_check(left_fx: np.ndarray, right_fx: np.ndarray, max_diff_px: float) -> np.ndarray:
    """Keep left disparities whose right pixel (u - d) carries the same disparity within tolerance."""
    h, w = left_fx.shape
    left32 = left_fx.astype(np.int32)
    columns = np.arange(w, dtype=np.int32) - (left32 + _SUBPIXEL // 2) // _SUBPIXEL  # rounded u - d
    rows = np.arange(h, dtype=np.int32)[:, None] * w
    back = right_fx.ravel()[rows + np.clip(columns, 0, w - 1)].astype(np.int32)
    consistent = ((left32 >= 0) & (columns >= 0) & (back >= 0)
                  & (np.abs(left32 - back) <= max_diff_px * _SUBPIXEL))
    return np.where(consistent, left_fx, np.int16(_INVALID))


def _flat(grey: np.ndarray, block_size: int, min_std: float) -> np.ndarray:
    """Pixels whose matching window has a grey-level standard deviation below ``min_std``."""
    window = (block_size, block_size)
    mean = cv2.boxFilter(grey, cv2.CV_32F, window)
    mean_sq = cv2.sqrBoxFilter(grey, cv2.CV_32F, window)
    return mean_sq - mean * mean < min_std * min_std


def _to_pixels(fixed: np.ndarray) -> np.ndarray:
    disparity = fixed.astype(np.float32) * np.float32(1.0 / _SUBPIXEL)
    disparity[fixed < 0] = np.nan
    return disparity


# ------------------------------------------------------------------------- disparity to 3D


@dataclass(frozen=True)
class StereoPoints:
    """Valid pixels of a disparity map and the 3D points they see."""

    u_px: np.ndarray  # (N,) float32 column of each kept pixel
    v_px: np.ndarray  # (N,) float32 row
    d_px: np.ndarray  # (N,) float32 disparity
    xyz_cam_m: np.ndarray  # (N, 3) float32 in the left optical frame (x right, y down, z forward)

    def __len__(self) -> int:
        return int(self.d_px.shape[0])


def depth_from_disparity(disparity: np.ndarray, intrinsics: Intrinsics, baseline_m: float) -> np.ndarray:
    """z = fx·B/d in metres (float32); NaN stays NaN and so does d <= 0 (no finite depth)."""
    d = np.asarray(disparity, dtype=np.float32)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(d > 0, np.float32(intrinsics.fx_px * baseline_m) / d, np.float32(np.nan))


def points_from_disparity(disparity: np.ndarray, intrinsics: Intrinsics, baseline_m: float, *,
                          stride_px: int = 1, min_depth_m: float = 0.2,
                          max_depth_m: float = 8.0) -> StereoPoints:
    """Back-project every ``stride_px``-th pixel (rows and columns) with a depth in range."""
    if stride_px < 1:
        raise ValueError(f"stride_px must be >= 1, not {stride_px}")
    sub = np.asarray(disparity, dtype=np.float32)[::stride_px, ::stride_px]
    z = depth_from_disparity(sub, intrinsics, baseline_m)
    with np.errstate(invalid="ignore"):
        rows, cols = np.nonzero((z >= min_depth_m) & (z <= max_depth_m))  # NaN compares False
    z = z[rows, cols]
    u = (cols * stride_px).astype(np.float32)
    v = (rows * stride_px).astype(np.float32)
    return StereoPoints(u, v, sub[rows, cols], intrinsics.back_project(u, v, z).astype(np.float32))


# ------------------------------------------------------------------------------ benchmark


def bench_pair() -> tuple[np.ndarray, np.ndarray]:
    """A real 640x480 RGB pair: the central crop of Middlebury's motorcycle (same columns in both)."""
    from skimage.data import stereo_motorcycle

    left, right, _ = stereo_motorcycle()
    rows, cols = slice(10, 490), slice(50, 690)
    return np.ascontiguousarray(left[rows, cols]), np.ascontiguousarray(right[rows, cols])


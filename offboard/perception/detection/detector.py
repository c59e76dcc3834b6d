"""What every target detector promises, the result it returns, and what is shared between them.

- :class:`Detection`: where the target's pictured face was found in the left image.
- :class:`Detector`: the protocol (``detect``, ``name``, measured ``cost_ms``, ``range_m``).
- :func:`make_detector`: the one registry of detectors by name; :func:`shipped_table`: the
  detectability table measured for each on the bundled target (``tables/``).
- :func:`locate_target`: the face's 3D centre from the detection and the stereo disparity.
- :func:`operating_range` and :class:`CostMeter`: the range and cost figures the detectors report.

Corner order everywhere is that of the simulator's ``picture_corners_m``: top-left, top-right,
bottom-right, bottom-left of the picture as a viewer facing it sees them. Image coordinates are
those of ``Intrinsics.project``: pixel centres at integers, so a face's outer edge lies on half pixels.
"""

from __future__ import annotations

import functools
import importlib
import math
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Protocol, runtime_checkable

import cv2
import numpy as np

from offboard.perception.detectability import DetectabilityTable
from offboard.perception.detection.target_model import TargetModel
from shared.geometry import Intrinsics, RigidTransform

# the share of the detected quadrilateral, about its centre, whose disparities place the face
CORE_FRACTION = 0.5
# a face no larger in the image than this share of it, in both directions (the near end of the range)
MAX_FILL = 0.9

# name -> "module:class"; imported on demand so that the detector modules can import this one.
_REGISTRY = {
    "sift": "offboard.perception.detection.sift:SiftDetector",
    "ncc": "offboard.perception.detection.ncc:NccDetector",
}


@dataclass(frozen=True, eq=False)  # eq=False: corners_px is an array
class Detection:
    """The target's pictured face found in a left image."""

    detector: str  # "sift" | "ncc"
    box_px: tuple[float, float, float, float]  # x_min, y_min, x_max, y_max; may pass the border
    corners_px: np.ndarray  # (4, 2) projected picture corners, order as in the module docstring
    score: float  # SIFT: RANSAC inliers; NCC: peak correlation
    confident: bool  # strong enough to count as found without a confirming look

    @classmethod
    def from_corners(cls, detector: str, corners_px: np.ndarray, score: float, confident: bool) -> Detection:
        corners = np.asarray(corners_px, dtype=np.float64).reshape(4, 2)
        lo, hi = corners.min(axis=0), corners.max(axis=0)
        box = (float(lo[0]), float(lo[1]), float(hi[0]), float(hi[1]))
        return cls(detector, box, corners, float(score), bool(confident))

    @property
    def center_px(self) -> np.ndarray:
        """Image (2,) of the face's centre: where the quadrilateral's diagonals cross (a homography
        maps the centre of a rectangle there, unlike the mean of the corners)."""
        p0, p1, p2, p3 = self.corners_px
        d1, d2 = p2 - p0, p3 - p1
        denom = d1[0] * d2[1] - d1[1] * d2[0]
        if abs(denom) < 1e-9:  # degenerate quadrilateral: fall back to the mean
            return self.corners_px.mean(axis=0)
        t = ((p1[0] - p0[0]) * d2[1] - (p1[1] - p0[1]) * d2[0]) / denom
        return p0 + t * d1


@runtime_checkable
class Detector(Protocol):
    name: str

    def detect(self, left_rgb: np.ndarray) -> Detection | None:
        """The target in a rectified left image (H, W, 3) uint8 RGB, or None."""
        ...

    @property
    def cost_ms(self) -> float:
        """Median cost of one ``detect`` on an image of the camera's size, milliseconds."""
        ...

    @property
    def range_m(self) -> tuple[float, float]:
        """Nearest and farthest distance to the face at which this target can be detected."""
        ...


def detector_names() -> list[str]:
    return sorted(_REGISTRY)


@functools.cache
def shipped_table(name: str) -> DetectabilityTable | None:
    """The detectability table measured for detector ``name`` on the bundled target
    (``syt-offboard calibrate-detector``), or None if none is shipped."""
    shipped = resources.files("offboard.perception.detection") / "tables" / f"{name}.json"
    return DetectabilityTable.load(Path(str(shipped))) if shipped.is_file() else None


def make_detector(name: str, model: TargetModel, intrinsics: Intrinsics, **options: object) -> Detector:
    """Build a registered detector; ``options`` are its keyword arguments (TypeError if unknown)."""
    if name not in _REGISTRY:
        raise ValueError(f"unknown detector {name!r}: choose one of {', '.join(detector_names())}")
    module_name, class_name = _REGISTRY[name].split(":")
    factory = getattr(importlib.import_module(module_name), class_name)
    return factory(model, intrinsics, **options)


def locate_target(detection: Detection, disparity: np.ndarray, intrinsics: Intrinsics, baseline_m: float,
                  camera_in_world: RigidTransform) -> np.ndarray | None:
    """World position (3,) of the pictured face's centre, or None without valid disparity on it.

    The depth is the median of the valid disparities (float px, NaN = invalid) inside the central
    part of the detected quadrilateral, shrunk by ``CORE_FRACTION`` about the face's centre: block
    matching fattens the foreground over the face's borders and a slanted face's border pixels may
    belong to the background. The median, not the mean, so that a few mismatches do not move it.
    """
    centre = detection.center_px
    core = centre + CORE_FRACTION * (detection.corners_px - centre)
    mask = np.zeros(disparity.shape[:2], dtype=np.uint8)
    cv2.fillConvexPoly(mask, np.round(core * 16).astype(np.int32), 1, lineType=cv2.LINE_8, shift=4)
    values = disparity[mask.astype(bool)]
    values = values[np.isfinite(values) & (values > 0)]
    if values.size == 0:
        return None
    z = intrinsics.fx_px * baseline_m / float(np.median(values))
    return camera_in_world.apply(intrinsics.back_project(centre[0], centre[1], z))


def operating_range(model: TargetModel, intrinsics: Intrinsics, *, min_face_px: float,
                    max_magnification: float = math.inf) -> tuple[float, float]:
    """(near, far) distances in metres to a fronto-parallel face.

    Near: the face still fits in ``MAX_FILL`` of the image in both directions, and is not magnified
    more than ``max_magnification`` times the best picture's resolution (no detail left beyond that).
    Far: the face's smaller side is still ``min_face_px`` pixels, what the method needs to work.
    """
    fx_w, fy_h = intrinsics.fx_px * model.face_width_m, intrinsics.fy_px * model.face_height_m
    picture_h, picture_w = max(p.shape[0] for p in model.pictures), max(p.shape[1] for p in model.pictures)
    near = max(fx_w / (MAX_FILL * intrinsics.width_px), fy_h / (MAX_FILL * intrinsics.height_px),
               fx_w / (max_magnification * picture_w), fy_h / (max_magnification * picture_h))
    far = min(fx_w, fy_h) / min_face_px
    if not near < far:
        raise ValueError(f"no distance at which a {model.face_width_m} x {model.face_height_m} m face is "
                         f"both inside the image and at least {min_face_px} px (near {near:.2f} m, far {far:.2f} m)")
    return (near, far)


class MeasuredDetector:
    """What every detector shares: its operating range, and its cost per image measured as it runs
    (seeded by timing it on :func:`timing_image` without the target: most images of a search do not
    hold it). Subclasses set ``name`` and implement ``_detect``."""

    name = ""

    def __init__(self, range_m: tuple[float, float]) -> None:
        self._range = range_m
        self._meter = CostMeter()

    def _measure_cost(self, model: TargetModel, intrinsics: Intrinsics, repeats: int) -> None:
        image = timing_image(model, intrinsics, with_target=False)
        for _ in range(repeats):
            self.detect(image)

    @property
    def cost_ms(self) -> float:
        return self._meter.median_ms

    @property
    def range_m(self) -> tuple[float, float]:
        return self._range

    def detect(self, left_rgb: np.ndarray) -> Detection | None:
        return self._meter.timed(self._detect, left_rgb)

    def _detect(self, left_rgb: np.ndarray) -> Detection | None:
        raise NotImplementedError


class CostMeter:
    """Running median of the last ``window`` detection times, seeded at construction by timing the
    detector on a synthetic image of the camera's size (see :func:`timing_image`)."""

    def __init__(self, window: int = 64) -> None:
        self._times_ms: deque[float] = deque(maxlen=window)

    def record(self, elapsed_ms: float) -> None:
        self._times_ms.append(elapsed_ms)

    def timed(self, fn: Callable[[np.ndarray], Detection | None], image: np.ndarray) -> Detection | None:
        start = time.perf_counter()
        result = fn(image)
        self.record((time.perf_counter() - start) * 1000.0)
        return result

    @property
    def median_ms(self) -> float:
        return float(np.median(self._times_ms)) if self._times_ms else math.nan


def timing_image(model: TargetModel, intrinsics: Intrinsics, *, with_target: bool = True) -> np.ndarray:
    """A deterministic stand-in for a camera image: room-like texture at several scales everywhere,
    with about as many SIFT keypoints as a rendered room (cost grows with them, so a plain image
    would flatter the detectors), and the model's first picture 80 px wide in the middle unless
    ``with_target`` is false (the detectors time themselves without it: most images of a search
    do not hold the target)."""
    rng = np.random.default_rng(0)
    w, h = intrinsics.width_px, intrinsics.height_px
    field = np.zeros((h, w), dtype=np.float32)
    for cells, weight in ((6, 1.0), (24, 0.8), (96, 0.5), (320, 0.25)):
        noise = rng.standard_normal((max(2, cells * h // w), cells)).astype(np.float32)
        field += weight * cv2.resize(noise, (w, h), interpolation=cv2.INTER_CUBIC)
    grey = np.clip(128.0 + 40.0 * field / field.std(), 0, 255).astype(np.uint8)
    image = np.repeat(grey[:, :, None], 3, axis=2)
    if with_target:
        face_w = min(80, w)
        face_h = min(h, max(1, round(face_w * model.face_height_m / model.face_width_m)))
        x0, y0 = (w - face_w) // 2, (h - face_h) // 2
        image[y0:y0 + face_h, x0:x0 + face_w] = cv2.resize(model.pictures[0], (face_w, face_h),
                                                            interpolation=cv2.INTER_AREA)
    return image


def to_grey(rgb: np.ndarray) -> np.ndarray:
    """(H, W) uint8 grey of an (H, W, 3) uint8 RGB image; grey images pass through."""
    image = np.asarray(rgb)
    if image.dtype != np.uint8:
        raise ValueError(f"images must be uint8, not {image.dtype}")
    if image.ndim == 3 and image.shape[2] == 3:
        return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)
    if image.ndim == 2:
        return np.ascontiguousarray(image)
    raise ValueError(f"images must be (H, W, 3) RGB or (H, W) grey, not {image.shape}")

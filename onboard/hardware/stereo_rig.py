"""A calibrated stereo rig: its OpenCV YAML file and the rectification it implies.

The file (``cv2.FileStorage``, written by ``stereo_calibration.calibrate``) holds::

    image_width, image_height   one camera's image size in pixels (half the side-by-side frame)
    K1, D1, K2, D2              camera matrices and distortion coefficients (left, right)
    R, T                        the right camera's pose: x_right = R x_left + T, T in metres
    rms_px                      (optional) the calibration's RMS reprojection error

The rectified pair follows the project's convention (``shared.geometry``): the left camera is the
reference and the right one sits at ``x = +baseline`` in its optical frame, so ``T`` is about
``(-baseline, 0, 0)`` for a horizontal rig.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from shared.geometry import Intrinsics

_MATRICES = {"K1": (3, 3), "K2": (3, 3), "R": (3, 3), "T": (3, 1)}
_DISTORTIONS = ("D1", "D2")


class CalibrationFileError(ValueError):
    """A stereo calibration file that is missing, unreadable or lacks a key; the message names which."""


@dataclass(frozen=True)
class StereoRig:
    """Intrinsics and extrinsics of a stereo pair as OpenCV calibrates them."""

    image_size: tuple[int, int]  # (width, height) of one camera's image
    k1: np.ndarray
    d1: np.ndarray
    k2: np.ndarray
    d2: np.ndarray
    rotation: np.ndarray  # R: left camera frame -> right camera frame
    translation_m: np.ndarray  # T, metres

    @property
    def baseline_m(self) -> float:
        return float(np.linalg.norm(self.translation_m))

    @property
    def swapped(self) -> bool:
        """The right camera left of the left one: T takes left-camera points into the right camera's
        frame, so its x is minus the baseline; if not, left and right traded places (depth < 0)."""
        return self.translation_m[0, 0] >= 0

    def save(self, path: Path | str, rms_px: float | None = None) -> None:
        storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
        try:
            storage.write("image_width", int(self.image_size[0]))
            storage.write("image_height", int(self.image_size[1]))
            for key, value in (("K1", self.k1), ("D1", self.d1), ("K2", self.k2), ("D2", self.d2),
                               ("R", self.rotation), ("T", self.translation_m)):
                storage.write(key, np.asarray(value, dtype=np.float64))
            if rms_px is not None:
                storage.write("rms_px", float(rms_px))
        finally:
            storage.release()

    def rectification(self) -> Rectification:
        """Rectifying rotations and projections (``cv2.stereoRectify``, zero disparity at infinity)."""
        r1, r2, p1, p2, _q, _roi1, _roi2 = cv2.stereoRectify(
            self.k1, self.d1, self.k2, self.d2, self.image_size, self.rotation, self.translation_m,
            flags=cv2.CALIB_ZERO_DISPARITY, alpha=0.0)
        return Rectification(self, r1, r2, p1, p2)


@dataclass(frozen=True)
class Rectification:
    """What rectifying a rig gives: the maps' inputs and the rectified pinhole model."""

    rig: StereoRig
    r1: np.ndarray
    r2: np.ndarray
    p1: np.ndarray
    p2: np.ndarray

    def intrinsics(self) -> Intrinsics:
        """The rectified left (reference) camera; the right one shares it."""
        w, h = self.rig.image_size
        return Intrinsics(int(w), int(h), float(self.p1[0, 0]), float(self.p1[1, 1]),
                          float(self.p1[0, 2]), float(self.p1[1, 2]))

    @property
    def baseline_m(self) -> float:
        """From the rectified right projection, P2[0, 3] = -fx * baseline."""
        return float(-self.p2[0, 3] / self.p2[0, 0])

    def maps(self) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """``cv2.remap`` maps (fixed point, fast) of the left and the right camera."""
        rig = self.rig
        return (cv2.initUndistortRectifyMap(rig.k1, rig.d1, self.r1, self.p1, rig.image_size, cv2.CV_16SC2),
                cv2.initUndistortRectifyMap(rig.k2, rig.d2, self.r2, self.p2, rig.image_size, cv2.CV_16SC2))


def load_rig(path: Path | str) -> StereoRig:
    """Read a calibration file; :class:`CalibrationFileError` names the file and what is wrong."""
    path = Path(path)
    if not path.is_file():
        raise CalibrationFileError(f"{path}: no such stereo calibration file "
                                   "(make one with: syt-onboard calibrate-stereo --out FILE)")
    try:
        storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except cv2.error as exc:
        raise CalibrationFileError(f"{path}: not an OpenCV YAML/XML file ({exc.msg.strip()})") from None
    try:
        if not storage.isOpened():
            raise CalibrationFileError(f"{path}: cannot be read as an OpenCV YAML/XML file")
        size = tuple(_integer(storage, key, path) for key in ("image_width", "image_height"))
        values = {key: _matrix(storage, key, shape, path) for key, shape in _MATRICES.items()}
        values |= {key: _distortion(storage, key, path) for key in _DISTORTIONS}
    finally:
        storage.release()
    for key in ("K1", "K2"):
        if problem := _camera_matrix_problem(values[key]):
            raise CalibrationFileError(f"{path}: {key} is not a camera matrix: {problem}")
    r = values["R"]
    if not (np.allclose(r @ r.T, np.eye(3), atol=1e-6) and np.linalg.det(r) > 0):
        raise CalibrationFileError(f"{path}: R is not a rotation (orthonormal, determinant +1)")
    rig = StereoRig(size, values["K1"], values["D1"], values["K2"], values["D2"], values["R"], values["T"])
    if rig.swapped:
        raise CalibrationFileError(f"{path}: T puts the right camera {rig.translation_m[0, 0]:g} m to the left of "
                                   "the left one (left and right swapped when it was made?)")
    return rig


def _camera_matrix_problem(k: np.ndarray) -> str:
    """Why ``k`` is no pinhole camera matrix ((fx, s, cx), (0, fy, cy), (0, 0, 1) with fx, fy > 0), or
    "": a degenerate one loads, then rectifies to NaN intrinsics that every info reply would carry."""
    if not (k[0, 0] > 0 and k[1, 1] > 0):
        return f"focal lengths fx={k[0, 0]:g}, fy={k[1, 1]:g} must be positive"
    if not np.array_equal(k[1:, 0], [0.0, 0.0]) or k[2, 1] != 0.0 or k[2, 2] != 1.0:
        return "its last two rows must be (0, fy, cy) and (0, 0, 1)"
    return ""


def _node(storage: cv2.FileStorage, key: str, path: Path) -> cv2.FileNode:
    node = storage.getNode(key)
    if node.empty():
        raise CalibrationFileError(f"{path}: missing key {key!r}")
    return node


def _integer(storage: cv2.FileStorage, key: str, path: Path) -> int:
    node = _node(storage, key, path)
    value = node.real() if node.isReal() or node.isInt() else None
    if value is None or value != int(value) or not 16 <= value <= 16384:
        raise CalibrationFileError(f"{path}: {key} must be an image size in pixels (16..16384)")
    return int(value)


def _matrix(storage: cv2.FileStorage, key: str, shape: tuple[int, int], path: Path) -> np.ndarray:
    value = _node(storage, key, path).mat()
    if value is None or value.size != shape[0] * shape[1] or not np.all(np.isfinite(value)):
        raise CalibrationFileError(f"{path}: {key} must be a finite {shape[0]}x{shape[1]} matrix")
    return value.astype(np.float64).reshape(shape)


def _distortion(storage: cv2.FileStorage, key: str, path: Path) -> np.ndarray:
    value = _node(storage, key, path).mat()
    if value is None or value.size not in (4, 5, 8, 12, 14) or not np.all(np.isfinite(value)):
        raise CalibrationFileError(f"{path}: {key} must hold 4, 5, 8, 12 or 14 finite distortion coefficients")
    return value.astype(np.float64).reshape(1, -1)

"""The target as the detectors know it: pictures of its textured face and its physical size.

Convention (the world format's, ``shared/world.py``): the target is a box of extents
``size_m = (x, y, z)`` before yaw, whose picture covers the face its yaw points to (+x before yaw).
The pictured face is therefore ``size_m[1]`` wide and ``size_m[2]`` high, and the picture is
stretched over the whole face whatever its own pixel aspect ratio; ``size_m[0]`` is the depth behind
the face. Several pictures may describe the same face (e.g. photographs under different light);
each is matched on its own.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from offboard.perception.detectability import face_size_m


MIN_PICTURE_PX = 16  # a smaller picture holds too little texture for either detector


class TargetModelError(ValueError):
    """A target model that cannot be built: unreadable picture, bad size."""


@dataclass(frozen=True, eq=False)  # eq=False: pictures are arrays, identity is the only sane equality
class TargetModel:
    pictures: tuple[np.ndarray, ...]  # (H, W, 3) uint8 RGB views of the pictured face
    size_m: tuple[float, float, float]  # box extents x (depth), y (face width), z (face height)

    def __post_init__(self) -> None:
        if not self.pictures:
            raise TargetModelError("a target model needs at least one picture")
        for i, picture in enumerate(self.pictures):
            _check_picture(picture, f"picture {i}")
        if len(self.size_m) != 3 or not all(math.isfinite(s) and s > 0 for s in self.size_m):
            raise TargetModelError(f"size_m must be three positive extents in metres, not {self.size_m}")

    @classmethod
    def from_files(cls, paths: Sequence[Path | str], size_m: Sequence[float]) -> TargetModel:
        """Read every picture file (any format OpenCV reads) as RGB."""
        if not paths:
            raise TargetModelError("a target model needs at least one picture file")
        size = tuple(float(s) for s in size_m)
        return cls(tuple(_read_rgb(Path(p)) for p in paths), size)  # type: ignore[arg-type]

    @property
    def face_width_m(self) -> float:
        return self.size_m[1]

    @property
    def face_height_m(self) -> float:
        return self.size_m[2]

    @property
    def face_size_m(self) -> float:
        """The size a detectability table scales with (:func:`~offboard.perception.detectability.face_size_m`)."""
        return face_size_m(self.face_width_m, self.face_height_m)


def _check_picture(picture: np.ndarray, label: str) -> None:
    if picture.dtype != np.uint8 or picture.ndim != 3 or picture.shape[2] != 3:
        raise TargetModelError(f"{label} must be (H, W, 3) uint8 RGB, not {picture.shape} {picture.dtype}")
    if min(picture.shape[:2]) < MIN_PICTURE_PX:
        raise TargetModelError(f"{label} is too small to detect anything in: {picture.shape[:2]} px")


def _read_rgb(path: Path) -> np.ndarray:
    if not path.is_file():
        raise TargetModelError(f"target picture {str(path)!r} does not exist or is not a file")
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise TargetModelError(f"target picture {str(path)!r} cannot be read as an image")
    rgb = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
    _check_picture(rgb, f"target picture {str(path)!r}")
    return rgb

"""Images written to disk (PNG and the like) by either program, or refused naming the file.

OpenCV's ``imwrite`` returns False, rather than raising, when it cannot write (a missing folder, a full
disk, an unknown extension): a caller that ignores it lists files that were never written.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np


def write_bgr(path: Path, image: np.ndarray) -> Path:
    """Write an image in OpenCV's own channel order (what its drawing functions produce)."""
    if not cv2.imwrite(str(path), image):
        raise OSError(f"cannot write the image {path}")
    return Path(path)


def write_rgb(path: Path, rgb: np.ndarray) -> Path:
    """Write an RGB image (what the cameras and the simulator produce)."""
    return write_bgr(path, cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))

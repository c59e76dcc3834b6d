"""Images are written, or refused naming the file: OpenCV alone says False and lets it pass."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from shared.image_files import write_rgb


def test_an_rgb_image_is_written_in_the_files_own_channel_order(tmp_path):
    rgb = np.zeros((4, 6, 3), np.uint8)
    rgb[..., 0] = 200  # red
    path = write_rgb(tmp_path / "red.png", rgb)
    assert cv2.imread(str(path))[0, 0].tolist() == [0, 0, 200]  # OpenCV reads BGR


def test_an_image_that_cannot_be_written_is_refused_naming_it(tmp_path):
    with pytest.raises(OSError, match="cannot write the image .*missing/red.png"):
        write_rgb(tmp_path / "missing" / "red.png", np.zeros((4, 6, 3), np.uint8))

"""Stereo calibration from chessboard pictures: ``syt-onboard calibrate-stereo``.

The image folder holds either pairs ``left_<name>.png`` + ``right_<name>.png`` (matched by
``<name>``; .jpg works too) or, when there is no ``left_*`` file, side-by-side frames (any
``*.png``/``*.jpg``, the left camera's image in the left half), as a UVC stereo camera saves them.

``board`` counts *inner* corners, columns x rows (a board of 10 x 7 squares is ``9x6``); one count
odd and one even keeps its orientation unambiguous. ``square_mm`` is a square's side, so ``T`` and
the baseline come out in metres. Each camera is calibrated alone (``calibrateCamera``, k3 fixed:
few views overfit it), then the pair (``stereoCalibrate`` with the intrinsics fixed). A bad set
is refused with a :class:`CalibrationError` saying what is wrong: no pictures, a picture without
its partner, sizes that differ, too few pairs with the board found (naming the pictures where it
was not, and the board size that was found instead if the count looks wrong), an RMS too high.
"""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from onboard.hardware.stereo_rig import StereoRig

log = logging.getLogger(__name__)

_SUFFIXES = (".png", ".jpg", ".jpeg")
_SUBPIX = ((5, 5), (-1, -1), (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4))
_FIND_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE


class CalibrationError(ValueError):
    """A picture set that cannot calibrate the rig; the message says what is wrong with it."""


@dataclass(frozen=True)
class ImagePair:
    name: str  # e.g. "left_03.png + right_03.png", or "frame_03.png" (side by side)
    left: np.ndarray  # grey
    right: np.ndarray
    sources: tuple[str, str]  # file names of the left and right image (the same one side by side)


@dataclass(frozen=True)
class CalibrationResult:
    rig: StereoRig
    rms_px: float  # stereo RMS reprojection error
    pairs_used: int
    pairs_skipped: tuple[str, ...]  # pairs where the board was not found in both images

    def summary(self) -> dict:
        """What ``calibrate-stereo`` prints."""
        rig = self.rig
        return {"rms_px": round(self.rms_px, 4), "pairs_used": self.pairs_used,
                "pairs_skipped": list(self.pairs_skipped), "image_size": list(rig.image_size),
                "fx_px": round(float(rig.k1[0, 0]), 2), "fy_px": round(float(rig.k1[1, 1]), 2),
                "baseline_m": round(rig.baseline_m, 5)}


def parse_board(text: str) -> tuple[int, int]:
    """``"9x6"`` -> ``(9, 6)`` inner corners."""
    match = re.fullmatch(r"\s*(\d+)\s*[xX]\s*(\d+)\s*", text)
    if match is None or min(int(match[1]), int(match[2])) < 2:
        raise CalibrationError(f"--board {text!r}: expected COLSxROWS inner corners, each at least 2 (e.g. 9x6)")
    return int(match[1]), int(match[2])


def calibrate_stereo(images: str | Path, board: str, square_mm: float, out: str | Path,
                     max_rms_px: float = 1.0, min_pairs: int = 5, swap_halves: bool = False) -> dict:
    """The ``calibrate-stereo`` command: calibrate, write ``out``, return the summary to print."""
    result = calibrate(images, parse_board(board), square_mm, max_rms_px=max_rms_px, min_pairs=min_pairs,
                       swap_halves=swap_halves)
    result.rig.save(out, result.rms_px)
    log.info("stereo calibration written to %s: %s", out, result.summary())
    return {**result.summary(), "out": str(out)}


def calibrate(images_dir: str | Path, board: tuple[int, int], square_mm: float, *,
              max_rms_px: float = 1.0, min_pairs: int = 5, swap_halves: bool = False) -> CalibrationResult:
    """Calibrate a stereo rig from chessboard pairs; raises :class:`CalibrationError` for a bad set.
    ``swap_halves``: side-by-side frames hold the right image in their left half (the camera's
    ``swap_halves``, which must agree, or the driver rectifies each half with the other's maps)."""
    if not square_mm > 0:
        raise CalibrationError(f"--square-mm {square_mm!r}: a square's side must be positive")
    pairs = load_pairs(Path(images_dir), swap_halves)
    found, skipped, missing = _detect(pairs, board)
    if len(found) < min_pairs:
        raise CalibrationError(_too_few(board, len(found), len(pairs), min_pairs, missing, pairs))
    size = pairs[0].left.shape[::-1]
    objects = [_board_points(board, square_mm / 1000.0)] * len(found)
    left = [corners[0] for corners in found]
    right = [corners[1] for corners in found]
    intrinsics = []
    for side, points in (("left", left), ("right", right)):
        rms, k, d, _r, _t = cv2.calibrateCamera(objects, points, size, None, None, flags=cv2.CALIB_FIX_K3)
        log.info("%s camera: RMS %.3f px", side, rms)
        intrinsics += [k, d]
    rms, k1, d1, k2, d2, r, t, _e, _f = cv2.stereoCalibrate(
        objects, left, right, *intrinsics, size, flags=cv2.CALIB_FIX_INTRINSIC,
        criteria=(cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 100, 1e-6))
    if not rms <= max_rms_px:
        raise CalibrationError(f"RMS reprojection error {rms:.3f} px exceeds {max_rms_px:g} px: blurred or "
                               "moving pictures, a board that is not flat, or a wrong --board/--square-mm")
    rig = StereoRig((int(size[0]), int(size[1])), k1, d1, k2, d2, r, t)
    if rig.swapped:
        raise CalibrationError(f"the right camera came out {t[0, 0]:.3f} m to the left of the left one: the "
                               "images are swapped (side-by-side frames: give --swap-halves)")
    return CalibrationResult(rig, float(rms), len(found), tuple(skipped))


def load_pairs(folder: Path, swap_halves: bool = False) -> list[ImagePair]:
    """The folder's pairs (see the module's docstring), as grey images of one size."""
    if not folder.is_dir():
        raise CalibrationError(f"{folder}: no such folder of calibration pictures")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in _SUFFIXES)
    lefts = {p.name[5:]: p for p in files if p.name.startswith("left_")}
    rights = {p.name[6:]: p for p in files if p.name.startswith("right_")}
    if lefts or rights:
        for key in sorted(set(lefts) ^ set(rights)):
            lone = lefts.get(key) or rights.get(key)
            partner = ("right_" if key in lefts else "left_") + key
            raise CalibrationError(f"{lone.name} has no partner {partner} in {folder}")
        pairs = [ImagePair(f"{lefts[k].name} + {rights[k].name}", _grey(lefts[k]), _grey(rights[k]),
                           (lefts[k].name, rights[k].name)) for k in sorted(lefts)]
    else:
        pairs = [_split(p, swap_halves) for p in files]
    if not pairs:
        raise CalibrationError(f"{folder}: no left_*.png/right_*.png pairs nor side-by-side pictures")
    _check_sizes(pairs)
    return pairs


def _grey(path: Path) -> np.ndarray:
    image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if image is None:
        raise CalibrationError(f"{path}: cannot be read as an image")
    return image


def _split(path: Path, swap_halves: bool) -> ImagePair:
    image = _grey(path)
    if image.shape[1] % 2:
        raise CalibrationError(f"{path.name}: a side-by-side picture needs an even width (got {image.shape[1]} px)")
    half = image.shape[1] // 2
    first, second = image[:, :half], image[:, half:]
    return ImagePair(path.name, *((second, first) if swap_halves else (first, second)), (path.name, path.name))


def _check_sizes(pairs: list[ImagePair]) -> None:
    first = pairs[0]
    expected = first.left.shape
    for pair in pairs:
        for image, source in zip((pair.left, pair.right), pair.sources):
            if image.shape != expected:
                raise CalibrationError(f"image sizes differ: {source} is {image.shape[1]}x{image.shape[0]}, "
                                       f"{first.sources[0]} is {expected[1]}x{expected[0]}")


def _find(image: np.ndarray, board: tuple[int, int]) -> np.ndarray | None:
    ok, corners = cv2.findChessboardCorners(image, board, flags=_FIND_FLAGS)
    if not ok:
        return None
    return cv2.cornerSubPix(image, corners, *_SUBPIX)


def _detect(pairs: list[ImagePair], board: tuple[int, int]):
    """(corners of the pairs seen in both images, names of the pairs skipped, files without the board)."""
    found, skipped, missing = [], [], []
    for pair in pairs:
        corners = [_find(image, board) for image in (pair.left, pair.right)]
        one_file = pair.sources[0] == pair.sources[1]  # side by side: say which image
        absent = [f"{source} ({side} image)" if one_file else source
                  for c, source, side in zip(corners, pair.sources, ("left", "right")) if c is None]
        if absent:
            skipped.append(pair.name)
            missing += absent
        else:
            found.append(corners)
    return found, skipped, missing


def _too_few(board: tuple[int, int], found: int, total: int, needed: int, missing: list[str],
             pairs: list[ImagePair]) -> str:
    cols, rows = board
    text = (f"the {cols}x{rows} board (inner corners) was found in both images of only {found} of "
            f"{total} pairs, at least {needed} are needed")
    if missing:
        text += f"; not found in: {', '.join(missing)}"
    if found == 0:
        other = _other_board_size(pairs[0].left, board)
        if other:
            text += (f". A {other[0]}x{other[1]} board was found in {pairs[0].sources[0]}: "
                     "--board counts inner corners, one fewer than squares")
    return text


def _other_board_size(image: np.ndarray, board: tuple[int, int]) -> tuple[int, int] | None:
    cols, rows = board
    for candidate in ((cols - 1, rows - 1), (cols - 1, rows), (cols, rows - 1), (cols + 1, rows + 1),
                      (cols + 1, rows), (cols, rows + 1), (rows, cols)):
        if min(candidate) >= 2 and candidate != board and _find(image, candidate) is not None:
            return candidate
    return None


def _board_points(board: tuple[int, int], square_m: float) -> np.ndarray:
    """The inner corners on the board's plane (z = 0), row by row as OpenCV orders them."""
    cols, rows = board
    grid = np.zeros((rows * cols, 3), np.float32)
    grid[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * square_m
    return grid

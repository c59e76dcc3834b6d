"""Stereo calibration from chessboard views the simulator renders, and its refusals of bad sets."""

from __future__ import annotations

import dataclasses
import json
import shutil
import subprocess
import sys

import cv2
import numpy as np
import pytest

from onboard.config import CameraConfig
from onboard.hardware.stereo_calibration import CalibrationError, calibrate, calibrate_stereo, parse_board
from onboard.hardware.stereo_rig import CalibrationFileError, load_rig
from onboard.config import UvcStereoConfig
from onboard.hardware.uvc_camera import UvcStereoCamera
from onboard.sim.chessboard_views import DEFAULT_VIEWS, render_chessboard_views

BOARD, SQUARE_MM = (9, 6), 80.0


@pytest.fixture(scope="module")
def views(tmp_path_factory):
    folder = tmp_path_factory.mktemp("chessboard")
    render_chessboard_views(folder, CameraConfig(), DEFAULT_VIEWS[:10], square_m=SQUARE_MM / 1000)
    return folder


def copy_of(views, tmp_path, names=None):
    folder = tmp_path / "set"
    folder.mkdir()
    for path in sorted(views.iterdir()):
        if names is None or path.name in names:
            shutil.copy(path, folder / path.name)
    return folder


def test_recovers_the_simulated_rig(views, tmp_path):
    sim = CameraConfig()
    out = tmp_path / "stereo.yaml"
    summary = calibrate_stereo(views, "9x6", SQUARE_MM, out)
    assert summary["pairs_used"] == 10 and summary["rms_px"] < 0.5
    rig = load_rig(out)
    f = sim.intrinsics().fx_px
    for k in (rig.k1, rig.k2):
        assert k[0, 0] == pytest.approx(f, rel=0.01) and k[1, 1] == pytest.approx(f, rel=0.01)
    assert rig.baseline_m == pytest.approx(sim.baseline_m, rel=0.02)
    assert rig.translation_m[0, 0] < 0  # the right camera sits at +x of the left one
    assert rig.image_size == (sim.width_px, sim.height_px)


def corner_rows(grey: np.ndarray) -> np.ndarray:
    """The rows of the board's inner corners, to subpixel accuracy."""
    grey = np.ascontiguousarray(grey)
    ok, corners = cv2.findChessboardCorners(grey, BOARD, flags=cv2.CALIB_CB_ADAPTIVE_THRESH)
    assert ok
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)
    return cv2.cornerSubPix(grey, corners, (5, 5), (-1, -1), criteria).reshape(-1, 2)[:, 1]


def test_side_by_side_pictures_and_rectified_rows(views, tmp_path):
    """A right camera rolled by 1.5° (its images warped accordingly): calibrated from side-by-side
    frames, the camera driver's rectified pairs put every corner on its partner's row."""
    sim = CameraConfig()
    k = sim.intrinsics().matrix()
    roll = np.radians(1.5)
    warp = k @ np.array([[np.cos(roll), -np.sin(roll), 0], [np.sin(roll), np.cos(roll), 0], [0, 0, 1]]) @ np.linalg.inv(k)
    folder = tmp_path / "sbs"
    folder.mkdir()
    for i in range(10):
        left = cv2.imread(str(views / f"left_{i:02d}.png"))
        right = cv2.warpPerspective(cv2.imread(str(views / f"right_{i:02d}.png")), warp, (sim.width_px, sim.height_px))
        cv2.imwrite(str(folder / f"frame_{i:02d}.png"), cv2.hconcat([left, right]))
    out = tmp_path / "rolled.yaml"
    assert calibrate_stereo(folder, "9x6", SQUARE_MM, out)["pairs_used"] == 10
    camera = UvcStereoCamera(UvcStereoConfig(device=str(folder / "frame_%02d.png"), calibration=str(out),
                                             width_px=2 * sim.width_px, height_px=sim.height_px, stale_frames=0))
    try:
        raw_offsets, rectified_offsets = [], []
        for i in range(3):
            pair = camera.capture()
            frame = cv2.imread(str(folder / f"frame_{i:02d}.png"), cv2.IMREAD_GRAYSCALE)
            raw = [corner_rows(half) for half in (frame[:, :sim.width_px], frame[:, sim.width_px:])]
            rect = [corner_rows(cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)) for img in (pair.left, pair.right)]
            raw_offsets.append(np.abs(raw[0] - raw[1]).max())
            rectified_offsets.append(np.abs(rect[0] - rect[1]).max())
    finally:
        camera.close()
    assert min(raw_offsets) > 2.0  # the roll shows before rectification...
    assert max(rectified_offsets) < 0.7  # ...and is gone after it
    assert camera.mount.baseline_m == pytest.approx(sim.baseline_m, rel=0.02)


def _side_by_side(views, tmp_path, count: int, swapped: bool = False, blank_right: tuple[int, ...] = ()):
    folder = tmp_path / ("swapped" if swapped else "sbs")
    folder.mkdir()
    for i in range(count):
        left, right = (cv2.imread(str(views / f"{side}_{i:02d}.png")) for side in ("left", "right"))
        right = np.full_like(right, 128) if i in blank_right else right
        cv2.imwrite(str(folder / f"frame_{i:02d}.png"), cv2.hconcat([right, left] if swapped else [left, right]))
    return folder


def test_side_by_side_frames_with_the_halves_swapped_are_refused_unless_said_so(views, tmp_path):
    folder = _side_by_side(views, tmp_path, 6, swapped=True)
    with pytest.raises(CalibrationError, match=r"right camera came out 0\.1\d+ m to the left .* --swap-halves"):
        calibrate(folder, BOARD, SQUARE_MM)
    out = tmp_path / "swapped.yaml"
    calibrate_stereo(folder, "9x6", SQUARE_MM, out, swap_halves=True)
    assert load_rig(out).translation_m[0, 0] == pytest.approx(-CameraConfig().baseline_m, rel=0.02)


def test_a_file_with_the_cameras_swapped_is_refused_by_name(views, tmp_path):
    out = tmp_path / "good.yaml"
    calibrate_stereo(_side_by_side(views, tmp_path, 6), "9x6", SQUARE_MM, out)
    rig = load_rig(out)
    swapped = tmp_path / "swapped.yaml"
    dataclasses.replace(rig, translation_m=-rig.translation_m).save(swapped, 0.1)  # the cameras traded places
    with pytest.raises(CalibrationFileError, match="swapped.yaml: T puts the right camera .* to the left"):
        load_rig(swapped)


def test_a_side_by_side_frame_without_the_board_in_one_half_names_that_image(views, tmp_path):
    folder = _side_by_side(views, tmp_path, 4, blank_right=(3,))
    with pytest.raises(CalibrationError, match=r"not found in: frame_03.png \(right image\)"):
        calibrate(folder, BOARD, SQUARE_MM)

def test_too_few_pairs_names_the_pictures_without_the_board(views, tmp_path):
    folder = copy_of(views, tmp_path, {f"{side}_{i:02d}.png" for side in ("left", "right") for i in range(3)})
    blank = np.full((480, 640, 3), 128, np.uint8)
    cv2.imwrite(str(folder / "left_09.png"), blank)
    cv2.imwrite(str(folder / "right_09.png"), blank)
    with pytest.raises(CalibrationError, match=r"found in both images of only 3 of 4 pairs, at least 5 are needed; "
                                               r"not found in: left_09.png, right_09.png"):
        calibrate(folder, BOARD, SQUARE_MM)


def test_wrong_board_size_is_named(views, tmp_path):
    folder = copy_of(views, tmp_path, {f"{side}_{i:02d}.png" for side in ("left", "right") for i in range(2)})
    with pytest.raises(CalibrationError, match=r"found in both images of only 0 of 2 pairs.*"
                                               r"A 9x6 board was found in left_00.png: --board counts inner corners"):
        calibrate(folder, (10, 7), SQUARE_MM)


def test_sizes_partners_rms_and_board_text(views, tmp_path):
    folder = copy_of(views, tmp_path)
    small = cv2.resize(cv2.imread(str(folder / "right_04.png")), (320, 240))
    cv2.imwrite(str(folder / "right_04.png"), small)
    with pytest.raises(CalibrationError, match=r"image sizes differ: right_04.png is 320x240, left_00.png is 640x480"):
        calibrate(folder, BOARD, SQUARE_MM)
    (folder / "right_04.png").unlink()
    with pytest.raises(CalibrationError, match=r"left_04.png has no partner right_04.png"):
        calibrate(folder, BOARD, SQUARE_MM)
    (folder / "left_04.png").unlink()
    with pytest.raises(CalibrationError, match=r"RMS reprojection error 0\.\d+ px exceeds 0.01 px"):
        calibrate(folder, BOARD, SQUARE_MM, max_rms_px=0.01)
    with pytest.raises(CalibrationError, match="no such folder"):
        calibrate(tmp_path / "absent", BOARD, SQUARE_MM)
    assert parse_board("9x6") == (9, 6)
    with pytest.raises(CalibrationError, match=r"--board '9-6': expected COLSxROWS"):
        parse_board("9-6")


def test_the_command_prints_the_rms_and_a_bad_set_exits_2_saying_why(views, tmp_path):
    out = tmp_path / "stereo.yaml"
    command = [sys.executable, "-m", "onboard.cli", "calibrate-stereo", "--images", str(views), "--square-mm",
               str(SQUARE_MM), "--out", str(out), "--board"]
    done = subprocess.run(command + ["9x6"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    summary = json.loads(done.stdout)
    assert summary["rms_px"] < 0.5 and summary["out"] == str(out) and load_rig(out).baseline_m > 0
    out.unlink()
    refused = subprocess.run(command + ["8x6"], capture_output=True, text=True, timeout=120)
    assert refused.returncode == 2 and refused.stdout == "" and not out.exists()
    assert "found in both images of only 0 of 10 pairs" in refused.stderr

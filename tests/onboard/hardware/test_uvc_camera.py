"""The UVC side-by-side stereo camera through a real cv2.VideoCapture on files written here."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest

from onboard.devices import DeviceFault
from onboard.hardware.stereo_rig import CalibrationFileError, StereoRig, load_rig
from onboard.config import UvcStereoConfig
from onboard.hardware.uvc_camera import UvcStereoCamera, probe
from shared.geometry import HeadMount

W, H = 320, 240
K = np.array([[300.0, 0.0, (W - 1) / 2], [0.0, 300.0, (H - 1) / 2], [0.0, 0.0, 1.0]])


def ideal_rig(baseline_m: float = 0.12) -> StereoRig:
    """Two identical, parallel, undistorted cameras: rectification changes nothing."""
    return StereoRig((W, H), K, np.zeros((1, 5)), K, np.zeros((1, 5)), np.eye(3),
                     np.array([[-baseline_m], [0.0], [0.0]]))


def frames(count: int) -> list[np.ndarray]:
    """Side-by-side BGR frames: a textured left half, a different right half, numbered by frame."""
    rng = np.random.default_rng(1)
    out = []
    for i in range(count):
        base = cv2.GaussianBlur(rng.integers(0, 255, (H, 2 * W, 3), dtype=np.uint8), (9, 9), 3)
        base[:, :W, 2] = 200  # a red left half (BGR), so a swap or a colour mix-up shows
        base[:, W:, 0] = 200  # a blue right half
        cv2.putText(base, str(i), (20, 60), cv2.FONT_HERSHEY_SIMPLEX, 2, (255, 255, 255), 3)
        out.append(base)
    return out


@pytest.fixture
def setup(tmp_path):
    calibration = tmp_path / "stereo.yaml"
    ideal_rig().save(calibration, rms_px=0.2)
    images = frames(3)
    for i, frame in enumerate(images):
        cv2.imwrite(str(tmp_path / f"img_{i:02d}.png"), frame)
    config = UvcStereoConfig(device=str(tmp_path / "img_%02d.png"), calibration=str(calibration),
                             width_px=2 * W, height_px=H, stale_frames=0)
    return config, images


def test_splits_rectifies_and_converts_each_frame_of_an_image_sequence(setup):
    config, images = setup
    camera = UvcStereoCamera(config, HeadMount(height_m=1.1))
    try:
        assert camera.mount == HeadMount(height_m=1.1, baseline_m=pytest.approx(0.12))
        assert camera.intrinsics.fx_px == pytest.approx(300.0, rel=1e-3)
        assert (camera.intrinsics.width_px, camera.intrinsics.height_px) == (W, H)
        for frame in images:
            pair = camera.capture()
            assert pair.left.shape == pair.right.shape == (H, W, 3)
            expected_left = cv2.cvtColor(frame[:, :W], cv2.COLOR_BGR2RGB)
            expected_right = cv2.cvtColor(frame[:, W:], cv2.COLOR_BGR2RGB)
            assert np.abs(pair.left.astype(int) - expected_left).mean() < 3.0
            assert np.abs(pair.right.astype(int) - expected_right).mean() < 3.0
            assert pair.left[:, :, 0].mean() > 150 > pair.left[:, :, 2].mean()  # red is R in RGB
        with pytest.raises(DeviceFault, match="no frame"):
            camera.capture()  # the sequence has ended
    finally:
        camera.close()


def test_swapped_halves_and_an_mjpg_video(tmp_path, setup):
    config, images = setup
    video = tmp_path / "stereo.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (2 * W, H))
    for frame in images:
        writer.write(frame)
    writer.release()
    camera = UvcStereoCamera(replace(config, device=str(video), swap_halves=True, stale_frames=1))
    try:
        pair = camera.capture()  # frame 0 dropped as stale, frame 1 read
        assert pair.right[:, :, 0].mean() > 150 and pair.left[:, :, 2].mean() > 150
        assert np.abs(pair.left.astype(int) - cv2.cvtColor(images[1][:, W:], cv2.COLOR_BGR2RGB)).mean() < 8.0
    finally:
        camera.close()
    assert probe(str(video))["width_px"] == 2 * W


def test_rectification_undoes_a_calibrated_distortion(tmp_path, setup):
    config, _ = setup
    d = np.array([[-0.3, 0.08, 0.0, 0.0, 0.0]])  # strong barrel distortion
    replace(ideal_rig(), d1=d, d2=d).save(tmp_path / "distorted.yaml")
    raw = (40.0, 30.0)  # a bright dot near the corner, where the distortion is strongest
    frame = np.zeros((H, 2 * W, 3), np.uint8)
    cv2.circle(frame, (int(raw[0] * 16), int(raw[1] * 16)), 3 * 16, (255, 255, 255), -1, cv2.LINE_AA, shift=4)
    cv2.imwrite(str(tmp_path / "dot_00.png"), frame)
    camera = UvcStereoCamera(replace(config, device=str(tmp_path / "dot_%02d.png"),
                                     calibration=str(tmp_path / "distorted.yaml")))
    try:
        left = camera.capture().left[:, :, 0].astype(float)
    finally:
        camera.close()
    rect = load_rig(tmp_path / "distorted.yaml").rectification()
    expected = cv2.undistortPoints(np.array([[raw]]), K, d, R=rect.r1, P=rect.p1)[0, 0]
    ys, xs = np.mgrid[0:H, 0:W]
    seen = np.array([(xs * left).sum(), (ys * left).sum()]) / left.sum()
    assert np.hypot(*(expected - raw)) > 5.0  # rectification moves the dot noticeably...
    assert np.hypot(*(seen - expected)) < 0.5  # ...to where the calibrated model says


def test_clear_errors(tmp_path, setup):
    config, _ = setup
    with pytest.raises(CalibrationFileError, match="no such stereo calibration file"):
        UvcStereoCamera(replace(config, calibration=str(tmp_path / "none.yaml")))
    broken = tmp_path / "broken.yaml"
    broken.write_text("%YAML:1.0\n---\nimage_width: 320\nimage_height: 240\n")
    with pytest.raises(CalibrationFileError, match="broken.yaml: missing key 'K1'"):
        load_rig(broken)
    rig = load_rig(config.calibration)
    for name, bad, says in (("k1", np.zeros((3, 3)), "K1 is not a camera matrix: focal lengths fx=0, fy=0"),
                            ("k2", rig.k2 * 2.0, r"K2 is not a camera matrix: its last two rows must be"),
                            ("rotation", rig.rotation * 1.1, r"R is not a rotation")):
        degenerate = tmp_path / f"degenerate-{name}.yaml"  # loaded, it rectified to NaN intrinsics
        replace(rig, **{name: bad}).save(degenerate)
        with pytest.raises(CalibrationFileError, match=f"degenerate-{name}.yaml: {says}"):
            load_rig(degenerate)
    with pytest.raises(DeviceFault, match="cannot be opened"):
        UvcStereoCamera(replace(config, device=str(tmp_path / "nothing_%02d.png")))
    with pytest.raises(DeviceFault, match="does not hold two 320x240 images"):
        UvcStereoCamera(replace(config, width_px=1280, height_px=480))
    cv2.imwrite(str(tmp_path / "small_00.png"), np.zeros((100, 200, 3), np.uint8))
    camera = UvcStereoCamera(replace(config, device=str(tmp_path / "small_%02d.png")))
    try:
        with pytest.raises(DeviceFault, match=r"frame is 200x100, configured 640x240"):
            camera.capture()
    finally:
        camera.close()

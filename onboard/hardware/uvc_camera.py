"""A side-by-side USB (UVC) stereo camera read through OpenCV: the ``StereoCamera`` of the hardware backend.

Such a camera delivers both images in one frame, the left camera's in the left half. Each
capture splits the frame and rectifies both halves with ``cv2.remap`` maps built once from the
calibration file (``onboard.hardware.stereo_rig``; make one with ``syt-onboard calibrate-stereo``).
``intrinsics`` are the rectified left camera's and the mount's baseline is the calibrated one.

``device`` is what ``cv2.VideoCapture`` opens: a V4L2 path (``/dev/video0``), a camera index
(``"0"``), a video file or an image sequence (``frames/img_%02d.png``), which is how tests drive it.

A Point Grey Bumblebee2 (the report's camera) is FireWire and needs its vendor's proprietary SDK
(FlyCapture with Triclops, now Spinnaker), so no driver for it ships here. Its owner writes a class
with ``intrinsics``, ``mount``, ``capture() -> StereoImages`` (rectified RGB, Triclops rectifies)
and ``close()``, the ``StereoCamera`` Protocol of ``onboard/devices.py``, and builds it where the
hardware backend builds this one.
"""

from __future__ import annotations

import logging
from dataclasses import replace

import cv2
import numpy as np

from onboard.config import UvcStereoConfig
from onboard.devices import DeviceFault, StereoImages
from onboard.hardware.stereo_rig import load_rig
from shared.geometry import HeadMount

log = logging.getLogger(__name__)


class UvcStereoCamera:
    """``StereoCamera`` over ``cv2.VideoCapture``; raises ``DeviceFault`` when the camera fails."""

    def __init__(self, config: UvcStereoConfig, head: HeadMount = HeadMount()):
        rig = load_rig(config.calibration)
        if (config.width_px, config.height_px) != (2 * rig.image_size[0], rig.image_size[1]):
            raise DeviceFault(f"camera: a {config.width_px}x{config.height_px} side-by-side frame does not hold "
                              f"two {rig.image_size[0]}x{rig.image_size[1]} images of {config.calibration}")
        rectification = rig.rectification()
        self.intrinsics = rectification.intrinsics()
        self.mount = replace(head, baseline_m=rectification.baseline_m)
        self._maps = rectification.maps()
        self.config = config
        self._capture = open_capture(config.device)
        _request_mode(self._capture, config)

    def capture(self) -> StereoImages:
        """The newest frame, split and rectified, as RGB."""
        for _ in range(self.config.stale_frames):
            self._capture.grab()
        ok, frame = self._capture.read()
        if not ok or frame is None:
            raise DeviceFault(f"camera {self.config.device!r}: no frame (unplugged, or the end of the file)")
        halves = split_frame(frame, self.config)
        left, right = (cv2.remap(image, *maps, cv2.INTER_LINEAR) for image, maps in zip(halves, self._maps))
        return StereoImages(cv2.cvtColor(left, cv2.COLOR_BGR2RGB), cv2.cvtColor(right, cv2.COLOR_BGR2RGB))

    def close(self) -> None:
        self._capture.release()


def open_capture(device: str) -> cv2.VideoCapture:
    """Open a camera index, device path, video file or image sequence."""
    if device == "sim":
        raise DeviceFault("camera: device 'sim' selects the simulated camera, not a UVC device")
    capture = cv2.VideoCapture(int(device) if device.isdigit() else device)
    if not capture.isOpened():
        raise DeviceFault(f"camera {device!r} cannot be opened (no such device, busy, or not a video)")
    return capture


def _request_mode(capture: cv2.VideoCapture, config: UvcStereoConfig) -> None:
    """Ask for the frame size and rate, and a short queue (a file ignores all of it)."""
    for prop, value in ((cv2.CAP_PROP_FRAME_WIDTH, config.width_px), (cv2.CAP_PROP_FRAME_HEIGHT, config.height_px),
                        (cv2.CAP_PROP_FPS, config.fps), (cv2.CAP_PROP_BUFFERSIZE, 1)):
        capture.set(prop, value)


def split_frame(frame: np.ndarray, config: UvcStereoConfig) -> tuple[np.ndarray, np.ndarray]:
    """(left, right) halves of a side-by-side BGR frame of the configured size."""
    h, w = frame.shape[:2]
    if (w, h) != (config.width_px, config.height_px):
        raise DeviceFault(f"camera {config.device!r}: frame is {w}x{h}, configured "
                          f"{config.width_px}x{config.height_px} (width_px, height_px)")
    if frame.ndim == 2:
        frame = cv2.cvtColor(frame, cv2.COLOR_GRAY2BGR)
    left, right = frame[:, : w // 2], frame[:, w // 2:]
    return (right, left) if config.swap_halves else (left, right)


def probe(device: str) -> dict:
    """Identify a camera: ``{"device": "camera", "path": ..., "width_px": ..., "height_px": ..., "fps": ...}``."""
    capture = open_capture(device)
    try:
        ok, frame = capture.read()
        if not ok or frame is None:
            raise DeviceFault(f"camera {device!r} opens but delivers no frame")
        fps = capture.get(cv2.CAP_PROP_FPS)
    finally:
        capture.release()
    return {"device": "camera", "path": device, "width_px": int(frame.shape[1]),
            "height_px": int(frame.shape[0]), "fps": round(float(fps), 2)}

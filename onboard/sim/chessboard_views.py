"""Chessboard views rendered by the simulator, for checking the stereo calibration tool.

A room with the built-in ``chessboard`` poster on a wall; the simulated stereo head looks at it
from several distances and angles, with the board off the image centre in some views, and each
pair is written as ``left_NN.png`` / ``right_NN.png``, the layout ``calibrate-stereo`` reads. The
rendered pairs are rectified and undistorted, so a good calibration recovers the simulated rig's
focal length and baseline.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

from onboard.config import CameraConfig
from onboard.sim import textures
from onboard.sim.render import StereoRenderer
from shared.geometry import Pose2D
from shared.world import World, parse_world
from shared.image_files import write_rgb

BOARD_CENTER_M = (0.0, 2.5, 1.4)  # on the x = 0 wall, facing +x


@dataclass(frozen=True)
class BoardView:
    """Where the head stands and looks: ``distance_m`` from the board along a line ``azimuth_deg``
    off its normal, aimed at the board's centre and then turned by the pan and tilt offsets."""

    distance_m: float
    azimuth_deg: float
    pan_offset_deg: float = 0.0
    tilt_offset_deg: float = 0.0


DEFAULT_VIEWS = (
    BoardView(1.5, 0.0), BoardView(1.5, -35.0, 8.0, 5.0), BoardView(1.5, 35.0, -8.0, -5.0),
    BoardView(2.0, -20.0, -10.0, 7.0), BoardView(2.0, 20.0, 10.0, -7.0), BoardView(2.0, 45.0, 0.0, 5.0),
    BoardView(2.0, -45.0, 0.0, -5.0), BoardView(2.6, 0.0, 14.0, 8.0), BoardView(2.6, 0.0, -14.0, -8.0),
    BoardView(1.4, 25.0, 5.0, -6.0), BoardView(1.4, -25.0, -5.0, 6.0), BoardView(3.0, 30.0, 0.0, 0.0),
)


def chessboard_world(square_m: float = 0.08) -> World:
    """A 6 x 5 x 3 m room with the chessboard poster (squares of ``square_m``) on its x = 0 wall."""
    cols, rows = textures.CHESSBOARD_SQUARES
    size = [(cols + 2) * square_m, (rows + 2) * square_m]  # the picture includes a one-square border
    return parse_world({
        "name": "chessboard-room",
        "room": {"size": [6.0, 5.0, 3.0]},
        "target": {"size": [0.23, 0.23, 0.23], "position": [5.6, 0.4, 0.0]},
        "robot": {"start": [3.0, 2.5]},
        "poster": [{"name": "chessboard", "picture": "chessboard", "center": list(BOARD_CENTER_M),
                    "size": size, "yaw_deg": 0.0}],
    }, Path("."))


def render_chessboard_views(out_dir: Path | str, camera: CameraConfig = CameraConfig(),
                            views: tuple[BoardView, ...] = DEFAULT_VIEWS, square_m: float = 0.08) -> list[Path]:
    """Render ``views`` of the chessboard into ``out_dir``; returns the files written."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    renderer = StereoRenderer(chessboard_world(square_m), camera.intrinsics(), camera.mount())
    written = []
    for i, view in enumerate(views):
        frame = renderer.render(*_head_setting(view, camera.head_height_m))
        for side, image in (("left", frame.left), ("right", frame.right)):
            path = out / f"{side}_{i:02d}.png"
            written.append(write_rgb(path, image))
    return written


def _head_setting(view: BoardView, head_height_m: float) -> tuple[Pose2D, float, float]:
    """Robot pose, pan and tilt of a view (the robot faces the board, the head makes the offsets)."""
    bx, by, bz = BOARD_CENTER_M
    az = math.radians(view.azimuth_deg)
    x, y = bx + view.distance_m * math.cos(az), by + view.distance_m * math.sin(az)
    heading = math.atan2(by - y, bx - x)
    tilt = math.atan2(bz - head_height_m, view.distance_m)
    return Pose2D(x, y, heading), math.radians(view.pan_offset_deg), tilt + math.radians(view.tilt_offset_deg)

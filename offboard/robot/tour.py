"""A short scripted drive: look around, capture, move, capture again, and save what was seen.

It is the demo until the search exists, and a quick check that a robot answers every command.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path

from offboard.robot.robot_client import RobotClient
from shared import messages as m
from shared.image_files import write_rgb

log = logging.getLogger(__name__)

# (pan_deg, tilt_deg) settings looked at from each stop, then the move to the next stop
_LOOKS = ((0.0, 0.0), (45.0, 0.0), (-45.0, 0.0), (0.0, 30.0))
_MOVES = ((0.0, 1.0), (90.0, 0.0))  # (turn_deg, distance_m)


def run_tour(robot: RobotClient, out_dir: Path) -> list[Path]:
    """Capture at every look of every stop; write left/right PNGs and a metadata JSON per capture."""
    out_dir.mkdir(parents=True, exist_ok=True)
    info = robot.wait_for_robot()
    log.info("robot %r (%s backend) ready", info.robot_id, info.backend)
    written: list[Path] = []
    for stop_index in range(len(_MOVES) + 1):
        for pan, tilt in _LOOKS:
            robot.look(pan, tilt)
            written += save_capture(robot.capture(), out_dir, f"stop{stop_index}_pan{pan:+.0f}_tilt{tilt:+.0f}")
        if stop_index < len(_MOVES):
            turn, distance = _MOVES[stop_index]
            result = robot.move(turn, distance)
            log.info("move turn=%g° distance=%g m: %s at (%.2f, %.2f)", turn, distance, result.status,
                     result.pose.x_m, result.pose.y_m)
    robot.look(0.0, 0.0)
    return written


def save_capture(capture: m.Capture, out_dir: Path, stem: str) -> list[Path]:
    paths = [out_dir / f"{stem}_left.png", out_dir / f"{stem}_right.png", out_dir / f"{stem}.json"]
    write_rgb(paths[0], capture.left)
    write_rgb(paths[1], capture.right)
    meta = {"pose": vars(capture.pose), "pan_deg": capture.pan_deg, "tilt_deg": capture.tilt_deg,
            "intrinsics": vars(capture.intrinsics), "mount": vars(capture.mount),
            "robot_time_s": capture.robot_time_s}
    paths[2].write_text(json.dumps(meta, indent=2))
    log.info("captured %s at robot time %.2f s", stem, capture.robot_time_s)
    return paths

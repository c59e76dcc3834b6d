"""``write_preview``: render one stereo frame of a world to files, for ``syt-onboard render``;
``write_frame`` writes a frame already rendered."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from onboard.sim.render import StereoFrame, StereoRenderer
from shared.world import World
from shared.geometry import HeadMount, Intrinsics, Pose2D
from shared.image_files import write_rgb

log = logging.getLogger(__name__)


def write_preview(world: World, pose: Pose2D, pan_rad: float, tilt_rad: float, out_dir: Path,
                  intrinsics: Intrinsics, mount: HeadMount) -> list[Path]:
    """Write ``left.png``, ``right.png`` (RGB images) and ``depth.npy`` (float32 metres, left
    camera) into ``out_dir`` (created if missing); returns the three paths."""
    paths = write_frame(StereoRenderer(world, intrinsics, mount).render(pose, pan_rad, tilt_rad), out_dir)
    log.info("rendered %s at (%.2f, %.2f, %.0f deg) pan %.1f deg tilt %.1f deg into %s", world.name,
             pose.x_m, pose.y_m, np.degrees(pose.heading_rad), np.degrees(pan_rad),
             np.degrees(tilt_rad), out_dir)
    return paths


def write_frame(frame: StereoFrame, out_dir: Path) -> list[Path]:
    """Write a rendered frame as ``write_preview`` does; returns the three paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = [out_dir / "left.png", out_dir / "right.png", out_dir / "depth.npy"]
    for path, rgb in zip(paths[:2], (frame.left, frame.right)):
        write_rgb(path, rgb)
    np.save(paths[2], frame.depth_m.astype(np.float32))
    return paths

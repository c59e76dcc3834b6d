"""``syt-onboard worlds views``: rendered stereo pairs with their true depth, to score stereo on.

The planner's stereo has Middlebury to be scored on, but the rooms it searches are rendered: their
textures tile, and a matcher that suits a photograph may not suit them. This writes a set of views
the way the robot sees a room: the head at its height, the robot on floor it could reach from the
world's start, facing anywhere, the head tilted as the navigator and the planner tilt it. ``offboard.perception.
rendered_views`` scores a matcher on them (``syt-offboard bench stereo --views DIR``).

Layout of the output directory: ``views.json`` (the camera and, per view, its world, pose, tilt and
folder) and one folder per view holding ``left.png``, ``right.png`` and ``depth.npy`` (float32
z-depth of the left camera, metres), as ``syt-onboard render`` writes them. A seed gives the same
views.
"""

from __future__ import annotations

import json
import logging
import math
from pathlib import Path

import numpy as np

from onboard.config import CameraConfig
from onboard.sim.preview import write_preview
from onboard.sim.world import load_world
from onboard.sim.world_check import reachable_floor
from shared.geometry import Pose2D
from shared.world import World

log = logging.getLogger(__name__)

TILTS_DEG = (-35.0, -25.0, 0.0, 30.0)  # the navigator's probe and look tilts, the planner's two


def sample_poses(world: World, count: int, rng: np.random.Generator) -> list[tuple[Pose2D, float]]:
    """``count`` (pose, tilt in rad) of a world: reachable floor, any heading, one of ``TILTS_DEG``."""
    floor = reachable_floor(world)
    x, y = floor.centres()
    cells = np.flatnonzero(floor.drivable)
    picks = rng.choice(cells, size=count, replace=cells.size < count)
    return [(Pose2D(float(x.flat[c]), float(y.flat[c]), float(rng.uniform(-math.pi, math.pi))),
             math.radians(float(rng.choice(TILTS_DEG)))) for c in picks]


def write_views(worlds: list[str], per_world: int, seed: int, out_dir: Path,
                camera: CameraConfig = CameraConfig()) -> Path:
    """Render ``per_world`` views of each world (bundled name or file) into ``out_dir``; returns the
    path of ``views.json``."""
    rng = np.random.default_rng(seed)
    intrinsics, mount = camera.intrinsics(), camera.mount()
    views = []
    for name in worlds:
        world = load_world(name)
        for pose, tilt in sample_poses(world, per_world, rng):
            folder = f"view-{len(views):04d}"
            write_preview(world, pose, 0.0, tilt, out_dir / folder, intrinsics, mount)
            views.append({"world": name, "pose": [pose.x_m, pose.y_m, math.degrees(pose.heading_rad)],
                          "tilt_deg": math.degrees(tilt), "folder": folder})
        log.info("%s: %d views", world.name, per_world)
    index = out_dir / "views.json"
    index.write_text(json.dumps({"seed": seed, "fx_px": intrinsics.fx_px, "baseline_m": mount.baseline_m,
                                 "views": views}, indent=1))
    return index

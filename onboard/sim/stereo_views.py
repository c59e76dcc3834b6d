"""``syt-onboard worlds views``: rendered stereo pairs with their true depth, to score stereo on.

The planner's stereo has Middlebury to be scored on, but the rooms it searches are rendered: their
textures tile, and a matcher that suits a photograph may not suit them. This writes a set of views
the way the robot sees a room: the head at its height, the robot on floor it could reach from the
world's start, facing anywhere, the head tilted as the navigator and the planner tilt it.
``offboard.perception.rendered_views`` scores a matcher on them (``syt-offboard bench stereo``).

Layout of the output directory: ``views.json`` (the camera and, per view, its world, pose, tilt and
folder) and one folder per view holding ``left.png``, ``right.png`` and ``depth.npy`` (float32
z-depth of the left camera, metres), as ``syt-onboard render`` writes them. Each world draws from
its own generator, seeded by the seed and the world's name, so a world's views do not depend on the
worlds listed with it.
"""

from __future__ import annotations

import functools
import json
import logging
import math
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from onboard.config import CameraConfig
from onboard.sim.preview import write_frame
from onboard.sim.render import StereoRenderer
from onboard.sim.world import load_world
from onboard.sim.world_check import reachable_floor
from shared.geometry import Pose2D
from shared.world import World

log = logging.getLogger(__name__)

TILTS_DEG = (-35.0, -25.0, 0.0, 30.0)  # the navigator's probe and look tilts, the planner's two
_world = functools.lru_cache(maxsize=None)(load_world)  # a world file is parsed and checked once


@dataclass(frozen=True)
class View:
    world: str  # bundled name or world file
    pose: Pose2D
    tilt_rad: float


def sample_views(name: str, world: World, count: int, seed: int) -> list[View]:
    """``count`` views of a world: reachable floor, any heading, one of ``TILTS_DEG``."""
    rng = np.random.default_rng([seed, zlib.crc32(name.encode())])
    floor = reachable_floor(world)
    x, y = floor.centres()
    cells = np.flatnonzero(floor.drivable)
    picks = rng.choice(cells, size=count, replace=cells.size < count)
    return [View(name, Pose2D(float(x.flat[c]), float(y.flat[c]), float(rng.uniform(-math.pi, math.pi))),
                 math.radians(float(rng.choice(TILTS_DEG)))) for c in picks]


def write_view_set(views: list[View], out_dir: Path, seed: int | None = None,
                   camera: CameraConfig = CameraConfig()) -> Path:
    """Render ``views`` into ``out_dir`` with their index; returns the path of ``views.json``."""
    intrinsics, mount = camera.intrinsics(), camera.mount()
    renderers: dict[str, StereoRenderer] = {}  # building one costs about as much as a render
    entries = []
    for k, view in enumerate(views):
        if view.world not in renderers:
            renderers[view.world] = StereoRenderer(_world(view.world), intrinsics, mount)
        folder = f"view-{k:04d}"
        write_frame(renderers[view.world].render(view.pose, 0.0, view.tilt_rad), out_dir / folder)
        entries.append({"world": view.world, "pose": [view.pose.x_m, view.pose.y_m, math.degrees(view.pose.heading_rad)],
                        "tilt_deg": math.degrees(view.tilt_rad), "folder": folder})
    index = out_dir / "views.json"
    index.write_text(json.dumps({"seed": seed, "fx_px": intrinsics.fx_px, "baseline_m": mount.baseline_m,
                                 "views": entries}, indent=1))
    return index


def write_views(worlds: list[str], per_world: int, seed: int, out_dir: Path) -> Path:
    """Sample and render ``per_world`` views of each world (bundled name or file) into ``out_dir``."""
    views = []
    for name in worlds:
        views += sample_views(name, _world(name), per_world, seed)
        log.info("%s: %d views", name, per_world)
    return write_view_set(views, out_dir, seed)

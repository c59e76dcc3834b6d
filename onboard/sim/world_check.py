"""Is a world fit for a search? The robot can drive from its start to a pose that sees the target.

The generator (``onboard.sim.world_generator``) runs this on every world before writing it:

- **drivable floor**: on a 5 cm grid, the cells whose centre keeps the navigator's clearance
  (0.31 m: the robot's radius 0.26 m plus its 5 cm margin) from the walls and from every obstacle
  standing on the floor; the robot can reach the 4-connected part that holds its start;
- **a seeing pose** among those cells: the camera within 0.6-2.5 m of the picture's centre and within
  40° of its normal, the tilt that aims at it inside the PTU-D46's limits (or the picture's centre
  still in the image at the limit), and the simulator's own renderer showing the picture there: the
  depth at its centre and at its corners drawn in by a tenth is the picture's (within 1 cm), not
  something in front of it. Those are the points SPL's yardstick asks to see in plain view
  (``shared.world.PICTURE_INSET``), so that it can score every world that passes: a picture set back
  on a high shelf, its bottom edge hidden by the shelf's front, is not.

A world that fails raises ``WorldRejected`` with the reason.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import cv2
import numpy as np

from onboard.config import CameraConfig
from onboard.sim.render import StereoRenderer
from shared.geometry import Pose2D, RigidTransform
from shared.limits import PanTiltLimits
from shared.world import PICTURE_INSET, World

# The offboard navigator's DRIVE_CLEARANCE_M (offboard.experiments.world_facts); onboard cannot import it.
DRIVE_CLEARANCE_M = 0.31
GRID_M = 0.05

Rect = tuple[tuple[float, float], tuple[float, float]]  # (x0, y0), (x1, y1) on the floor


class WorldRejected(ValueError):
    """A world the search could not be run in; the message says why."""


@dataclass(frozen=True)
class SeeingRule:
    """When a floor pose sees the target's picture."""

    near_m: float = 0.6
    far_m: float = 2.5
    max_off_normal_deg: float = 40.0
    depth_tolerance_m: float = 0.01  # the renderer's depth against the picture's: a hit, not an occluder
    image_margin_px: float = 20.0  # the picture's centre at least this far inside the image
    max_renders: int = 10  # candidate poses rendered before the world is declared unseeable
    min_start_distance_m: float = 1.0  # the start may not already be this close to the target


@dataclass(frozen=True)
class Viewpoint:
    """A pose that sees the target: robot at (x, y) facing it, pan 0, this tilt."""

    x_m: float
    y_m: float
    heading_rad: float
    tilt_rad: float
    distance_m: float  # camera to the picture's centre
    off_normal_deg: float
    renders: int  # poses rendered before this one was confirmed, itself included


@dataclass(frozen=True)
class FloorGrid:
    """Cell centres ((i + 0.5) g, (j + 0.5) g), index [i, j] = [x, y], and which cells are drivable."""

    grid_m: float
    drivable: np.ndarray  # bool (nx, ny)

    def centres(self) -> tuple[np.ndarray, np.ndarray]:
        nx, ny = self.drivable.shape
        return np.meshgrid((np.arange(nx) + 0.5) * self.grid_m, (np.arange(ny) + 0.5) * self.grid_m, indexing="ij")

    def cell(self, x_m: float, y_m: float) -> tuple[int, int]:
        nx, ny = self.drivable.shape
        return (min(max(int(x_m / self.grid_m), 0), nx - 1), min(max(int(y_m / self.grid_m), 0), ny - 1))


def rect_distance(x: np.ndarray, y: np.ndarray, rect: Rect) -> np.ndarray:
    """Distance from points to an axis-aligned rectangle (0 inside)."""
    (x0, y0), (x1, y1) = rect
    return np.hypot(np.maximum.reduce([x0 - x, np.zeros_like(x), x - x1]),
                    np.maximum.reduce([y0 - y, np.zeros_like(y), y - y1]))


def clearance_grid(room_xy: tuple[float, float], rects: Iterable[Rect], clearance_m: float,
                   grid_m: float = GRID_M) -> FloorGrid:
    """Cells whose centre keeps ``clearance_m`` from the walls and from every rectangle."""
    nx, ny = (int(math.ceil(size / grid_m - 1e-9)) for size in room_xy)
    grid = FloorGrid(grid_m, np.ones((nx, ny), bool))
    x, y = grid.centres()
    free = np.minimum.reduce([x, room_xy[0] - x, y, room_xy[1] - y]) >= clearance_m
    for rect in rects:
        free &= rect_distance(x, y, rect) >= clearance_m
    return FloorGrid(grid_m, free)


def floor_rects(world: World) -> list[Rect]:
    """Footprints of what blocks the base: floor obstacles, and the target when it stands low."""
    return [((b.min_m[0], b.min_m[1]), (b.max_m[0], b.max_m[1])) for b in world.base_blockers()]


def reachable_floor(world: World, clearance_m: float = DRIVE_CLEARANCE_M) -> FloorGrid:
    """The drivable cells the robot can reach from its start."""
    grid = clearance_grid(world.room.size_m[:2], floor_rects(world), clearance_m)
    start = grid.cell(world.start.x_m, world.start.y_m)
    if not grid.drivable[start]:
        raise WorldRejected(f"the start ({world.start.x_m:.2f}, {world.start.y_m:.2f}) is closer than "
                            f"{clearance_m} m to a wall or an obstacle")
    labels = areas(grid)
    return FloorGrid(grid.grid_m, labels == labels[start])


def areas(grid: FloorGrid) -> np.ndarray:
    """Labels (int, the grid's shape) of the 4-connected drivable areas, 0 where it is not drivable."""
    return cv2.connectedComponents(grid.drivable.astype(np.uint8), connectivity=4)[1]


def check_world(world: World, camera: CameraConfig = CameraConfig(), pantilt: PanTiltLimits = PanTiltLimits(),
                rule: SeeingRule = SeeingRule()) -> Viewpoint:
    """The pose that confirms ``world`` is fit for a search; raises ``WorldRejected`` otherwise."""
    target = world.target
    gap = math.hypot(world.start.x_m - target.position_m[0], world.start.y_m - target.position_m[1])
    if gap < rule.min_start_distance_m:
        raise WorldRejected(f"the start is {gap:.2f} m from the target (at least {rule.min_start_distance_m} m)")
    candidates = _candidate_poses(world, reachable_floor(world), camera, pantilt, rule)
    if not candidates:
        raise WorldRejected("no reachable pose has the target in range, in front of its picture and in the image")
    renderer = StereoRenderer(world, camera.intrinsics(), camera.mount())
    picks = np.unique(np.linspace(0, len(candidates) - 1, min(rule.max_renders, len(candidates))).round().astype(int))
    for tries, index in enumerate(picks, start=1):
        pose = candidates[int(index)]
        if _unoccluded(renderer, world, pose, camera, rule):
            return Viewpoint(*pose, renders=tries)
    raise WorldRejected(f"something hides the target from each of {len(picks)} rendered poses "
                        f"(of {len(candidates)} in range and angle)")


def picture_probes(world: World) -> np.ndarray:
    """Points (5, 3) on the picture: its centre, then its corners drawn in by ``PICTURE_INSET``."""
    corners = world.target.picture_corners_m()
    centre = corners.mean(axis=0)
    return np.vstack([centre, centre + PICTURE_INSET * (corners - centre)])


def _candidate_poses(world: World, floor: FloorGrid, camera: CameraConfig, pantilt: PanTiltLimits,
                     rule: SeeingRule) -> list[tuple[float, float, float, float, float, float]]:
    """Reachable (x, y, heading, tilt, distance, off-normal°) in range and angle with the picture's
    centre in the image, best first (nearest 40 % into the range, most frontal)."""
    centre, normal = picture_probes(world)[0], world.target.facing()
    x, y = (a[floor.drivable] for a in floor.centres())
    heading = np.arctan2(centre[1] - y, centre[0] - x)
    mount = camera.mount()
    head = np.stack([x + mount.forward_m * np.cos(heading), y + mount.forward_m * np.sin(heading),
                     np.full_like(x, mount.height_m)], axis=1)
    to_head = head - centre
    dist = np.linalg.norm(to_head, axis=1)
    off = np.degrees(np.arccos(np.clip(to_head @ normal / np.maximum(dist, 1e-9), -1.0, 1.0)))
    tilt = np.clip(np.arctan2(centre[2] - head[:, 2], np.hypot(*(centre[:2] - head[:, :2]).T)),
                   math.radians(pantilt.tilt_min_deg), math.radians(pantilt.tilt_max_deg))
    ok = (dist >= rule.near_m) & (dist <= rule.far_m) & (off <= rule.max_off_normal_deg)
    ideal_m = rule.near_m + 0.4 * (rule.far_m - rule.near_m)
    order = np.argsort(off[ok] / rule.max_off_normal_deg + np.abs(dist[ok] - ideal_m) / ideal_m, kind="stable")
    poses = [tuple(float(v[i]) for v in (x[ok], y[ok], heading[ok], tilt[ok], dist[ok], off[ok])) for i in order]
    return [p for p in poses if _in_image(camera, mount.camera_in_world(Pose2D(*p[:3]), 0.0, p[3]), centre,
                                          rule.image_margin_px)]


def _in_image(camera: CameraConfig, camera_in_world: RigidTransform, point: np.ndarray, margin_px: float) -> bool:
    intr = camera.intrinsics()
    u, v = intr.project(camera_in_world.inverse().apply(point[None, :]))[0]
    return bool(margin_px <= u <= intr.width_px - 1 - margin_px and margin_px <= v <= intr.height_px - 1 - margin_px)


def _unoccluded(renderer: StereoRenderer, world: World, pose: tuple[float, ...], camera: CameraConfig,
                rule: SeeingRule) -> bool:
    """Does the rendered depth at every probe of the picture match the probe's own depth?"""
    camera_in_world = camera.mount().camera_in_world(Pose2D(*pose[:3]), 0.0, pose[3])
    _, depth = renderer.render_view(camera_in_world)
    points = camera_in_world.inverse().apply(picture_probes(world))
    pixels = np.round(camera.intrinsics().project(points)).astype(int)
    height, width = depth.shape
    for (u, v), expected in zip(pixels, points[:, 2]):
        if not (0 <= u < width and 0 <= v < height) or abs(float(depth[v, u]) - expected) > rule.depth_tolerance_m:
            return False
    return True

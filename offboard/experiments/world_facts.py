"""The experimenter's world: the truth the planner never sees, and the scenarios built on it.

- :func:`load_facts`: what the harness needs of a world file, read by the one world reader
  (``shared.world``);
- :class:`Truth` and :func:`viewpoint`: which floor positions see the target (in the detector's
  range of its face, in front of it, nothing between) and the shortest collision-free path to the
  closest one: SPL's shortest path, and where the oracle baseline drives;
- :func:`target_placements`, :func:`robot_starts`: the report's Fig. 5 setup derived from any world
  (targets on its tables facing open floor, starts spread around the room);
- :func:`tables_hints`: the ``tables`` prior as a hints file for ``--prior hints:FILE``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from offboard.navigation import grid_planner
from offboard.perception.occupancy import FloorMap
from shared.strict import bounds
from shared.world import Box, load_world, resolve_world, suite_of

Vec3 = tuple[float, float, float]
Start = tuple[float, float, float]  # x, y, heading° (the agent's --start)
Placement = tuple[float, float, float, float]  # x, y, z of the bottom centre, yaw° (the agent's --target)
TABLE_KINDS = ("table", "desk")  # the surfaces of the "tables" prior and of the target placements
DRIVE_CLEARANCE_M = 0.31  # what the navigator keeps from obstacles: the robot's radius 0.26 + its margin 0.05


# --- the truth -------------------------------------------------------------------------------------

@dataclass(frozen=True)
class Obstacle:
    min_m: Vec3
    max_m: Vec3


@dataclass(frozen=True)
class Truth:
    """The real room: only the oracle and the harness's measurements read it, never the planner."""

    room_m: Vec3
    obstacles: tuple[Obstacle, ...]
    target_center_m: Vec3
    target_yaw_deg: float  # the direction its picture faces, 0 = +x, counter-clockwise
    target_depth_m: float = 0.23  # the picture is half this in front of the centre
    target_sides: int = 1  # pictured vertical faces: 1, or 4 (yaw and every quarter turn from it)

    def face_normals(self) -> list[np.ndarray]:
        yaws = [math.radians(self.target_yaw_deg + 90.0 * k) for k in range(self.target_sides)]
        return [np.array([math.cos(yaw), math.sin(yaw)]) for yaw in yaws]


@dataclass(frozen=True)
class SeeingCriteria:
    """When a floor position "sees" the target: in range of its face, in front of it, nothing between."""

    range_m: float = field(default=2.5, metadata=bounds(0.1, 20.0))  # the detector's useful range
    near_m: float = field(default=0.5, metadata=bounds(0.0, 5.0))  # closer, the face overflows the image
    max_off_normal_deg: float = field(default=60.0, metadata=bounds(0.0, 90.0))
    robot_radius_m: float = field(default=0.26, metadata=bounds(0.05, 2.0))
    robot_height_m: float = field(default=1.35, metadata=bounds(0.1, 3.0))  # lower obstacles block the base
    camera_height_m: float = field(default=1.2, metadata=bounds(0.1, 3.0))
    resolution_m: float = field(default=0.05, metadata=bounds(0.01, 0.5))


def _cell_centres(room_m: Vec3, res: float) -> tuple[np.ndarray, np.ndarray]:
    nx, ny = (int(math.ceil(room_m[a] / res - 1e-9)) for a in (0, 1))
    return np.meshgrid((np.arange(nx) + 0.5) * res, (np.arange(ny) + 0.5) * res, indexing="ij")


def true_floor_map(truth: Truth, criteria: SeeingCriteria = SeeingCriteria()) -> FloorMap:
    """The floor map of the real obstacles, inflated by the robot's radius, walls included."""
    res = criteria.resolution_m
    x, y = _cell_centres(truth.room_m, res)
    occupied = np.zeros(x.shape, bool)
    for box in truth.obstacles:
        if box.min_m[2] < criteria.robot_height_m:
            occupied |= (x >= box.min_m[0]) & (x <= box.max_m[0]) & (y >= box.min_m[1]) & (y <= box.max_m[1])
    # cell centre to the nearest occupied cell's edge (half a cell nearer than its centre)
    to_obstacle = cv2.distanceTransform((~occupied).astype(np.uint8), cv2.DIST_L2, 5) * res - res / 2
    to_wall = np.minimum.reduce([x, truth.room_m[0] - x, y, truth.room_m[1] - y])
    blocked = (to_obstacle < criteria.robot_radius_m) | (to_wall < criteria.robot_radius_m) | occupied
    return FloorMap(res, occupied, blocked, np.zeros_like(occupied))


def _segments_hit_box(p0: np.ndarray, p1: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Do the 2D segments p0 → p1[i] cross the box [lo, hi]? (slab test, vectorised over p1)"""
    d = p1 - p0
    t0, t1 = np.zeros(len(p1)), np.ones(len(p1))
    for a in (0, 1):
        parallel = np.abs(d[:, a]) < 1e-12
        inside = lo[a] <= p0[a] <= hi[a]
        with np.errstate(divide="ignore", invalid="ignore"):
            ta, tb = (lo[a] - p0[a]) / d[:, a], (hi[a] - p0[a]) / d[:, a]
        near = np.where(parallel, -np.inf if inside else np.inf, np.minimum(ta, tb))
        far = np.where(parallel, np.inf if inside else -np.inf, np.maximum(ta, tb))
        t0, t1 = np.maximum(t0, near), np.minimum(t1, far)
    return t0 <= t1


def seeing_cells(truth: Truth, floor: FloorMap, criteria: SeeingCriteria = SeeingCriteria()) -> np.ndarray:
    """Free floor cells from which the camera sees one of the target's pictures (bool, the floor map's shape)."""
    seen = np.zeros(floor.blocked.shape, bool)
    for normal in truth.face_normals():
        seen |= _seeing_face(truth, floor, criteria, normal)
    return seen


def _seeing_face(truth: Truth, floor: FloorMap, criteria: SeeingCriteria, normal: np.ndarray) -> np.ndarray:
    x, y = _cell_centres(truth.room_m, floor.resolution_m)
    face = np.array(truth.target_center_m[:2]) + normal * truth.target_depth_m / 2
    dx, dy = x - face[0], y - face[1]
    dist = np.hypot(dx, dy)
    facing = (dx * normal[0] + dy * normal[1]) >= np.cos(np.radians(criteria.max_off_normal_deg)) * dist
    ok = (dist >= criteria.near_m) & (dist <= criteria.range_m) & facing & ~floor.blocked
    # an obstacle hides the face if it spans some height between the face and the camera
    z_lo, z_hi = sorted((truth.target_center_m[2], criteria.camera_height_m))
    cells = np.stack([x[ok], y[ok]], axis=1)
    clear = np.ones(len(cells), bool)
    centre = np.array(truth.target_center_m)
    for box in truth.obstacles:
        under = box.max_m[2] <= centre[2] and np.all((centre[:2] >= box.min_m[:2]) & (centre[:2] <= box.max_m[:2]))
        if box.min_m[2] < z_hi and box.max_m[2] > z_lo and not under:  # what it stands on hides nothing
            clear &= ~_segments_hit_box(face, cells, np.array(box.min_m[:2]), np.array(box.max_m[:2]))
    ok[ok] = clear
    return ok


def viewpoint(truth: Truth, start_xy: tuple[float, float],
              criteria: SeeingCriteria = SeeingCriteria()) -> tuple[tuple[float, float] | None, float]:
    """The seeing position closest to ``start_xy`` along collision-free paths, and that path's length
    (``None, inf`` if none is reachable)."""
    floor = true_floor_map(truth, criteria)
    field_m = grid_planner.distance_field(floor, start_xy)
    cost = np.where(seeing_cells(truth, floor, criteria), field_m, np.inf)
    best = np.unravel_index(int(np.argmin(cost)), cost.shape)
    if not math.isfinite(cost[best]):
        return None, math.inf
    return grid_planner.cell_center(floor, (int(best[0]), int(best[1]))), float(cost[best])


# --- the world, as the experimenter knows it -------------------------------------------------------

@dataclass(frozen=True)
class WorldFacts:
    name: str
    path: Path
    room_m: Vec3
    obstacles: tuple[Box, ...]
    target_size_m: Vec3
    target_picture: str
    target: Placement  # the world's own
    start: Start
    target_sides: int = 1

    def tables(self) -> tuple[Box, ...]:
        return tuple(b for b in self.obstacles if b.kind in TABLE_KINDS)

    def truth(self, target: Placement) -> Truth:
        """The real room with the target placed (``target``: its bottom centre and yaw)."""
        x, y, z, yaw = target
        return Truth(self.room_m, tuple(Obstacle(b.min_m, b.max_m) for b in self.obstacles),
                     (x, y, z + self.target_size_m[2] / 2), yaw, self.target_size_m[0], self.target_sides)


def load_facts(name_or_path: str) -> WorldFacts:
    """What the harness needs of a world (a bundled name or a file), validated by the world format."""
    path = resolve_world(name_or_path)
    world = load_world(path)
    target, start = world.target, world.start
    return WorldFacts(world.name, path, world.room.size_m, world.obstacles, target.size_m, target.picture,
                      (*target.position_m, target.yaw_deg),
                      (start.x_m, start.y_m, round(math.degrees(start.heading_rad), 9)), target.sides)


# --- scenarios: where the robot starts, where the target is, what the planner is told ---------------

def _clearance_m(world: WorldFacts, face: np.ndarray, normal: np.ndarray, support: Box, cap_m: float = 1.5) -> float:
    """Free distance in front of a face along its normal, in a corridor a little wider than the target."""
    side = np.array([-normal[1], normal[0]]) * (world.target_size_m[1] / 2 + 0.05)
    camera_m = SeeingCriteria().camera_height_m  # what stands between the face and the camera's height
    blockers = [b for b in world.obstacles
                if b is not support and b.max_m[2] > support.max_m[2] and b.min_m[2] < camera_m]
    for d in np.arange(0.0, cap_m, 0.05):
        for p in (face + normal * d + side * k for k in (-1, 0, 1)):
            outside = not (0 <= p[0] <= world.room_m[0] and 0 <= p[1] <= world.room_m[1])
            if outside or any(b.min_m[0] <= p[0] <= b.max_m[0] and b.min_m[1] <= p[1] <= b.max_m[1] for b in blockers):
                return float(d)
    return cap_m


def _table_placements(world: WorldFacts, table: Box, min_clear_m: float = 0.6) -> list[Placement]:
    """On the table's top, facing out from each long side that faces open floor; along the side, the
    spot with the most clearance in front (nearest the middle among equals)."""
    long_axis = 0 if table.max_m[0] - table.min_m[0] >= table.max_m[1] - table.min_m[1] else 1
    mid = np.array([(table.min_m[a] + table.max_m[a]) / 2 for a in (0, 1)])
    along = np.arange(table.min_m[long_axis] + 0.2, table.max_m[long_axis] - 0.2 + 1e-9, 0.05)
    placements = []
    for sign in (-1.0, 1.0):
        normal = np.zeros(2)
        normal[1 - long_axis] = sign
        spots = []
        for t in along if len(along) else [mid[long_axis]]:
            centre = mid.copy()
            centre[long_axis] = t
            clear = _clearance_m(world, centre + normal * world.target_size_m[0] / 2, normal, table)
            spots.append(((clear, -abs(t - mid[long_axis])), centre))
        (clear, _), centre = max(spots, key=lambda spot: spot[0])
        if clear >= min_clear_m:
            yaw = math.degrees(math.atan2(normal[1], normal[0]))
            placements.append((round(float(centre[0]), 3), round(float(centre[1]), 3), table.max_m[2], yaw))
    return placements


def target_placements(world: WorldFacts, count: int = 4,
                      drive_clearance_m: float = DRIVE_CLEARANCE_M) -> list[Placement]:
    """Up to ``count`` placements on the world's tables, taken in turn from each table (report Fig. 5b),
    then the world's own placement if the tables offer fewer. A table placement counts only if the
    robot, with its navigation clearance, can drive from the world's start to where it sees it."""
    drive = SeeingCriteria(robot_radius_m=drive_clearance_m)
    per_table = [[p for p in _table_placements(world, t) if math.isfinite(viewpoint(world.truth(p), world.start[:2], drive)[1])]
                 for t in world.tables()]
    chosen = [world.target] if suite_of(world.path) else []  # a suite world's own target: checked, and first
    for rank in range(max((len(p) for p in per_table), default=0)):
        chosen += [p[rank] for p in per_table if rank < len(p)]
    if len(chosen) < count and world.target not in chosen:
        chosen.append(world.target)
    return chosen[:count]


def robot_starts(world: WorldFacts, count: int = 5, margin_m: float = 0.45,
                 drive_clearance_m: float = DRIVE_CLEARANCE_M) -> list[Start]:
    """The world's own start, then the free spots farthest from those already chosen (corners and
    edges first, as in the report's Fig. 5a), each heading for the room's centre. A spot keeps
    ``margin_m`` from everything and lies in the open floor the world's start lies in, as the robot
    with its navigation clearance (``drive_clearance_m``) sees it: not in a pocket it cannot leave."""
    truth = world.truth((0.0, 0.0, 0.0, 0.0))  # the target plays no part
    # candidate spots every 0.25 m, judged on the fine map (a thin partition slips between coarse cells)
    floor = true_floor_map(truth, SeeingCriteria(robot_radius_m=margin_m))
    drivable = true_floor_map(truth, SeeingCriteria(robot_radius_m=drive_clearance_m))
    reach = grid_planner.distance_field(drivable, world.start[:2])
    step = round(0.25 / floor.resolution_m)
    spots = np.argwhere(np.ones(np.array(floor.blocked.shape) // step, bool)) * step + step // 2
    ok = ~floor.blocked[spots[:, 0], spots[:, 1]] & np.isfinite(reach[spots[:, 0], spots[:, 1]])
    free = (spots[ok] + 0.5) * floor.resolution_m
    chosen = [np.array(world.start[:2])]
    while len(chosen) < count and len(free):
        gaps = np.min([np.hypot(*(free - c).T) for c in chosen], axis=0)
        chosen.append(free[int(np.argmax(gaps))])
    centre = np.array(world.room_m[:2]) / 2
    starts = [tuple(world.start)]
    for x, y in chosen[1:]:
        heading = round(math.degrees(math.atan2(centre[1] - y, centre[0] - x)) / 15) * 15
        starts.append((round(float(x), 3), round(float(y), 3), float(heading)))
    return starts


def tables_hints(world: WorldFacts, layer_m: float = 0.3, mass: float = 0.9) -> str:
    """The ``tables`` prior as a hints file: the layer just above each table top shares ``mass`` by area."""
    tables = world.tables()
    if not tables:
        raise ValueError(f"{world.name}: no obstacle of kind {' or '.join(TABLE_KINDS)} for the tables prior")
    areas = [(t.max_m[0] - t.min_m[0]) * (t.max_m[1] - t.min_m[1]) for t in tables]
    lines = [f"# the target is on one of the tables of {world.name}: {mass:g} of the mass just above their tops"]
    for table, area in zip(tables, areas):
        top = min(table.max_m[2] + layer_m, world.room_m[2])
        lines += ["[[hint]]", f'name = "{table.name}"',
                  f"min = [{table.min_m[0]:g}, {table.min_m[1]:g}, {table.max_m[2]:g}]",
                  f"max = [{table.max_m[0]:g}, {table.max_m[1]:g}, {top:g}]",
                  f"weight = {mass * area / sum(areas):.6f}", ""]
    return "\n".join(lines)



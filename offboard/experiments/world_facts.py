"""The experimenter's world: the truth the planner never sees, and the scenarios built on it.

- :func:`load_facts`: what the harness needs of a world file, read by the one world reader
  (``shared.world``);
- :class:`Truth` and :func:`viewpoint`: which floor positions see the target (in the detector's
  range of its face, in front of it, nothing between) and the shortest collision-free path to the
  closest one: SPL's shortest path, and where the oracle baseline drives;
- :func:`target_placements`, :func:`robot_starts`: the report's Fig. 5 setup derived from any world
  (targets on its tables facing open floor, starts spread around the room);
- :func:`tables_hints`: the ``tables`` (knowledge) prior as a hints file for ``--prior hints:FILE``.
"""

from __future__ import annotations

import math
import subprocess
import sys
from dataclasses import dataclass, field, replace
from pathlib import Path

import cv2
import numpy as np

from offboard.navigation import grid_planner
from offboard.perception.detectability import DetectabilityTable, face_size_m, facing_angle_deg
from offboard.perception.detection.detector import shipped_table
from offboard.perception.occupancy import FloorMap
from shared import toml_writer
from shared.geometry import HeadMount
from shared.limits import PanTiltLimits
from shared.strict import bounds
from shared.world import PICTURE_INSET, Box, WorldError, is_bundled_room, load_world, resolve_world, support_of

Vec3 = tuple[float, float, float]
Start = tuple[float, float, float]  # x, y, heading° (the agent's --start)
Placement = tuple[float, float, float, float]  # x, y, z of the bottom centre, yaw° (the agent's --target)
TABLE_KINDS = ("table", "desk")  # the surfaces of the "tables" prior and of the target placements
DRIVE_CLEARANCE_M = 0.31  # what the navigator keeps from obstacles: the robot's radius 0.26 + its margin 0.05
ARRIVAL_MARGIN_M = 0.25  # how far from where it was sent a robot may stop (the oracle's "arrived")


# --- the simulator's command line -------------------------------------------------------------------

def simulator_refuses(*args: str) -> str:
    """Run the simulator's command line (``syt-onboard ARGS``) in its own process, since this side never
    imports the simulator: "" if it succeeded, else the reasons it logged as errors ("; " between them),
    or its exit status if it logged none."""
    done = subprocess.run([sys.executable, "-m", "onboard.cli", *args], capture_output=True, text=True)
    if done.returncode == 0:
        return ""
    reasons = [line.split(" ERROR ", 1)[1].split(": ", 1)[-1] for line in done.stderr.splitlines()
               if " ERROR " in line]
    return "; ".join(reasons) or done.stderr.strip() or f"exit {done.returncode}"


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
    target_height_m: float = 0.23  # the picture's height
    target_width_m: float = 0.23  # and width

    @property
    def face_size_m(self) -> float:
        return face_size_m(self.target_width_m, self.target_height_m)

    def face_normals(self) -> list[np.ndarray]:
        yaws = [math.radians(self.target_yaw_deg + 90.0 * k) for k in range(self.target_sides)]
        return [np.array([math.cos(yaw), math.sin(yaw)]) for yaw in yaws]

    def face_centre(self, normal: np.ndarray) -> np.ndarray:
        """The 3D centre of the picture whose horizontal normal is ``normal``."""
        x, y, z = self.target_center_m
        half = self.target_depth_m / 2
        return np.array([x + normal[0] * half, y + normal[1] * half, z])

    def picture_points(self, normal: np.ndarray, inset: float = PICTURE_INSET) -> np.ndarray:
        """The picture's centre and its corners drawn in by ``inset`` (5, 3): what must be in plain view
        (the bottom corners then clear the surface the target stands on)."""
        centre = self.face_centre(normal)
        across = np.array([-normal[1], normal[0], 0.0]) * self.target_width_m / 2 * inset
        up = np.array([0.0, 0.0, self.target_height_m / 2 * inset])
        return np.array([centre] + [centre + a * across + b * up for a in (-1, 1) for b in (-1, 1)])


def detector_table(detector: str = "sift") -> DetectabilityTable:
    """The detectability table shipped for ``detector``: the one the searches of the bundled target load."""
    if (table := shipped_table(detector)) is None:
        raise ValueError(f"no detectability table is shipped for detector {detector!r}")
    return table


@dataclass(frozen=True)
class SeeingCriteria:
    """When a floor position "sees" the target: with the camera aimed at the picture as well as the
    tilt limits allow, the detector's measured rate (by distance, angle off the optical axis and angle
    off the picture's normal) is at least ``min_rate``, the whole picture fits in the image, and no
    obstacle crosses the lines from the camera to the picture's centre and its corners drawn in by a tenth
    (:meth:`Truth.picture_points`). The range, the nearest distance
    and the widest angle off the normal follow from the table (:attr:`range_m`, :attr:`near_m`,
    :attr:`max_off_normal_deg`). The table is for the face size it was measured with;
    :func:`seeing_cells` rescales it to the target's (direct callers of :meth:`rate` must too).

    The camera stands on the head's axis, where the shipped tables were measured from; the planner's
    left camera sits half the stereo baseline (6 cm) aside. A review (session 53) found that offset
    changes 0-3 % of the seeing (cell, face) pairs of three targets each in `office` and `paper-lab`."""

    table: DetectabilityTable = field(default_factory=detector_table, compare=False)
    min_rate: float = field(default=0.8, metadata=bounds(0.0, 1.0))  # "the detector reliably finds it"
    robot_radius_m: float = field(default=0.26, metadata=bounds(0.05, 2.0))
    robot_height_m: float = field(default=1.35, metadata=bounds(0.1, 3.0))  # lower obstacles block the base
    camera_height_m: float = field(default=HeadMount().height_m, metadata=bounds(0.1, 3.0))  # the tilt axis
    tilt_min_deg: float = field(default=PanTiltLimits().tilt_min_deg, metadata=bounds(-90.0, 0.0))
    tilt_max_deg: float = field(default=PanTiltLimits().tilt_max_deg, metadata=bounds(0.0, 90.0))
    vertical_half_fov_deg: float = field(default=26.0, metadata=bounds(1.0, 89.0))  # 640 × 480 at 66° across
    resolution_m: float = field(default=0.05, metadata=bounds(0.01, 0.5))

    def _reliable_bins(self, axis: int) -> np.ndarray:
        """Bins along ``axis`` of the table (0: distance, 2: off the normal) with a cell ≥ ``min_rate``."""
        return np.nonzero(self.table.rate.max(axis=tuple(a for a in range(3) if a != axis)) >= self.min_rate)[0]

    @property
    def range_m(self) -> float:
        """The farthest distance at which the detector reliably finds the target (0: nowhere)."""
        bins = self._reliable_bins(0)
        return float(self.table.distance_edges_m[bins[-1] + 1]) if bins.size else 0.0

    @property
    def near_m(self) -> float:
        bins = self._reliable_bins(0)
        return float(self.table.distance_edges_m[bins[0]]) if bins.size else 0.0

    @property
    def max_off_normal_deg(self) -> float:
        bins = self._reliable_bins(2)
        return float(self.table.facing_edges_deg[bins[-1] + 1]) if bins.size else 0.0

    def rate(self, camera_xy: np.ndarray, face: np.ndarray, normal: np.ndarray, picture_height_m: float) -> np.ndarray:
        """The detector's rate from cameras at ``camera_xy`` (n, 2) on the picture centred at ``face``
        (3D) facing ``normal``, the camera aimed at it as well as the tilt limits allow; 0 where the
        picture does not fit in the image."""
        to_face = face[:2] - camera_xy
        flat_m = np.hypot(to_face[:, 0], to_face[:, 1])
        rise_m = face[2] - self.camera_height_m
        distance = np.hypot(flat_m, rise_m)
        elevation = np.degrees(np.arctan2(rise_m, flat_m))
        # what the tilt cannot reach stays off the optical axis (a high shelf close by)
        off_axis = np.abs(elevation - np.clip(elevation, self.tilt_min_deg, self.tilt_max_deg))
        fits = off_axis + np.degrees(np.arctan2(picture_height_m / 2, distance)) <= self.vertical_half_fov_deg
        facing = facing_angle_deg(np.arctan2(to_face[:, 1], to_face[:, 0]), math.atan2(normal[1], normal[0]),
                                  np.radians(elevation))
        return np.where(fits, self.table.lookup(distance, off_axis, facing), 0.0)


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


def segments_hit_box(p0: np.ndarray, p1: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Do the segments p0 → p1[i] cross the box [lo, hi]? (slab test in as many dimensions as p0 has,
    vectorised over p1)"""
    d = p1 - p0
    t0, t1 = np.zeros(len(p1)), np.ones(len(p1))
    for a in range(len(p0)):
        parallel = np.abs(d[:, a]) < 1e-12
        inside = lo[a] <= p0[a] <= hi[a]
        with np.errstate(divide="ignore", invalid="ignore"):
            ta, tb = (lo[a] - p0[a]) / d[:, a], (hi[a] - p0[a]) / d[:, a]
        near = np.where(parallel, -np.inf if inside else np.inf, np.minimum(ta, tb))
        far = np.where(parallel, np.inf if inside else -np.inf, np.maximum(ta, tb))
        t0, t1 = np.maximum(t0, near), np.minimum(t1, far)
    return t0 <= t1


def seeing_cells(truth: Truth, floor: FloorMap, criteria: SeeingCriteria = SeeingCriteria()) -> np.ndarray:
    """Free floor cells from which the camera sees one of the target's pictures (bool, the floor map's shape),
    by the criteria's table rescaled to the target's size."""
    criteria = replace(criteria, table=criteria.table.for_face(truth.face_size_m))
    seen = np.zeros(floor.blocked.shape, bool)
    for normal in truth.face_normals():
        seen |= _seeing_face(truth, floor, criteria, normal)
    return seen


def _seeing_face(truth: Truth, floor: FloorMap, criteria: SeeingCriteria, normal: np.ndarray) -> np.ndarray:
    x, y = _cell_centres(truth.room_m, floor.resolution_m)
    face = truth.face_centre(normal)
    ok = ~floor.blocked & (np.hypot(x - face[0], y - face[1]) <= criteria.range_m)
    cells = np.stack([x[ok], y[ok]], axis=1)
    sees = criteria.rate(cells, face, normal, truth.target_height_m) >= criteria.min_rate
    # lines of sight in 3D from the camera to the picture's centre and corners: all of it in plain view (a
    # table top below them hides nothing; a shelf's front edge above a camera close below does)
    cameras = np.column_stack([cells, np.full(len(cells), criteria.camera_height_m)])
    for point in truth.picture_points(normal):
        for box in truth.obstacles:
            sees[sees] &= ~segments_hit_box(point, cameras[sees], np.array(box.min_m), np.array(box.max_m))
    ok[ok] = sees
    return ok


def viewpoint(truth: Truth, start_xy: tuple[float, float], criteria: SeeingCriteria = SeeingCriteria(),
              margin_m: float = 0.0, avoid: tuple[tuple[float, float], ...] = (),
              avoid_m: float = 0.0) -> tuple[tuple[float, float] | None, float]:
    """The seeing position closest to ``start_xy`` along collision-free paths, and that path's length
    (``None, inf`` if none is reachable; ``start_xy, 0`` if the start's own cell sees it). Paths are
    any-angle (:func:`~offboard.navigation.grid_planner.any_angle_field`): the robot straightens its
    own, so grid steps (up to 8 % longer) would set SPL's yardstick past what it can drive. With
    ``margin_m``, only positions whose every free neighbour within that distance sees the target too:
    a robot that stops a little off still sees it.
    Positions within ``avoid_m`` of a point of ``avoid`` (viewpoints already tried) do not count."""
    floor = true_floor_map(truth, criteria)
    seen = seeing_cells(truth, floor, criteria)
    if margin_m > 0:
        radius = int(math.ceil(margin_m / floor.resolution_m))
        disk = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius + 1, 2 * radius + 1))
        seen &= cv2.erode((seen | floor.blocked).astype(np.uint8), disk, borderValue=1).astype(bool)
    if avoid:
        cells = np.argwhere(seen)
        centres = grid_planner.cell_centers(floor, cells)
        near = [np.hypot(*(centres - point).T) <= avoid_m for point in avoid]
        seen[tuple(cells[np.any(near, axis=0)].T)] = False
    if seen[grid_planner.cell_of(floor, start_xy)]:
        # the start's own cell sees it: the robot needs no drive at all (not the few mm to the cell's centre)
        return start_xy, 0.0
    field_m = grid_planner.any_angle_field(floor, start_xy)
    cost = np.where(seen, field_m, np.inf)
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

    def support(self, target: Placement) -> Box | None:
        """The obstacle the target stands on (``None``: the floor)."""
        x, y, z, _ = target
        return support_of(self.obstacles, x, y, z)

    def picture_file(self, folder: Path) -> Path:
        """The target's picture as a file the planner can read: the world's own image, else the
        simulator's built-in picture of that name, written into ``folder``; :class:`WorldError` with the
        simulator's reason if it cannot draw one."""
        own = self.path.parent / self.target_picture
        if own.is_file():
            return own
        folder.mkdir(parents=True, exist_ok=True)
        out = folder / f"{Path(self.target_picture).stem}.png"  # named as built: two worlds' may share a name
        refused = simulator_refuses("picture", Path(self.target_picture).stem, "--out", str(out))
        if refused:
            raise WorldError(f"its target picture: {refused}")
        return out

    def knowledge_surfaces(self) -> tuple[Box, ...]:
        """Where the knowledge prior says the target is: on a table, or on a surface of the kind the
        world's own target stands on (a generated world's shelf or counter)."""
        own = self.support(self.target)
        kinds = set(TABLE_KINDS) | ({own.kind} if own else set())
        return tuple(b for b in self.obstacles if b.kind in kinds)

    def truth(self, target: Placement) -> Truth:
        """The real room with the target placed (``target``: its bottom centre and yaw)."""
        x, y, z, yaw = target
        return Truth(self.room_m, tuple(Obstacle(b.min_m, b.max_m) for b in self.obstacles),
                     (x, y, z + self.target_size_m[2] / 2), yaw, self.target_size_m[0], self.target_sides,
                     self.target_size_m[2], self.target_size_m[1])


def parse_placement(text: str) -> Placement:
    """A target placement as results.csv writes it, ``x,y,z,yaw``; a ValueError naming it otherwise."""
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 4 or not all(math.isfinite(v) for v in values):
        raise ValueError(f"target {text!r} is not x,y,z,yaw")
    return values


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
    camera_m = HeadMount().height_m  # what stands between the face and the camera's height
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
    """Up to ``count`` placements: the world's own target first (a suite's or a user's room is searched
    for the target it declares, wherever the file lies), then the world's tables', taken in turn from
    each table (report Fig. 5b); fewer than ``count`` if that is all there is. The rooms bundled beside
    ``paper-lab`` keep the report's scenarios: their tables' first, their own target last, and only if
    the tables offer fewer. A table placement counts only if the robot, with its navigation clearance,
    can drive from the world's start to where it sees the target, with room to stop
    :data:`ARRIVAL_MARGIN_M` off."""
    drive = SeeingCriteria(robot_radius_m=drive_clearance_m)
    per_table = [[p for p in _table_placements(world, t)
                  if math.isfinite(viewpoint(world.truth(p), world.start[:2], drive, ARRIVAL_MARGIN_M)[1])]
                 for t in world.tables()]
    chosen = [] if is_bundled_room(world.path) else [world.target]
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
        if gaps.max() <= 0.0:  # every free spot chosen: a small room has fewer starts, none twice
            break
        chosen.append(free[int(np.argmax(gaps))])
    centre = np.array(world.room_m[:2]) / 2
    starts = [tuple(world.start)]
    for x, y in chosen[1:]:
        heading = round(math.degrees(math.atan2(centre[1] - y, centre[0] - x)) / 15) * 15
        starts.append((round(float(x), 3), round(float(y), 3), float(heading)))
    return starts


def tables_hints(world: WorldFacts, layer_m: float = 0.3, mass: float = 0.99) -> str:
    """The ``tables`` (knowledge) prior as a hints file: the layer just above each of the world's
    :meth:`~WorldFacts.knowledge_surfaces` holds the same share of ``mass``.

    The knowledge is the report's "the target is on one of the tables": which pieces, not where on
    them. So each piece is equally likely, whatever its size; sharing by area would send the robot
    to the largest tops first and leave a small crate for last.

    The knowledge is true here (the surfaces include the target's own), so it is nearly all the mass;
    the rest, spread over the room, lets a search go on where the map misplaces a top. Tuned on `dev`
    (cost 3, four starts a room, seed 0): 0.99 against 0.9 gained 0.028 of SPL (standard error 0.018)
    and 1.7 looks (docs/search-experiments.md, "How sure the knowledge is")."""
    tables = world.knowledge_surfaces()
    if not tables:
        raise ValueError(f"{world.name}: no table, desk or surface under its target for the tables prior")
    kinds = " or ".join(sorted({t.kind for t in tables}))
    hints = [{"name": t.name, "min": [float(t.min_m[0]), float(t.min_m[1]), float(t.max_m[2])],
              "max": [float(t.max_m[0]), float(t.max_m[1]), round(min(t.max_m[2] + layer_m, world.room_m[2]), 6)],
              "weight": round(mass / len(tables), 6)} for t in tables]
    about = (f"the target is on a {kinds} of {world.name}: {mass:g} of the mass just above their tops, "
             "the same on each")
    return toml_writer.comment(about) + toml_writer.dumps({"hint": hints})  # both escape what the names hold


"""The world format: a closed box-shaped room, box obstacles, the target, posters, the robot start.

One reader for every user of world files: the simulator renders and moves in them (and adds its own
checks of textures and pictures, ``onboard.sim.world``), the experiment harness reads the truth the
planner never sees. The planner itself never reads a world.

World files are TOML (a contract other tools write; ``shared/worlds`` bundles four, the suites
``dev`` and ``test`` of generated rooms, and ``hand`` of rooms written by hand)::

    name = "paper-lab"
    [room]
    size = [9.0, 5.0, 2.5]        # metres along x, y, z; the room spans [0, size] on each axis
    texture = "brick"             # optional, walls; floor_texture / ceiling_texture optional too

    [[obstacle]]                  # any number of axis-aligned boxes
    name = "table-1"
    kind = "table"                # optional free label (default "box"); picks the default texture
    min = [1.0, 3.2, 0.0]
    max = [2.2, 4.0, 0.75]
    texture = "wood"              # optional

    [target]
    picture = "target.png"        # optional (default "target"): built-in picture or image path
    size = [0.23, 0.23, 0.23]     # box extents along x, y, z before yaw, metres
    position = [1.6, 3.6, 0.75]   # centre of the target's bottom face, on the floor or on the top
                                  # of an obstacle under that centre (nothing floats)
    yaw_deg = -90                 # optional (default 0): direction its picture faces, 0 = +x, CCW
    sides = 1                     # optional (default 1): pictured sides, 1 (the face yaw points to)
                                  # or 4 (every vertical face: recognisable from any direction;
                                  # size[0] == size[1], since every face must show the same picture)

    [robot]
    start = [4.5, 0.6]            # x, y
    heading_deg = 90              # optional (default 0)

Extension: ``[[poster]]`` tables place flat pictures (distractors for the detector): ``name``,
``picture``, ``center = [x, y, z]`` (centre of the picture), ``size = [width, height]`` in metres,
``yaw_deg`` (optional, direction the picture faces). A poster may hang flat on a wall: its
rectangle only has to lie inside the room.

Textures and pictures are names here; the simulator checks that it can render them.

Everything is validated on load and again by ``World.with_start`` / ``World.with_target``; a
mistake raises ``WorldError`` whose message starts with the offending key, e.g.
``obstacle[2].max: ...`` (indices count from 0). Obstacles whose bottom is below
``FLOOR_OBSTACLE_MAX_Z_M`` stand on the floor and block the robot base; higher ones (wall shelves)
do not.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Iterable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from shared import toml_writer
from shared.geometry import Pose2D
from shared.strict import finite_float

WORLDS_DIR = Path(__file__).parent / "worlds"
FLOOR_OBSTACLE_MAX_Z_M = 1.5
DEFAULT_ROBOT_RADIUS_M = 0.26
MAX_ROOM_SIDE_M = 100.0  # a building's floor, well inside the wire's poses; the planner holds its region to it
PICTURE_INSET = 0.9  # a picture is in plain view when its centre and its corners drawn in by this are:
# the simulator's world check probes these points, and SPL's yardstick asks for them
_TOL_M = 1e-3  # contact tolerance: resting on a surface or touching a wall is not an overlap

Vec3 = tuple[float, float, float]


class WorldError(ValueError):
    """An invalid world file or override; the message names the key and the problem."""


@dataclass(frozen=True)
class Box:
    name: str
    kind: str
    min_m: Vec3
    max_m: Vec3
    texture: str | None


@dataclass(frozen=True)
class Room:
    size_m: Vec3
    texture: str | None
    floor_texture: str | None
    ceiling_texture: str | None


def _yawed_frame(yaw_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors (forward, left) of a frame yawed by ``yaw_deg`` about world z."""
    yaw = math.radians(yaw_deg)
    return np.array([math.cos(yaw), math.sin(yaw), 0.0]), np.array([-math.sin(yaw), math.cos(yaw), 0.0])


def _picture_corners(center: np.ndarray, yaw_deg: float, width: float, height: float) -> np.ndarray:
    """Corners (4, 3) of an upright picture facing ``yaw_deg``: top-left, top-right, bottom-right,
    bottom-left as a viewer facing the picture sees them (the viewer's right is the picture's left
    axis, because the viewer looks back along the facing direction)."""
    _, left = _yawed_frame(yaw_deg)
    right, up = left * (width / 2.0), np.array([0.0, 0.0, height / 2.0])
    return np.stack([center - right + up, center + right + up, center + right - up, center - right - up])


@dataclass(frozen=True)
class Target:
    picture: str
    size_m: Vec3
    position_m: Vec3  # centre of the bottom face
    yaw_deg: float
    sides: int = 1  # pictured vertical faces: 1 (the one yaw points to) or 4

    def center_m(self) -> np.ndarray:
        return np.array(self.position_m) + np.array([0.0, 0.0, self.size_m[2] / 2.0])

    def facing(self) -> np.ndarray:
        """Unit vector (3,) along which the picture faces."""
        return _yawed_frame(self.yaw_deg)[0]

    def picture_corners_m(self) -> np.ndarray:
        """Corners (4, 3) of the picture face: top-left, top-right, bottom-right, bottom-left."""
        face_center = self.center_m() + self.facing() * (self.size_m[0] / 2.0)
        return _picture_corners(face_center, self.yaw_deg, self.size_m[1], self.size_m[2])

    def footprint_corners_m(self) -> np.ndarray:
        """Corners (4, 2) of the yawed box seen from above."""
        forward, left = _yawed_frame(self.yaw_deg)
        c = np.array(self.position_m[:2])
        hx, hy = forward[:2] * self.size_m[0] / 2.0, left[:2] * self.size_m[1] / 2.0
        return np.stack([c + hx + hy, c - hx + hy, c - hx - hy, c + hx - hy])

    def box(self) -> Box:
        """Axis-aligned bounding box of the yawed target."""
        corners = self.footprint_corners_m()
        z0 = self.position_m[2]
        lo, hi = corners.min(axis=0), corners.max(axis=0)
        return Box("target", "target", (float(lo[0]), float(lo[1]), z0),
                   (float(hi[0]), float(hi[1]), z0 + self.size_m[2]), None)


@dataclass(frozen=True)
class Poster:
    name: str
    picture: str
    center_m: Vec3
    size_m: tuple[float, float]  # width, height
    yaw_deg: float

    def picture_corners_m(self) -> np.ndarray:
        """Corners (4, 3): top-left, top-right, bottom-right, bottom-left."""
        return _picture_corners(np.array(self.center_m), self.yaw_deg, *self.size_m)


@dataclass(frozen=True)
class World:
    name: str
    room: Room
    obstacles: tuple[Box, ...]
    target: Target
    posters: tuple[Poster, ...]
    start: Pose2D
    base_dir: Path  # folder of the world file, for relative picture paths
    robot_radius_m: float = DEFAULT_ROBOT_RADIUS_M  # used to validate the start pose

    def with_start(self, x_m: float, y_m: float, heading_rad: float) -> World:
        _check_numbers("robot.start", (x_m, y_m, heading_rad))
        world = replace(self, start=Pose2D(float(x_m), float(y_m), float(heading_rad)))
        _validate(world)
        return world

    def with_target(self, x_m: float, y_m: float, z_m: float, yaw_deg: float) -> World:
        """Move the target; ``(x_m, y_m, z_m)`` is the centre of its bottom face."""
        _check_numbers("target.position", (x_m, y_m, z_m, yaw_deg))
        target = replace(self.target, position_m=(float(x_m), float(y_m), float(z_m)),
                         yaw_deg=float(yaw_deg))
        world = replace(self, target=target)
        _validate(world)
        return world

    def floor_obstacles(self) -> tuple[Box, ...]:
        """Obstacles standing on the floor (they block the robot base)."""
        return tuple(b for b in self.obstacles if b.min_m[2] < FLOOR_OBSTACLE_MAX_Z_M)

    def base_blockers(self, height_m: float = FLOOR_OBSTACLE_MAX_Z_M) -> tuple[Box, ...]:
        """What a base this tall runs into: the obstacles, and the target (on the floor, say), whose
        bottom lies below ``height_m``."""
        return tuple(b for b in (*self.obstacles, self.target.box()) if b.min_m[2] < height_m)


def bundled_world_names() -> list[str]:
    return sorted(p.stem for p in WORLDS_DIR.glob("*.toml"))


def suite_names() -> list[str]:
    """The bundled suites: folders of ``shared/worlds`` holding world files (``dev``, ``hand``, ``test``)."""
    return sorted(p.name for p in WORLDS_DIR.iterdir() if p.is_dir() and any(p.glob("*.toml")))


def suite_worlds(name: str) -> list[Path]:
    """The world files of a bundled suite, sorted."""
    if name not in suite_names():
        raise WorldError(f"{name}: no such world suite (suites: {', '.join(suite_names())})")
    return folder_worlds(WORLDS_DIR / name)


def expand_suites(names: Iterable[str]) -> tuple[str, ...]:
    """World names and files with every suite name replaced by the names of its worlds
    (``test`` → ``test/room-2000-0``, ...: bundled names that ``load_world`` takes anywhere) and every
    folder by its world files (rooms of one's own, such as ``worlds generate --out DIR`` writes)."""
    suites = suite_names()
    expanded: list[str] = []
    for name in names:
        if name in suites and not Path(name).is_file():
            expanded += [f"{name}/{path.stem}" for path in suite_worlds(name)]
        elif Path(name).is_dir():
            expanded += [str(path) for path in folder_worlds(Path(name))]
        else:
            expanded.append(name)
    return tuple(expanded)


def folder_worlds(folder: Path) -> list[Path]:
    """The world files (``*.toml``) of a folder, sorted; refused if it holds none."""
    worlds = sorted(folder.glob("*.toml"))
    if not worlds:
        raise WorldError(f"{folder}: a folder with no world files (*.toml) in it")
    return worlds


def _is_bundled_name(name: str) -> bool:
    """``NAME`` (a bundled world) or ``SUITE/NAME`` (a world of a bundled suite)."""
    parts = name.split("/")
    return len(parts) == 1 or (len(parts) == 2 and parts[0] in suite_names())


def is_bundled_room(path: str | Path) -> bool:
    """Whether a world file is one of the rooms bundled beside ``paper-lab`` (not a suite's, not a user's)."""
    return Path(path).resolve().parent == WORLDS_DIR.resolve()


def load_world(path_or_name: str | Path, *, robot_radius_m: float = DEFAULT_ROBOT_RADIUS_M) -> World:
    """Load a bundled world by name (``"paper-lab"``, ``"test/room-2000-0"``) or a world file by path."""
    path = resolve_world(path_or_name)
    try:
        text = path.read_text(encoding="utf-8-sig")  # an editor's byte-order mark is no TOML statement
    except (OSError, UnicodeDecodeError) as exc:
        raise WorldError(f"{path}: cannot read world file ({exc})") from exc
    try:
        data = tomllib.loads(text)
    except (ValueError, RecursionError) as exc:  # TOMLDecodeError carries "(at line L, column C)";
        # tomllib also raises ValueError for an integer of over 4300 digits, RecursionError for deep nesting
        raise WorldError(f"{path}: TOML syntax error: {exc}") from exc
    try:
        return parse_world(data, path.parent, robot_radius_m=robot_radius_m)
    except WorldError as exc:
        raise WorldError(f"{exc} [in {path}]") from exc


def resolve_world(path_or_name: str | Path) -> Path:
    """The file of a world given by path or by bundled name."""
    path = Path(path_or_name)
    if path.is_file():
        return path
    bundled = WORLDS_DIR / f"{path_or_name}.toml"
    if isinstance(path_or_name, str) and _is_bundled_name(path_or_name) and bundled.is_file():
        return bundled
    raise WorldError(
        f"{path_or_name}: no such world file and no bundled world of that name "
        f"(bundled: {', '.join(bundled_world_names())})"
    )


# ----------------------------------------------------------------------------- parsing

_TOP_KEYS = ({"name", "room", "target", "robot"}, {"obstacle", "poster"})
_ROOM_KEYS = ({"size"}, {"texture", "floor_texture", "ceiling_texture"})
_OBSTACLE_KEYS = ({"name", "min", "max"}, {"kind", "texture"})
_TARGET_KEYS = ({"size", "position"}, {"picture", "yaw_deg", "sides"})
_ROBOT_KEYS = ({"start"}, {"heading_deg"})
_POSTER_KEYS = ({"name", "picture", "center", "size"}, {"yaw_deg"})


def parse_world(data: dict[str, Any], base_dir: Path, *,
                robot_radius_m: float = DEFAULT_ROBOT_RADIUS_M) -> World:
    """Build and validate a World from parsed TOML; raises ``WorldError``."""
    _check_keys(data, "", _TOP_KEYS)
    room_t, target_t, robot_t = (_table(data[k], k) for k in ("room", "target", "robot"))
    _check_keys(room_t, "room", _ROOM_KEYS)
    _check_keys(target_t, "target", _TARGET_KEYS)
    _check_keys(robot_t, "robot", _ROBOT_KEYS)
    room = Room(
        _vector(room_t["size"], "room.size", 3, positive=True),
        *(_texture(room_t.get(k), f"room.{k}") for k in ("texture", "floor_texture", "ceiling_texture")),
    )
    target = Target(
        _string(target_t.get("picture", "target"), "target.picture"),
        _vector(target_t["size"], "target.size", 3, positive=True),
        _vector(target_t["position"], "target.position", 3),
        _number(target_t.get("yaw_deg", 0.0), "target.yaw_deg"),
        _sides(target_t.get("sides", 1)),
    )
    start_xy = _vector(robot_t["start"], "robot.start", 2)
    heading = math.radians(_number(robot_t.get("heading_deg", 0.0), "robot.heading_deg"))
    world = World(
        name=_string(data["name"], "name"),
        room=room,
        obstacles=tuple(_obstacle(t, f"obstacle[{i}]") for i, t in enumerate(_tables(data, "obstacle"))),
        target=target,
        posters=tuple(_poster(t, f"poster[{i}]") for i, t in enumerate(_tables(data, "poster"))),
        start=Pose2D(start_xy[0], start_xy[1], heading),
        base_dir=Path(base_dir),
        robot_radius_m=_vector([robot_radius_m], "robot_radius_m", 1, positive=True)[0],
    )
    _validate(world)
    return world


def _obstacle(table: dict[str, Any], key: str) -> Box:
    _check_keys(table, key, _OBSTACLE_KEYS)
    return Box(
        _string(table["name"], f"{key}.name"),
        _string(table.get("kind", "box"), f"{key}.kind"),
        _vector(table["min"], f"{key}.min", 3),
        _vector(table["max"], f"{key}.max", 3),
        _texture(table.get("texture"), f"{key}.texture"),
    )


def _poster(table: dict[str, Any], key: str) -> Poster:
    _check_keys(table, key, _POSTER_KEYS)
    return Poster(
        _string(table["name"], f"{key}.name"),
        _string(table["picture"], f"{key}.picture"),
        _vector(table["center"], f"{key}.center", 3),
        _vector(table["size"], f"{key}.size", 2, positive=True),  # type: ignore[arg-type]
        _number(table.get("yaw_deg", 0.0), f"{key}.yaw_deg"),
    )


def _check_keys(table: dict[str, Any], prefix: str, keys: tuple[set[str], set[str]]) -> None:
    required, optional = keys
    dot = f"{prefix}." if prefix else ""
    for key in table:
        if key not in required | optional:
            known = ", ".join(sorted(required | optional))
            raise WorldError(f"{dot}{key}: unknown key (known keys here: {known})")
    for key in sorted(required):
        if key not in table:
            raise WorldError(f"{dot}{key}: missing required key")


def _table(value: Any, key: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise WorldError(f"{key}: must be a table ([{key}]), got {type(value).__name__}")
    return value


def _tables(data: dict[str, Any], key: str) -> list[dict[str, Any]]:
    value = data.get(key, [])
    if not isinstance(value, list) or not all(isinstance(t, dict) for t in value):
        raise WorldError(f"{key}: must be an array of tables ([[{key}]])")
    return value


def _string(value: Any, key: str) -> str:
    if not isinstance(value, str) or not value:
        raise WorldError(f"{key}: must be a non-empty string, got {value!r}")
    return value


def _number(value: Any, key: str) -> float:
    try:
        return finite_float(value)
    except ValueError as exc:
        raise WorldError(f"{key}: {exc}, got {value!r}") from None


def _sides(value: Any) -> int:
    if isinstance(value, bool) or value not in (1, 4):
        raise WorldError(f"target.sides: must be 1 or 4 (pictured vertical faces), got {value!r}")
    return int(value)


def _check_numbers(key: str, values: tuple[Any, ...]) -> None:
    for value in values:
        _number(value, key)


def _vector(value: Any, key: str, n: int, *, positive: bool = False) -> Vec3:
    if not isinstance(value, list) or len(value) != n:
        raise WorldError(f"{key}: must be a list of {n} numbers, got {value!r}")
    numbers = tuple(_number(v, key) for v in value)
    if positive and min(numbers) <= 0.0:
        raise WorldError(f"{key}: every size must be positive, got {list(numbers)}")
    return numbers  # type: ignore[return-value]


def _texture(value: Any, key: str) -> str | None:
    if value is None:
        return None
    return _string(value, key)


# ----------------------------------------------------------------------------- writing


def world_toml(data: dict[str, Any], comment: str = "") -> str:
    """World data (what ``parse_world`` reads) as TOML text, under ``comment`` as ``#`` lines."""
    return toml_writer.comment(comment) + toml_writer.dumps(data)


# ----------------------------------------------------------------------------- validation


def _validate(world: World) -> None:
    size = np.array(world.room.size_m)
    if np.any(size > MAX_ROOM_SIDE_M):
        raise WorldError(f"room.size: every side must be at most {MAX_ROOM_SIDE_M:g} m (got {_listed(size)})")
    for i, box in enumerate(world.obstacles):
        key = f"obstacle[{i}]"
        lo, hi = np.array(box.min_m), np.array(box.max_m)
        if np.any(hi <= lo):
            raise WorldError(f"{key}.max: max must exceed min on every axis (got min {_listed(box.min_m)}, "
                             f"max {_listed(box.max_m)})")
        if np.any(lo < -_TOL_M):
            raise WorldError(f"{key}.min: obstacle {box.name!r} lies outside the room (min {_listed(lo)})")
        if np.any(hi > size + _TOL_M):
            raise WorldError(f"{key}.max: obstacle {box.name!r} lies outside the room {_listed(size)} "
                             f"(max {_listed(hi)})")
    _validate_target(world, size)
    for i, poster in enumerate(world.posters):
        corners = poster.picture_corners_m()
        if np.any(corners < -_TOL_M) or np.any(corners > size + _TOL_M):
            raise WorldError(f"poster[{i}].center: poster {poster.name!r} lies outside the room")
    _validate_start(world, size)


def _validate_target(world: World, size: np.ndarray) -> None:
    target = world.target
    box = target.box()
    if target.sides == 4 and abs(target.size_m[0] - target.size_m[1]) > _TOL_M:
        # the detector and the seeing geometry model one face shape, size[1] wide, for all four sides
        raise WorldError(f"target.size: a target pictured on 4 sides needs a square footprint "
                         f"(size[0] == size[1]), got {_listed(target.size_m)}")
    if np.any(np.array(box.min_m) < -_TOL_M) or np.any(np.array(box.max_m) > size + _TOL_M):
        raise WorldError(f"target.position: target box lies outside the room {_listed(size)} "
                         f"(its extent is {_listed(box.min_m)} .. {_listed(box.max_m)})")
    for obstacle in world.obstacles:
        if _target_overlaps(target, obstacle):
            raise WorldError(f"target.position: target box overlaps obstacle {obstacle.name!r} "
                             "(it may rest on a surface but not cut into it)")
    _validate_support(world)


def support_of(boxes: Iterable, x: float, y: float, z: float):
    """The box (anything with ``min_m`` and ``max_m``) whose top a target's bottom centre (x, y, z)
    rests on, within the contact tolerance; None: none does (it stands on the floor, or on nothing)."""
    return next((b for b in boxes if abs(b.max_m[2] - z) <= _TOL_M and _over(b, x, y)), None)


def _over(box, x: float, y: float) -> bool:
    return box.min_m[0] - _TOL_M <= x <= box.max_m[0] + _TOL_M and box.min_m[1] - _TOL_M <= y <= box.max_m[1] + _TOL_M


def _validate_support(world: World) -> None:
    """The target's bottom rests on the floor or on the top of an obstacle under its centre: the
    simulator has no gravity, so a target in the air would render and be searched for as if held up."""
    x, y, z = world.target.position_m
    if abs(z) > _TOL_M and support_of(world.obstacles, x, y, z) is None:
        tops = "".join(f", {b.name!r} at {b.max_m[2]:g} m" for b in world.obstacles if _over(b, x, y))
        raise WorldError(f"target.position: the target's bottom is {z:g} m high and rests on nothing: the tops "
                         f"at its centre ({x:g}, {y:g}) are the floor at 0 m{tops} (tolerance {_TOL_M * 1000:g} mm)")


def _listed(values: Iterable[float]) -> str:
    """Metres as a message shows them: ``[6, 5, 2.5]``, not numpy reprs or float noise."""
    return "[" + ", ".join(f"{round(float(v), 3):g}" for v in values) + "]"


def _target_overlaps(target: Target, box: Box) -> bool:
    """Interior overlap of the yawed target with an axis-aligned box (separating axes)."""
    z0, z1 = target.position_m[2], target.position_m[2] + target.size_m[2]
    if min(z1, box.max_m[2]) - max(z0, box.min_m[2]) <= _TOL_M:
        return False
    forward, left = _yawed_frame(target.yaw_deg)
    centre_gap = np.array(target.position_m[:2]) - (np.array(box.min_m[:2]) + np.array(box.max_m[:2])) / 2
    box_half = (np.array(box.max_m[:2]) - np.array(box.min_m[:2])) / 2
    for axis in (np.array([1.0, 0.0]), np.array([0.0, 1.0]), forward[:2], left[:2]):
        target_r = (abs(axis @ forward[:2]) * target.size_m[0] + abs(axis @ left[:2]) * target.size_m[1]) / 2
        box_r = abs(axis[0]) * box_half[0] + abs(axis[1]) * box_half[1]
        if abs(axis @ centre_gap) >= target_r + box_r - _TOL_M:
            return False
    return True


def _validate_start(world: World, size: np.ndarray) -> None:
    x, y, r = world.start.x_m, world.start.y_m, world.robot_radius_m
    if not (r <= x <= size[0] - r and r <= y <= size[1] - r):
        raise WorldError(f"robot.start: the robot disc (radius {r} m) at ({x:.3f}, {y:.3f}) "
                         f"is not inside the room {_listed(size[:2])}")
    for box in world.base_blockers():
        dx = max(box.min_m[0] - x, 0.0, x - box.max_m[0])
        dy = max(box.min_m[1] - y, 0.0, y - box.max_m[1])
        if math.hypot(dx, dy) < r - _TOL_M:
            raise WorldError(f"robot.start: the robot disc (radius {r} m) at ({x:.3f}, {y:.3f}) "
                             f"overlaps {box.kind} {box.name!r}")


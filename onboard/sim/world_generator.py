"""Furnished rooms the search has never seen (issue 12): ``generate_world`` draws one, ``write_worlds``
checks each (``onboard.sim.world_check``) and writes the ones that pass.

A room is 4-12 m along x and y (independently) and 2.4-3 m high. Its furniture is axis-aligned
boxes of several kinds (tables, low tables, desks, bookshelves, high wall shelves that leave the
floor free, cabinets, crates, partitions, sofas), each with a texture chosen per kind. Pieces on the
floor stand flush against a wall or at least ``GAP_M`` from the walls, and at least ``GAP_M`` from
each other, so the robot (0.62 m across with its clearance) can pass between any two of them. The
target (one-sided, the built-in "target" picture, 0.23 m cube) stands near the front edge of a
table, desk, cabinet, crate or shelf top, high (1.6-2.1 m), low (0.4-0.8 m) or in between, its picture
facing at least ``OPEN_FLOOR_M`` of open floor, half the time turned by up to ``max_turn_deg``, 10° unless
asked. The robot starts in the open floor, 3 m or more from the target where the room allows (never
under 1.5 m). A few posters (distractors, never the target's picture nor "chelsea") hang on the walls.

Everything is drawn from the ``numpy`` generator given, so a seed makes the same rooms.
"""

from __future__ import annotations

import logging
import math
import time
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from onboard.sim.world import check_renderable
from onboard.sim.world_check import (DRIVE_CLEARANCE_M, WorldRejected, areas, check_world, clearance_grid,
                                     rect_distance)
from shared.world import FLOOR_OBSTACLE_MAX_Z_M, WorldError, parse_world, world_toml

log = logging.getLogger(__name__)

ROOM_SIDE_M = (4.0, 12.0)
ROOM_HEIGHT_M = (2.4, 3.0)
GAP_M = 0.8  # between floor pieces, and between a piece and a wall it does not touch
STACK_GAP_M = 0.35  # a wall shelf clears whatever stands under it by this much
OPEN_FLOOR_M = 1.5  # free floor in front of the target's picture
START_MARGIN_M = 0.45  # the start keeps this from walls and obstacles: open floor, not a niche
START_FAR_M = 3.0  # the start this far from the target if the room allows: a search, not a glance
TARGET_SIZE_M = 0.23
TARGET_EDGE_M = 0.15  # the target's centre keeps this from the sides of its support
MAX_TURN_DEG = 10.0  # half the targets are turned by up to this from square to their edge, unless asked
TURN_LIMIT_DEG = 45.0  # the most that may be asked: beyond, the picture would face another side's axis
HIGH_M, LOW_M = 1.5, 0.8  # support tops above HIGH_M are "high", up to LOW_M "low"
MAX_ATTEMPTS = 40  # draws of one world before giving up
DISTRACTORS = ("astronaut", "coffee", "hubble", "rocket")  # never "target" nor "chelsea" (the target's cat)
WALL_TEXTURES = ("plaster", "brick", "plaster", "gravel")
FLOOR_TEXTURES = ("carpet", "wood", "gravel", "carpet")
CEILING_TEXTURES = ("plaster",)


@dataclass(frozen=True)
class Furniture:
    """A kind of piece: extents along its wall (length), away from it (depth), height; where it goes."""

    kind: str  # the world file's obstacle kind
    length_m: tuple[float, float]
    depth_m: tuple[float, float]
    height_m: tuple[float, float]
    textures: tuple[str, ...]
    placement: str  # "wall" (flush against one), "free" (in the room), "either"
    surface: bool  # the target may stand on its top
    bottom_m: tuple[float, float] = (0.0, 0.0)  # above the floor: wall shelves


CATALOGUE: dict[str, Furniture] = {
    "table": Furniture("table", (0.9, 1.8), (0.7, 1.0), (0.7, 0.78), ("wood", "metal", "plaster"), "either", True),
    "low-table": Furniture("table", (0.8, 1.2), (0.5, 0.7), (0.4, 0.5), ("wood", "plaster"), "free", True),
    "desk": Furniture("desk", (1.2, 1.8), (0.6, 0.8), (0.72, 0.76), ("wood", "metal"), "wall", True),
    "bookshelf": Furniture("shelf", (0.8, 1.6), (0.3, 0.45), (1.6, 2.0), ("wood", "metal"), "wall", True),
    "wall-shelf": Furniture("shelf", (0.8, 2.0), (0.3, 0.4), (0.04, 0.05), ("wood", "metal"), "wall", True,
                            (1.55, 2.04)),
    "cabinet": Furniture("cabinet", (0.5, 1.2), (0.4, 0.6), (0.6, 1.3), ("metal", "wood", "plaster"), "wall", True),
    "crate": Furniture("crate", (0.4, 0.8), (0.4, 0.8), (0.4, 0.8), ("wood", "cardboard"), "either", True),
    "partition": Furniture("partition", (1.0, 2.4), (0.05, 0.08), (1.2, 1.8), ("fabric", "plaster", "metal"),
                           "either", False),
    "sofa": Furniture("sofa", (1.6, 2.2), (0.8, 0.95), (0.75, 0.9), ("fabric", "carpet"), "wall", False),
}
REQUIRED = (("table", "desk"), ("wall-shelf", "bookshelf"), ("cabinet",), ("crate", "low-table"))  # every room
EXTRA_WEIGHTS = {"table": 3, "low-table": 1, "desk": 2, "bookshelf": 1, "wall-shelf": 2, "cabinet": 2,
                 "crate": 2, "partition": 2, "sofa": 1}


@dataclass(frozen=True)
class Piece:
    name: str
    label: str  # its CATALOGUE entry
    lo: tuple[float, float, float]
    hi: tuple[float, float, float]
    texture: str
    wall: int | None  # the wall it stands against: 0 y = 0, 1 y = max, 2 x = 0, 3 x = max

    def on_floor(self) -> bool:
        return self.lo[2] < FLOOR_OBSTACLE_MAX_Z_M

    def rect(self) -> tuple[tuple[float, float], tuple[float, float]]:
        return (self.lo[0], self.lo[1]), (self.hi[0], self.hi[1])


# The direction (unit x, y) pointing into the room from each wall.
_INTO_ROOM = {0: (0, 1), 1: (0, -1), 2: (1, 0), 3: (-1, 0)}


def _r(value: float) -> float:
    """Positions in the files in centimetres: readable, and exact after a TOML round trip."""
    return round(float(value), 2)


# ----------------------------------------------------------------------------- one world


def generate_world(rng: np.random.Generator, name: str, max_turn_deg: float = MAX_TURN_DEG) -> dict[str, Any]:
    """One furnished room as world data (``shared.world.world_toml`` writes it); not yet checked; the
    target turned by up to ``max_turn_deg`` half the time. Raises ``WorldRejected`` when the draw leaves
    no place for the target or the start."""
    room = (_r(rng.uniform(*ROOM_SIDE_M)), _r(rng.uniform(*ROOM_SIDE_M)), _r(rng.uniform(*ROOM_HEIGHT_M)))
    pieces = _furnish(rng, room)
    target = _place_target(rng, room, pieces, max_turn_deg)
    start = _place_start(rng, room, pieces, target)
    data = {
        "name": name,
        "room": {"size": list(room), "texture": str(rng.choice(WALL_TEXTURES)),
                 "floor_texture": str(rng.choice(FLOOR_TEXTURES)),
                 "ceiling_texture": str(rng.choice(CEILING_TEXTURES))},
        "obstacle": [{"name": p.name, "kind": CATALOGUE[p.label].kind, "min": list(p.lo), "max": list(p.hi),
                      "texture": p.texture} for p in pieces],
        "target": target,
        "poster": _posters(rng, room),
        "robot": start,
    }
    return {k: v for k, v in data.items() if v != []}  # no posters: no key


def _furnish(rng: np.random.Generator, room: tuple[float, float, float]) -> list[Piece]:
    """The required kinds, then extras in proportion to the floor area; a piece that does not fit
    after some tries is left out."""
    count = int(np.clip(round(room[0] * room[1] / rng.uniform(3.5, 6.0)), len(REQUIRED) + 1, 16))
    labels = [str(rng.choice(options)) for options in REQUIRED]
    extras = list(EXTRA_WEIGHTS)
    weights = np.array([EXTRA_WEIGHTS[k] for k in extras], float)
    labels += [str(k) for k in rng.choice(extras, count - len(labels), p=weights / weights.sum())]
    pieces: list[Piece] = []
    for label in labels:
        for _ in range(30):
            piece = _draw_piece(rng, label, room, f"{CATALOGUE[label].kind}-{len(pieces) + 1}")
            if _fits(piece, pieces, room):
                pieces.append(piece)
                break
    return pieces


def _draw_piece(rng: np.random.Generator, label: str, room: tuple[float, float, float], name: str) -> Piece:
    spec = CATALOGUE[label]
    length, depth = rng.uniform(*spec.length_m), rng.uniform(*spec.depth_m)
    bottom = rng.uniform(*spec.bottom_m)
    height = rng.uniform(*spec.height_m)
    texture = str(rng.choice(spec.textures))
    against_wall = spec.placement == "wall" or (spec.placement == "either" and rng.random() < 0.5)
    if not against_wall:
        if rng.random() < 0.5:
            length, depth = depth, length
        x0 = rng.uniform(GAP_M, max(GAP_M, room[0] - GAP_M - length))
        y0 = rng.uniform(GAP_M, max(GAP_M, room[1] - GAP_M - depth))
        return Piece(name, label, (_r(x0), _r(y0), _r(bottom)), (_r(x0 + length), _r(y0 + depth), _r(bottom + height)),
                     texture, None)
    wall = int(rng.integers(4))
    if label == "partition":  # a screen sticks out of the wall, square to it
        length, depth = depth, length
    along_size = room[0] if wall < 2 else room[1]
    across_size = room[1] if wall < 2 else room[0]
    length, depth = min(length, along_size), min(depth, across_size / 2)
    a0 = _along_wall(rng, along_size, length)
    d0 = 0.0 if wall in (0, 2) else across_size - depth
    x0, y0, dx, dy = (a0, d0, length, depth) if wall < 2 else (d0, a0, depth, length)
    return Piece(name, label, (_r(x0), _r(y0), _r(bottom)), (_r(x0 + dx), _r(y0 + dy), _r(bottom + height)),
                 texture, wall)


def _along_wall(rng: np.random.Generator, wall_m: float, length_m: float) -> float:
    """Where a piece starts along its wall: in a corner, or at least GAP_M from both ends."""
    lo, hi = GAP_M, wall_m - length_m - GAP_M
    if hi < lo or rng.random() < 0.3:
        return float(rng.choice([0.0, wall_m - length_m]))
    return float(rng.uniform(lo, hi))


def _fits(piece: Piece, pieces: list[Piece], room: tuple[float, float, float]) -> bool:
    """Inside the room; a floor piece flush with or ``GAP_M`` from each wall and ``GAP_M`` from every
    other floor piece; nothing stacked closer than ``STACK_GAP_M``."""
    lo, hi = np.array(piece.lo), np.array(piece.hi)
    if np.any(lo < 0.0) or np.any(hi > np.array(room)):
        return False
    if piece.on_floor():
        wall_gaps = (lo[0], room[0] - hi[0], lo[1], room[1] - hi[1])
        if any(1e-6 < g < GAP_M for g in wall_gaps):
            return False
    for other in pieces:
        if _rect_gap(piece, other) >= (GAP_M if piece.on_floor() and other.on_floor() else 1e-6):
            continue
        if piece.on_floor() and other.on_floor():
            return False
        below, above = sorted((piece, other), key=lambda p: p.lo[2])
        if above.lo[2] - below.hi[2] < STACK_GAP_M:
            return False
    return True


def _rect_gap(a: Piece, b: Piece) -> float:
    dx = max(b.lo[0] - a.hi[0], a.lo[0] - b.hi[0], 0.0)
    dy = max(b.lo[1] - a.hi[1], a.lo[1] - b.hi[1], 0.0)
    return math.hypot(dx, dy)


# ----------------------------------------------------------------------------- the target


def _place_target(rng: np.random.Generator, room: tuple[float, float, float], pieces: list[Piece],
                  max_turn_deg: float) -> dict[str, Any]:
    """On a support of the height class drawn (high, low, in between; any if that class has none),
    facing the side with the most open floor in front."""
    supports = [p for p in pieces if CATALOGUE[p.label].surface and _top_holds_target(p)
                and p.hi[2] + TARGET_SIZE_M < room[2] - 0.05]
    wanted = str(rng.choice(["high", "low", "middle"], p=[0.3, 0.3, 0.4]))
    preferred = [p for p in supports if _height_class(p.hi[2]) == wanted]
    others = [p for p in supports if _height_class(p.hi[2]) != wanted]
    for group in (preferred, others):
        for index in rng.permutation(len(group)):
            support = group[int(index)]
            options = [(_open_floor_m(room, pieces, support, f, target["position"]), k, target)
                       for k, f in enumerate(_facings(support))
                       for target in [_target_on(rng, support, f, max_turn_deg)]]
            options = [option for option in options if option[0] >= OPEN_FLOOR_M]
            if options:
                return max(options)[2]
    raise WorldRejected("no table, desk, cabinet, crate or shelf top faces open floor")


def _height_class(top_m: float) -> str:
    return "high" if top_m > HIGH_M else "low" if top_m <= LOW_M else "middle"


def _top_holds_target(p: Piece) -> bool:
    return min(p.hi[0] - p.lo[0], p.hi[1] - p.lo[1]) >= TARGET_SIZE_M + 0.05


def _facings(p: Piece) -> list[tuple[int, int]]:
    """Directions the picture may face: away from the piece's wall, or any side of a free piece."""
    return [_INTO_ROOM[p.wall]] if p.wall is not None else [(1, 0), (-1, 0), (0, 1), (0, -1)]


def _open_floor_m(room: tuple[float, float, float], pieces: list[Piece], support: Piece,
                  facing: tuple[int, int], target_xy: list[float], cap_m: float = 3.0) -> float:
    """Free floor in front of the target, from the support's edge along ``facing``, in a strip a robot wide."""
    axis, sign = (0, facing[0]) if facing[0] else (1, facing[1])
    edge = support.hi[axis] if sign > 0 else support.lo[axis]
    centre = list(target_xy[:2])
    blockers = [p.rect() for p in pieces if p.on_floor() and p is not support]
    for step in np.arange(0.05, cap_m, 0.05):
        point = list(centre)
        point[axis] = edge + sign * step
        xs = np.array([point[0]] * 3) + (0 if axis == 0 else np.array([-0.3, 0.0, 0.3]))
        ys = np.array([point[1]] * 3) + (0 if axis == 1 else np.array([-0.3, 0.0, 0.3]))
        inside = np.all((xs > 0) & (xs < room[0]) & (ys > 0) & (ys < room[1]))
        if not inside or any(np.any(rect_distance(xs, ys, rect) == 0.0) for rect in blockers):
            return float(step - 0.05)
    return cap_m


def _target_on(rng: np.random.Generator, support: Piece, facing: tuple[int, int],
               max_turn_deg: float) -> dict[str, Any]:
    """At the front edge of the support's top, anywhere along it, turned by up to ``max_turn_deg`` half the time."""
    axis, sign = (0, facing[0]) if facing[0] else (1, facing[1])
    other = 1 - axis
    centre = [0.0, 0.0]
    lo, hi = support.lo[other] + TARGET_EDGE_M, support.hi[other] - TARGET_EDGE_M
    centre[other] = rng.uniform(lo, hi) if hi > lo else (support.lo[other] + support.hi[other]) / 2
    turn = rng.uniform(-max_turn_deg, max_turn_deg) if rng.random() < 0.5 else 0.0
    # The front face at most 3 cm behind the edge: seen from below, a deeper edge would hide its foot.
    reach = TARGET_SIZE_M / 2 * (math.cos(math.radians(turn)) + math.sin(math.radians(abs(turn))))
    inset = min(reach + rng.uniform(0.0, 0.03), (support.hi[axis] - support.lo[axis]) / 2)
    centre[axis] = (support.hi[axis] - inset) if sign > 0 else (support.lo[axis] + inset)
    yaw = math.degrees(math.atan2(facing[1], facing[0])) + turn
    return {"picture": "target", "size": [TARGET_SIZE_M] * 3, "position": [_r(centre[0]), _r(centre[1]), support.hi[2]],
            "yaw_deg": round(yaw, 1), "sides": 1}


# ----------------------------------------------------------------------------- start and posters


def _place_start(rng: np.random.Generator, room: tuple[float, float, float], pieces: list[Piece],
                 target: dict[str, Any]) -> dict[str, Any]:
    """A cell of open floor (``START_MARGIN_M`` from everything) in the largest drivable area, at
    least ``START_FAR_M`` from the target where the room allows, else at least 1.5 m."""
    rects = [p.rect() for p in pieces if p.on_floor()]
    open_floor = clearance_grid(room[:2], rects, START_MARGIN_M)
    drivable = clearance_grid(room[:2], rects, DRIVE_CLEARANCE_M)
    labels = areas(drivable)
    largest = int(np.argmax(np.bincount(labels[labels > 0]))) if np.any(labels > 0) else -1
    x, y = open_floor.centres()
    tx, ty = target["position"][:2]
    ok = open_floor.drivable & (labels == largest)
    gap = np.hypot(x - tx, y - ty)
    cells = np.argwhere(ok & (gap >= START_FAR_M))
    cells = cells if len(cells) else np.argwhere(ok & (gap >= 1.5))
    if not len(cells):
        raise WorldRejected("no open floor for the start at least 1.5 m from the target")
    i, j = cells[int(rng.integers(len(cells)))]
    return {"start": [_r(x[i, j]), _r(y[i, j])], "heading_deg": float(15 * rng.integers(24))}


def _posters(rng: np.random.Generator, room: tuple[float, float, float]) -> list[dict[str, Any]]:
    """Up to three pictures flat on the walls, at eye height or a little above."""
    posters = []
    for k in range(int(rng.integers(0, 4))):
        wall = int(rng.integers(4))
        width = rng.uniform(0.4, 0.9)
        height = min(width * rng.uniform(0.6, 1.2), 0.9)
        along_size = room[0] if wall < 2 else room[1]
        along = rng.uniform(width / 2 + 0.05, along_size - width / 2 - 0.05)
        across = 0.0 if wall in (0, 2) else (room[1] if wall == 1 else room[0])
        x, y = (along, across) if wall < 2 else (across, along)
        into = _INTO_ROOM[wall]
        posters.append({"name": f"poster-{k + 1}", "picture": str(rng.choice(DISTRACTORS)),
                        "center": [_r(x), _r(y), _r(rng.uniform(1.0, min(1.8, room[2] - height / 2 - 0.1)))],
                        "size": [_r(width), _r(height)], "yaw_deg": float(math.degrees(math.atan2(into[1], into[0])))})
    return posters


# ----------------------------------------------------------------------------- checked files


def world_file_name(seed: int, index: int) -> str:
    return f"room-{seed}-{index}"


def draw_checked_world(seed: int, index: int, out_dir: Path, max_turn_deg: float = MAX_TURN_DEG) -> tuple[str, int]:
    """The text of world ``index`` of ``seed`` (the first draw that passes the checks) and how many
    draws were rejected before it; its comment names a ``max_turn_deg`` other than ``MAX_TURN_DEG``, which
    draws another room under the same name. Raises ``RuntimeError`` after ``MAX_ATTEMPTS`` draws."""
    name = world_file_name(seed, index)
    rng = np.random.default_rng([seed, index])
    for attempt in range(MAX_ATTEMPTS):
        started = time.perf_counter()
        try:
            data = generate_world(rng, name, max_turn_deg)
            world = parse_world(tomllib.loads(world_toml(data)), out_dir)  # what the file will hold
            check_renderable(world)
            seen = check_world(world)
        except (WorldRejected, WorldError) as exc:  # WorldError: a draw the format refuses (overlaps)
            log.info("%s: draw %d rejected: %s", name, attempt + 1, exc)
            continue
        turn = "" if max_turn_deg == MAX_TURN_DEG else f" --max-turn-deg {max_turn_deg}"
        comment = (f"Generated by `syt-onboard worlds generate --seed {seed}{turn}` (world {index} of that seed).\n"
                   f"Checked: the robot can drive from its start to ({seen.x_m:.2f}, {seen.y_m:.2f}), where the "
                   f"camera sees the target's picture\nfrom {seen.distance_m:.2f} m, {seen.off_normal_deg:.0f}° "
                   f"off its normal, at tilt {math.degrees(seen.tilt_rad):.0f}° (confirmed by rendering).")
        text = world_toml(data, comment)
        log.info("%s: %.1f x %.1f x %.2f m, %d pieces, target %.2f m high, seen from %.2f m after %d render(s), "
                 "%.2f s", name, *data["room"]["size"], len(data["obstacle"]), data["target"]["position"][2],
                 seen.distance_m, seen.renders, time.perf_counter() - started)
        return text, attempt
    raise RuntimeError(f"{name}: no acceptable world in {MAX_ATTEMPTS} draws")


def write_worlds(count: int, seed: int, out_dir: Path, max_turn_deg: float = MAX_TURN_DEG) -> list[Path]:
    """Write ``count`` checked worlds ``out_dir/room-SEED-K.toml``; the same seed (and turn) writes the same
    files. Raises ``ValueError``, before writing anything, for a negative seed, a turn outside 0 to
    ``TURN_LIMIT_DEG`` or a folder holding other world files."""
    if count < 1:
        raise ValueError(f"count must be at least 1, got {count}")
    if seed < 0:
        raise ValueError(f"seed must be 0 or more, got {seed}")
    if not 0.0 <= max_turn_deg <= TURN_LIMIT_DEG:
        raise ValueError(f"max_turn_deg must be from 0 to {TURN_LIMIT_DEG:g}, got {max_turn_deg:g}")
    _check_only_this_batch(count, seed, out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths, rejected, started = [], 0, time.perf_counter()
    for index in range(count):
        text, failures = draw_checked_world(seed, index, out_dir, max_turn_deg)
        path = out_dir / f"{world_file_name(seed, index)}.toml"
        path.write_text(text, encoding="utf-8")
        paths.append(path)
        rejected += failures
    log.info("%d worlds in %s (%d draws rejected) in %.1f s", count, out_dir, rejected, time.perf_counter() - started)
    return paths


def _check_only_this_batch(count: int, seed: int, out_dir: Path) -> None:
    """Refuse a folder holding world files this batch would not write: run as a folder of worlds
    (``--worlds DIR``), it would run those stale ones too. The batch's own files may be rewritten, whatever
    turn drew them (a name is seed and index): the batch rewrites each of them."""
    ours = {f"{world_file_name(seed, index)}.toml" for index in range(count)}
    others = sorted(p.name for p in out_dir.glob("*.toml") if p.name not in ours) if out_dir.is_dir() else []
    if others:
        shown = ", ".join(others[:3]) + (f" and {len(others) - 3} more" if len(others) > 3 else "")
        raise ValueError(f"{out_dir}: already holds world files this batch (seed {seed}, count {count}) would not "
                         f"write: {shown}; write into an empty folder or remove them")

"""Global path planning for the base on the inflated floor map: Dijkstra, A* and line-of-sight smoothing.

The configuration space is the :class:`~offboard.perception.occupancy.FloorMap`'s ``blocked`` array (occupied
columns inflated by the robot's radius, walls included); a cell centre is where the robot's centre
may stand. Cell (i, j) spans [i·res, (i+1)·res) × [j·res, (j+1)·res): the map starts at the world
origin, the room's corner. Unknown cells are *free* (the free-space assumption of planning in partly
known terrain: optimistic paths, re-planned when stereo shows otherwise).

- :func:`distance_field`: Dijkstra on the 8-connected grid (diagonals cost √2 and may not cut a
  blocked corner) from one start to every cell, in metres; the search planner reads the path length
  to its candidate viewpoints from it.
- :func:`shortest_path`: A* (octile heuristic, admissible and consistent on this grid) to one goal,
  then greedy line-of-sight shortcutting ("string pulling"), which removes the grid's zig-zags.
- :func:`any_angle_field`: the lengths of any-angle paths (Theta*'s rule: a cell's path runs straight
  from its neighbour's parent when that is in line of sight) from one start to every cell. Grid steps
  read a straight line 22.5° off an axis 8 % long; this is the yardstick for "the shortest path",
  which a robot that straightens its paths can drive.

The kernels are numba: a priority-queue search is sequential by nature.
"""

from __future__ import annotations

import heapq
import math

import numba
import numpy as np

from offboard.perception.occupancy import FloorMap

Point = tuple[float, float]

_SQRT2 = math.sqrt(2.0)
# the 8 neighbours: (di, dj, step length in cells)
_NEIGHBOURS = np.array([(1, 0, 1.0), (-1, 0, 1.0), (0, 1, 1.0), (0, -1, 1.0),
                        (1, 1, _SQRT2), (1, -1, _SQRT2), (-1, 1, _SQRT2), (-1, -1, _SQRT2)])


# --- cells and points ------------------------------------------------------------------------------

def cell_of(floor_map: FloorMap, xy: Point) -> tuple[int, int]:
    """Index of the cell holding a world point, clamped into the map (the map starts at the origin)."""
    i, j = floor_map.cells_of(np.array([xy]))[0]
    return int(i), int(j)


def cell_center(floor_map: FloorMap, cell: tuple[int, int]) -> Point:
    res = floor_map.resolution_m
    return ((cell[0] + 0.5) * res, (cell[1] + 0.5) * res)


def cell_centers(floor_map: FloorMap, cells: np.ndarray) -> np.ndarray:
    """World centres (N, 2) of cells (N, 2): :func:`cell_center` for many at once."""
    return (cells + 0.5) * floor_map.resolution_m


def is_free(floor_map: FloorMap, xy: Point) -> bool:
    """Can the robot's centre stand at ``xy``? (Outside the room it cannot.)"""
    nx, ny = floor_map.blocked.shape
    i, j = (math.floor(v / floor_map.resolution_m) for v in xy)
    return 0 <= i < nx and 0 <= j < ny and not floor_map.blocked[i, j]


def nearest_free_cell(floor_map: FloorMap, xy: Point, among: np.ndarray | None = None) -> tuple[int, int] | None:
    """The free cell whose centre is closest to ``xy`` (the robot hugging an obstacle starts there);
    ``among``: only cells where this mask (the floor's shape) is true."""
    allowed = ~floor_map.blocked if among is None else ~floor_map.blocked & among
    cell = cell_of(floor_map, xy)
    if allowed[cell]:
        return cell
    free = np.argwhere(allowed)
    if free.shape[0] == 0:
        return None
    centres = cell_centers(floor_map, free)
    best = int(np.argmin(np.hypot(centres[:, 0] - xy[0], centres[:, 1] - xy[1])))
    return int(free[best, 0]), int(free[best, 1])


def segment_is_free(floor_map: FloorMap, a: Point, b: Point) -> bool:
    """Does the straight segment a→b cross only free cells (every cell it touches)?"""
    res = floor_map.resolution_m
    return bool(_segment_free(floor_map.blocked, a[0] / res, a[1] / res, b[0] / res, b[1] / res))


def path_length_m(path: list[Point] | None) -> float:
    """Length of a polyline in metres (``inf`` for no path)."""
    if path is None:
        return math.inf
    return float(sum(math.dist(p, q) for p, q in zip(path[:-1], path[1:])))


# --- planning --------------------------------------------------------------------------------------

def distance_field(floor_map: FloorMap, start_xy: Point) -> np.ndarray:
    """Path length (m) from ``start_xy`` to every cell's centre; ``inf`` if unreachable.

    A path is the straight hop from ``start_xy`` to the centre of its cell (or, if that is blocked,
    the robot hugging an obstacle, of the nearest free cell), then 8-connected steps between cell
    centres: the cell it starts from reads that hop, not 0, wherever in it the start lies.
    """
    blocked = np.ascontiguousarray(floor_map.blocked)
    start = nearest_free_cell(floor_map, start_xy)
    dist = np.full(blocked.shape, np.inf)
    if start is None:
        return dist
    offset = math.dist(start_xy, cell_center(floor_map, start)) / floor_map.resolution_m
    _dijkstra(blocked, start[0], start[1], offset, -1, -1, dist, np.full(blocked.shape, -1, np.int64))
    return dist * floor_map.resolution_m


def distances_at(floor_map: FloorMap, field: np.ndarray, points_xy: np.ndarray) -> np.ndarray:
    """Look up a :func:`distance_field` at world points (N, 2); ``inf`` outside the room."""
    pts = np.atleast_2d(np.asarray(points_xy, dtype=np.float64))
    idx = np.floor(pts / floor_map.resolution_m).astype(np.int64)
    inside = np.all((idx >= 0) & (idx < np.array(field.shape)), axis=1)
    out = np.full(pts.shape[0], np.inf)
    out[inside] = field[idx[inside, 0], idx[inside, 1]]
    return out


def path_lengths(floor_map: FloorMap, start_xy: Point, points_xy: np.ndarray) -> np.ndarray:
    """Shortest path length (m) from ``start_xy`` to each world point (N, 2); ``inf`` where no path
    reaches it."""
    return distances_at(floor_map, distance_field(floor_map, start_xy), points_xy)


def any_angle_field(floor_map: FloorMap, start_xy: Point) -> np.ndarray:
    """Length (m) of an any-angle path from ``start_xy`` to every cell's centre; ``inf`` where
    :func:`distance_field` has it. A cell in line of sight of the start reads the straight distance;
    around obstacles a path bends at cell centres (Theta*, Nash et al. 2007: close to the true
    shortest, and in the tests never longer than the 8-connected path). A blocked start hops to the
    nearest free cell first, as :func:`distance_field`'s does."""
    blocked = np.ascontiguousarray(floor_map.blocked)
    start = nearest_free_cell(floor_map, start_xy)
    dist = np.full(blocked.shape, np.inf)
    if start is None:
        return dist
    res = floor_map.resolution_m
    source, offset = start_xy, 0.0
    if not is_free(floor_map, start_xy):
        source = cell_center(floor_map, start)
        offset = math.dist(start_xy, source) / res
    _theta_field(blocked, start[0], start[1], source[0] / res, source[1] / res, offset, dist)
    return dist * res


def shortest_path(floor_map: FloorMap, start_xy: Point, goal_xy: Point) -> list[Point] | None:
    """Shortest collision-free polyline from start to goal (both included), or ``None``.

    ``None`` when the goal's cell is blocked, lies outside the room, or no free route connects them.
    """
    if not is_free(floor_map, goal_xy):
        return None
    start = nearest_free_cell(floor_map, start_xy)
    if start is None:
        return None
    goal = cell_of(floor_map, goal_xy)
    blocked = np.ascontiguousarray(floor_map.blocked)
    parent = np.full(blocked.shape, -1, np.int64)
    dist = np.full(blocked.shape, np.inf)
    if not _dijkstra(blocked, start[0], start[1], 0.0, goal[0], goal[1], dist, parent):
        return None
    # from the robot itself (if it stood blocked, its first hop leaves the obstacle) through the
    # centres of the cells before the goal's; a start on its cell's centre is not listed twice
    inner = [cell_center(floor_map, c) for c in _backtrack(parent, goal, blocked.shape[1])[:-1]]
    if inner and inner[0] == start_xy:
        inner = inner[1:]
    return _shortcut(floor_map, [start_xy, *inner, goal_xy])


def _backtrack(parent: np.ndarray, goal: tuple[int, int], ny: int) -> list[tuple[int, int]]:
    cells = [goal]
    flat = parent[goal]
    while flat >= 0:
        cells.append((int(flat // ny), int(flat % ny)))
        flat = parent[cells[-1]]
    cells.reverse()
    return cells


def _shortcut(floor_map: FloorMap, points: list[Point]) -> list[Point]:
    """Greedy string pulling: from each kept vertex jump to the farthest vertex still in line of sight.

    A blocked start keeps its first hop: no segment from a blocked cell is free."""
    out = [points[0]]
    i = 0
    while i < len(points) - 1:
        j = len(points) - 1
        while j > i + 1 and not segment_is_free(floor_map, points[i], points[j]):
            j -= 1
        out.append(points[j])
        i = j
    return out


# --- kernels ---------------------------------------------------------------------------------------

@numba.njit(cache=True)
def _dijkstra(blocked, si, sj, start_cost, gi, gj, dist, parent):
    """Dijkstra from (si, sj), or A* with the octile heuristic when a goal (gi >= 0) is given.

    Fills ``dist`` (cells) and ``parent`` (flat index); returns whether the goal was reached."""
    nx, ny = blocked.shape
    use_goal = gi >= 0
    dist[si, sj] = start_cost
    heap = [(start_cost + _octile(si, sj, gi, gj, use_goal), si * ny + sj)]
    done = np.zeros(blocked.shape, np.bool_)
    while heap:
        _, flat = heapq.heappop(heap)
        i, j = flat // ny, flat % ny
        if done[i, j]:
            continue
        done[i, j] = True
        if use_goal and i == gi and j == gj:
            return True
        for k in range(8):
            di, dj, step = int(_NEIGHBOURS[k, 0]), int(_NEIGHBOURS[k, 1]), _NEIGHBOURS[k, 2]
            a, b = i + di, j + dj
            if a < 0 or a >= nx or b < 0 or b >= ny or blocked[a, b] or done[a, b]:
                continue
            if di != 0 and dj != 0 and (blocked[i + di, j] or blocked[i, j + dj]):
                continue  # a diagonal may not cut the corner of a blocked cell
            cost = dist[i, j] + step
            if cost < dist[a, b]:
                dist[a, b] = cost
                parent[a, b] = flat
                heapq.heappush(heap, (cost + _octile(a, b, gi, gj, use_goal), a * ny + b))
    return False


@numba.njit(cache=True)
def _theta_field(blocked, si, sj, sx, sy, start_cost, dist):
    """Dijkstra from cell (si, sj) whose relaxation tries the popped cell's parent point first
    (Theta*): ``dist`` (cells) to every cell centre, paths bending at cell centres or starting at the
    source point (sx, sy) (cell units) at ``start_cost``. Steps between neighbours obey
    :func:`_dijkstra`'s rules, so it reaches the same cells."""
    nx, ny = blocked.shape
    parent_x = np.full(blocked.shape, np.nan)
    parent_y = np.full(blocked.shape, np.nan)
    parent_d = np.zeros(blocked.shape)  # the path length at the parent point
    parent_x[si, sj], parent_y[si, sj], parent_d[si, sj] = sx, sy, start_cost
    dist[si, sj] = start_cost + math.hypot(si + 0.5 - sx, sj + 0.5 - sy)
    heap = [(dist[si, sj], si * ny + sj)]
    done = np.zeros(blocked.shape, np.bool_)
    while heap:
        _, flat = heapq.heappop(heap)
        i, j = flat // ny, flat % ny
        if done[i, j]:
            continue
        done[i, j] = True
        px, py, pd = parent_x[i, j], parent_y[i, j], parent_d[i, j]
        for k in range(8):
            di, dj, step = int(_NEIGHBOURS[k, 0]), int(_NEIGHBOURS[k, 1]), _NEIGHBOURS[k, 2]
            a, b = i + di, j + dj
            if a < 0 or a >= nx or b < 0 or b >= ny or blocked[a, b] or done[a, b]:
                continue
            if di != 0 and dj != 0 and (blocked[i + di, j] or blocked[i, j + dj]):
                continue  # _dijkstra's rules, written out: an inlined helper for both made it twice as slow
            cx, cy = a + 0.5, b + 0.5
            if _segment_free(blocked, px, py, cx, cy):  # straight on from the parent
                cost, qx, qy, qd = pd + math.hypot(cx - px, cy - py), px, py, pd
            else:  # bend at this cell's centre
                cost, qx, qy, qd = dist[i, j] + step, i + 0.5, j + 0.5, dist[i, j]
            if cost < dist[a, b]:
                dist[a, b] = cost
                parent_x[a, b], parent_y[a, b], parent_d[a, b] = qx, qy, qd
                heapq.heappush(heap, (cost, a * ny + b))


@numba.njit(cache=True, inline="always")
def _octile(i, j, gi, gj, use_goal):
    if not use_goal:
        return 0.0
    dx, dy = abs(i - gi), abs(j - gj)
    return max(dx, dy) + (_SQRT2 - 1.0) * min(dx, dy)


@numba.njit(cache=True)
def _segment_free(blocked, x0, y0, x1, y1):
    """Amanatides-Woo walk over every cell the segment touches (cell units); False at a blocked one.

    Where the segment passes exactly through a cell corner both side cells are checked."""
    nx, ny = blocked.shape
    i, j = int(math.floor(x0)), int(math.floor(y0))
    i1, j1 = int(math.floor(x1)), int(math.floor(y1))
    dx, dy = x1 - x0, y1 - y0
    si = 1 if dx > 0 else -1
    sj = 1 if dy > 0 else -1
    ti = ((i + 1 - x0) / dx if dx > 0 else (x0 - i) / -dx) if dx != 0 else np.inf
    tj = ((j + 1 - y0) / dy if dy > 0 else (y0 - j) / -dy) if dy != 0 else np.inf
    di = abs(1.0 / dx) if dx != 0 else np.inf
    dj = abs(1.0 / dy) if dy != 0 else np.inf
    for _ in range(abs(i1 - i) + abs(j1 - j) + 2):
        if i < 0 or i >= nx or j < 0 or j >= ny or blocked[i, j]:
            return False
        # in the last cell, or on its boundary: a segment that ends on a corner does not pass through
        # it, though round-off may put its end a hair past (0.95 / 0.05 is 18.999999999999996)
        if (i == i1 and j == j1) or min(ti, tj) >= 1.0 - 1e-9:
            return 0 <= i1 < nx and 0 <= j1 < ny and not blocked[i1, j1]
        if abs(ti - tj) < 1e-9:  # through a corner: the two side cells count as touched
            if (0 <= i + si < nx and blocked[i + si, j]) or (0 <= j + sj < ny and blocked[i, j + sj]):
                return False
            i += si
            j += sj
            ti += di
            tj += dj
        elif ti < tj:
            i += si
            ti += di
        else:
            j += sj
            tj += dj
    return False  # not reached: float round-off on a degenerate segment; be safe

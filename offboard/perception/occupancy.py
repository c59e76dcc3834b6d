"""How solid each cube is: a 3D log-odds occupancy grid built from stereo (report §4.1, eq. 5-8).

Per frame, for every stereo point (u, v, d):

- its uncertainty region U is the box spanned by ``u ± 0.5, v ± 0.5, d ± 0.5`` (eq. 6), and the set
  C of cubes overlapping U each receive ``hit_scale / |C|`` of evidence (eq. 7): a far point, whose
  region is large, says less about each cube than a near one. C is taken as the cubes of the
  world-aligned box around U's eight corners. U is a needle along the ray (at 5 m, 40 cm deep and a
  centimetre wide), so where the ray runs diagonally to the grid that box holds several times the
  cubes U crosses: 60 against 11 looking straight ahead at 5 m, 108 against 13 turned by 45°. The
  exact count (the cubes the needle's axis crosses, docs/trials/needle-occupancy.patch) changed 91 of
  `dev`'s 128 runs and SPL by −0.003 (standard error 0.012): see docs/search-experiments.md;
- every cube between the camera and U gains ``s = miss_log_odds`` (eq. 8);
- a point beyond ``max_range_m`` is too blurred to place (eq. 6's region grows as depth squared), and
  is dropped. With ``clear_beyond_range`` the ray to it is taken as clear instead: its cubes out to
  the range gain ``s`` and none is hit (OctoMap's maxrange). That clears space only such rays cross,
  where one frame's wrong disparity otherwise stays an obstacle (a pocket sealed by ghosts), but it
  cost SPL on `dev`, so it is off (docs/search-experiments.md, "Boxed in by a margin");
- each cube is updated once per frame: the evidence of all the points that touched it, capped at
  ``max_hit_per_frame``, else one miss. Occupied wins over free. (Summing, not taking the largest,
  lets the many pixels that see one far cube together say what one near pixel says alone.)

With the prior p(m_i) = 0.5 the prior term of eq. 5 is zero, so the update is a plain sum, clamped
as OctoMap does so that a changed world can be re-learnt. Parameters are named like OctoMap's.
The kernels are numba: a ray walk per point is not something numpy can vectorise.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import cv2
import numba
import numpy as np

from offboard.perception.voxel_grid import VoxelGrid
from shared.geometry import Intrinsics, RigidTransform
from shared.strict import bounds

UNKNOWN, FREE, OCCUPIED = 0, 1, 2


@dataclass(frozen=True)
class OccupancyConfig:
    resolution_m: float = field(default=0.05, metadata=bounds(0.01, 1.0))  # cube edge (report: 5 cm)
    hit_scale: float = field(default=1.0, metadata=bounds(0.01, 10.0))  # eq. 7: log-odds 1/|C| per point
    max_hit_per_frame: float = field(default=1.0, metadata=bounds(0.01, 10.0))  # one frame's say on a cube
    miss_log_odds: float = field(default=-0.4, metadata=bounds(-5.0, -0.01))  # eq. 8: s
    clamp_min: float = field(default=-2.0, metadata=bounds(-20.0, 0.0))  # OctoMap's 0.12
    clamp_max: float = field(default=3.5, metadata=bounds(0.0, 20.0))  # OctoMap's 0.97
    occupied_log_odds: float = field(default=0.5, metadata=bounds(0.0, 20.0))  # at or above: occupied
    free_log_odds: float = field(default=-0.3, metadata=bounds(-20.0, 0.0))  # at or below: free
    max_range_m: float = field(default=6.0, metadata=bounds(0.5, 50.0))  # stereo beyond this is not placed
    clear_beyond_range: bool = False  # a ray to a point beyond max range clears out to it (else: dropped)
    point_stride_px: int = field(default=4, metadata=bounds(1, 32))  # subsample the disparity image

    def __post_init__(self) -> None:
        order = (self.clamp_min, self.free_log_odds, self.occupied_log_odds, self.clamp_max)
        if not (order[0] <= order[1] < order[2] <= order[3]):  # else a wall is never occupied, or always free
            raise ValueError(f"occupancy needs clamp_min <= free_log_odds < occupied_log_odds <= clamp_max, "
                             f"not {' / '.join(map(str, order))}")
        if not (self.free_log_odds < 0 < self.occupied_log_odds):  # at 0, unobserved space stops every ray
            raise ValueError(f"occupancy needs free_log_odds < 0 < occupied_log_odds (0: no evidence either way), "
                             f"not {self.free_log_odds} / {self.occupied_log_odds}")


@dataclass(frozen=True)
class RayHits:
    distance_m: np.ndarray  # (N,) to the first occupied cube, the room's boundary, or max range
    hit: np.ndarray  # (N,) bool: stopped by an occupied cube or the boundary, not by max range


@dataclass(frozen=True)
class FloorMap:
    """A 2D map for the base: obstacles between floor clearance and robot height."""

    resolution_m: float
    occupied: np.ndarray  # (nx, ny) bool: some occupied cube in the robot's height band
    blocked: np.ndarray  # (nx, ny) bool: occupied inflated by the robot radius, plus the walls
    unknown: np.ndarray  # (nx, ny) bool: no cube of the band observed

    def cells_of(self, xy_m: np.ndarray) -> np.ndarray:
        """Indices (n, 2) of the cells holding the floor points ``xy_m`` (n, 2), clamped into the map
        (which starts at the origin): a point just outside a wall reads the wall's own cell."""
        cells = np.floor(np.asarray(xy_m, np.float64) / self.resolution_m).astype(np.int64)
        return np.clip(cells, 0, np.array(self.blocked.shape) - 1)


class OccupancyGrid:
    def __init__(self, grid: VoxelGrid, config: OccupancyConfig = OccupancyConfig()):
        self.grid = grid
        self.config = config
        self._log_odds = np.zeros(grid.shape, np.float32)
        self._observed = np.zeros(grid.shape, np.bool_)
        # for coarsened(): per x-y column of cubes, the epoch of its last write; the epoch, one more
        # at each coarsening, is an array so that shallow copies (the navigator's view) share it
        self._written = np.zeros(grid.shape[:2], np.int64)
        self._epoch = np.zeros(1, np.int64)
        self._coarse: dict[int, tuple] = {}  # factor -> (first epoch not pooled yet, the coarse grid)
        n = grid.num_cubes
        self._hit_value = np.zeros(n, np.float32)
        self._hit_stamp = np.zeros(n, np.int32)
        self._touch_stamp = np.zeros(n, np.int32)
        self._touched = np.zeros(n, np.int64)
        self._frame = 0

    # --- the maps ----------------------------------------------------------------------------------

    @property
    def log_odds(self) -> np.ndarray:
        """Log-odds per cube (float32), read-only: write through :meth:`edit`."""
        return _read_only(self._log_odds)

    @property
    def observed(self) -> np.ndarray:
        """Whether each cube was ever updated (bool), read-only: write through :meth:`edit`."""
        return _read_only(self._observed)

    @contextmanager
    def edit(self) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """The writable ``(log_odds, observed)`` maps, for writes other than stereo (a bumper's
        contact, a restored checkpoint, a test's scene); :meth:`coarsened` then pools them all again."""
        try:
            yield self._log_odds, self._observed
        finally:
            self._written[:] = self._epoch[0]

    # --- update ------------------------------------------------------------------------------------

    def integrate(self, u_px: np.ndarray, v_px: np.ndarray, d_px: np.ndarray, intrinsics: Intrinsics,
                  baseline_m: float, camera_in_world: RigidTransform) -> int:
        """Fold one frame's stereo points into the grid (eq. 6-8); return the number of cubes updated."""
        k, c = intrinsics, self.config
        _check_stereo(k, baseline_m, camera_in_world)
        u, v, d = (np.ascontiguousarray(a, np.float64) for a in (u_px, v_px, d_px))
        if not (u.ndim == v.ndim == d.ndim == 1 and len(u) == len(v) == len(d)):  # the kernel pairs them by index
            raise ValueError(f"stereo points need u, v and d of one length each, not shapes {u.shape}, {v.shape}, "
                             f"{d.shape}")
        # an infinite disparity is depth 0 (eq. 6): it would mark the camera's own cube occupied
        valid = np.isfinite(d) & (d > 0)
        range_px = k.fx_px * baseline_m / c.max_range_m  # the disparity at max range
        keep, beyond = valid & (d >= range_px), valid & (d < range_px) & c.clear_beyond_range
        camera = np.array([k.fx_px, k.fy_px, k.cx_px, k.cy_px, baseline_m])
        # the frame's pose in cube units: p_cube = (R p_cam + t - origin) / resolution
        rotation = camera_in_world.rotation / self.grid.resolution_m
        translation = (camera_in_world.translation - self.grid.origin) / self.grid.resolution_m
        self._frame += 1
        return int(_integrate_frame(
            self._log_odds.reshape(-1), self._observed.reshape(-1), self._written.reshape(-1), self._epoch[0],
            self._hit_value, self._hit_stamp, self._touch_stamp, self._touched, self._frame, u[keep], v[keep],
            d[keep], u[beyond], v[beyond], range_px, camera, np.ascontiguousarray(rotation), translation,
            np.array(self.grid.shape, np.int64),
            c.hit_scale, c.max_hit_per_frame, c.miss_log_odds, c.clamp_min, c.clamp_max))

    def integrate_disparity(self, disparity: np.ndarray, intrinsics: Intrinsics, baseline_m: float,
                            camera_in_world: RigidTransform) -> int:
        """Integrate every ``point_stride_px``-th valid pixel of a disparity image (NaN = invalid)."""
        if np.ndim(disparity) != 2:
            raise ValueError(f"a disparity image is 2-D (rows, columns), not of shape {np.shape(disparity)}")
        s = self.config.point_stride_px
        sub = disparity[s // 2::s, s // 2::s]
        v, u = np.nonzero(np.isfinite(sub) & (sub > 0))
        return self.integrate(u * s + s // 2, v * s + s // 2, sub[v, u], intrinsics, baseline_m, camera_in_world)

    # --- queries -----------------------------------------------------------------------------------

    def state(self) -> np.ndarray:
        """Three-valued occupancy per cube: UNKNOWN, FREE or OCCUPIED (uint8)."""
        out = np.full(self.grid.shape, UNKNOWN, np.uint8)
        out[self._observed & (self._log_odds <= self.config.free_log_odds)] = FREE
        out[self._observed & (self._log_odds >= self.config.occupied_log_odds)] = OCCUPIED
        return out

    def occupied(self) -> np.ndarray:
        return self._log_odds >= self.config.occupied_log_odds

    def seen_empty(self, max_log_odds: float, margin_cubes: int = 0, resting: bool = False) -> np.ndarray:
        """Cubes observed at or below ``max_log_odds`` that cannot hold a target's centre, given its
        half size ``margin_cubes``, so that one wrong far disparity through a target does not carve
        its centre out of the belief:

        - by default, every neighbour within the margin (the room's outside included) is seen empty
          too: a surface, unknown space or a wall that near keeps a cube;
        - ``resting`` (the target stands on a horizontal surface): no support top lies within the
          margin sideways and ``margin_cubes + 1`` below (the extra cube: stereo's error in the top's
          height). A support top is a cube not seen empty (a surface, or unknown space that may be
          one) under a cube seen empty, or the floor. Open space beside a wall or under the ceiling
          is empty; space just above a table, a shelf or the floor is kept."""
        empty = self._observed & (self._log_odds <= max_log_odds)
        if margin_cubes <= 0:
            return empty
        if resting:
            tops = np.zeros_like(empty)
            tops[:, :, :-1] = ~empty[:, :, :-1] & empty[:, :, 1:]
            holds = _grown(tops, 2, margin_cubes + 1, 0, outside=True)  # the floor: the outside below z = 0
            for axis in (0, 1):  # the room's walls have no top to stand on
                holds = _grown(holds, axis, margin_cubes, margin_cubes, outside=False)
        else:
            holds = ~empty
            for axis in range(3):  # a cube's neighbourhood is separable: grow along each axis in turn
                holds = _grown(holds, axis, margin_cubes, margin_cubes, outside=True)
        return empty & ~holds

    def cast_rays(self, origins_m: np.ndarray, directions: np.ndarray, max_range_m: float) -> RayHits:
        """Walk each ray to the first occupied cube (or the room's boundary, or ``max_range_m``);
        unknown space does not stop it (the expected sensed spheres' optimistic choice)."""
        origins, dirs = _checked_rays(origins_m, directions, max_range_m)
        origins, dirs = np.broadcast_arrays((origins - self.grid.origin) / self.grid.resolution_m, dirs)
        dist, hit = _cast_rays(self._log_odds, np.ascontiguousarray(origins), np.ascontiguousarray(dirs),
                               max_range_m / self.grid.resolution_m,
                               self.config.occupied_log_odds)
        return RayHits(dist * self.grid.resolution_m, hit)

    def coarsened(self, factor: int) -> OccupancyGrid:
        """The same map in cubes ``factor`` times larger: a block is as occupied as its most occupied
        observed cube and observed if any cube is. Ray casts on it take ``factor`` times fewer steps.

        The planner asks at every decision, and a look changes only part of the map: the blocks are
        kept per factor, and only those over a column written since are pooled again. So the result
        is one grid per factor, shared and brought up to date by each call (a new grid would cost
        more than the pooling): use it before the next call.

        Blocks cover the room in whole blocks, so where a side is not a whole number of them a ray
        runs up to a block past that wall. Harmless for planning, its one user: there is no cube of
        belief out there for the longer ray to reach."""
        if factor <= 1:
            return self
        if factor not in self._coarse:
            shape = tuple(-(-n // factor) for n in self.grid.shape)
            grid = VoxelGrid(tuple(n * factor * self.grid.resolution_m for n in shape),
                             self.grid.resolution_m * factor, self.grid.origin_m)
            self._coarse[factor] = (0, OccupancyGrid(grid))
        since, coarse = self._coarse[factor]
        _max_pool(self._log_odds, self._observed, factor, self._written, since, coarse._log_odds, coarse._observed)
        epoch = self._epoch[0]
        self._coarse[factor] = (epoch + 1, coarse)
        self._epoch[0] = epoch + 1  # later writes are newer than this pooling
        coarse.config = self.config  # a view of these maps (copy.copy) may have another
        return coarse

    def floor_map(self, robot_radius_m: float, robot_height_m: float, floor_clearance_m: float = 0.1) -> FloorMap:
        """Columns blocked for the base: anything occupied from ``floor_clearance_m`` (stereo noise on
        the floor is not an obstacle) up to the robot's height, inflated by its radius."""
        res = self.grid.resolution_m
        band = self.grid.layers(floor_clearance_m, robot_height_m)
        occupied = self.occupied()[:, :, band].any(axis=2)
        unknown = ~self._observed[:, :, band].any(axis=2)
        radius_cells = int(math.ceil(robot_radius_m / res))
        disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * radius_cells + 1, 2 * radius_cells + 1))
        padded = np.pad(occupied, radius_cells, constant_values=True)  # the walls bound the room
        inside = tuple(slice(radius_cells, radius_cells + n) for n in occupied.shape)
        blocked = cv2.dilate(padded.astype(np.uint8), disc)[inside]
        return FloorMap(res, occupied, blocked.astype(bool), unknown)


def _check_stereo(k: Intrinsics, baseline_m: float, camera_in_world: RigidTransform) -> None:
    """A frame the kernel can place: in front of the camera (z = f·B/d, eq. 6), from a finite pose."""
    if not (baseline_m > 0 and k.fx_px > 0 and k.fy_px > 0):  # else points land behind the camera
        raise ValueError(f"stereo needs a positive baseline and focal length, not {baseline_m} m and "
                         f"{k.fx_px}/{k.fy_px} px")
    if not (math.isfinite(k.cx_px) and math.isfinite(k.cy_px)):  # NaN dropped every point, unsaid
        raise ValueError(f"stereo needs a finite principal point, not cx {k.cx_px} / cy {k.cy_px} px")
    for name in ("rotation", "translation"):  # NaN dropped the frame or updated stray cubes, unsaid
        value = np.asarray(getattr(camera_in_world, name))
        if not np.isfinite(value).all():
            raise ValueError(f"a frame needs a finite camera pose, not {name} {value.tolist()}")


def _checked_rays(origins_m: np.ndarray, directions: np.ndarray, max_range_m: float) -> tuple[np.ndarray, ...]:
    """The origins (n, 3) and unit directions (n, 3), or 1 for n, of rays that the kernel can walk."""
    origins, dirs = np.atleast_2d(origins_m).astype(np.float64), np.atleast_2d(directions).astype(np.float64)
    paired = len(origins) == len(dirs) or 1 in (len(origins), len(dirs))  # else numpy broadcasting fails
    if origins.shape[1:] != (3,) or dirs.shape[1:] != (3,) or not paired:
        raise ValueError(f"rays need one origin or one per direction, each a 3-vector: got origins "
                         f"{origins.shape} and directions {dirs.shape}")  # the kernel checks no bounds
    for name, value in (("origins", origins), ("directions", dirs)):  # a NaN origin hit at 0 m, unsaid
        if not np.isfinite(value).all():
            raise ValueError(f"rays need finite {name}, not {value[~np.isfinite(value).all(axis=1)][0].tolist()}")
    if not (math.isfinite(max_range_m) and max_range_m > 0):  # else a negative or NaN distance
        raise ValueError(f"rays need a finite, positive max range, not {max_range_m} m")
    norms = np.linalg.norm(dirs, axis=1, keepdims=True)
    if not np.all(norms > 0):
        raise ValueError("a ray's direction must not be the zero vector")
    return origins, dirs / norms


def _read_only(array: np.ndarray) -> np.ndarray:
    view = array.view()
    view.flags.writeable = False
    return view


# --- kernels ---------------------------------------------------------------------------------------

@numba.njit(cache=True)
def _max_pool(log_odds, observed, factor, written, since, out_log_odds, out_observed):
    """Pool each block of ``factor``³ cubes into its coarse cube (unobserved: log-odds 0), for the
    coarse columns over a fine column ``written`` at epoch ``since`` or later; the others are kept.
    A block's fine columns are first folded into one column of fine cubes, with a select rather than
    a branch and no index arithmetic, so that the innermost loop, along memory, vectorises; only
    then are runs of ``factor`` cubes along z folded."""
    nx, ny, nz = log_odds.shape
    best = np.empty(nz, np.float32)  # per fine z: the block's largest observed log-odds so far
    seen = np.empty(nz, np.bool_)
    for a in range(out_log_odds.shape[0]):
        i0, i1 = a * factor, min((a + 1) * factor, nx)
        for b in range(out_log_odds.shape[1]):
            j0, j1 = b * factor, min((b + 1) * factor, ny)
            if written[i0:i1, j0:j1].max() < since:
                continue
            best[:] = -np.inf
            seen[:] = False
            for i in range(i0, i1):
                for j in range(j0, j1):
                    column, column_observed = log_odds[i, j], observed[i, j]
                    for k in range(nz):
                        value = column[k] if column_observed[k] else np.float32(-np.inf)
                        best[k] = value if value > best[k] else best[k]
                        seen[k] |= column_observed[k]
            for c in range(out_log_odds.shape[2]):
                k0, k1 = c * factor, min((c + 1) * factor, nz)
                value, any_seen = best[k0], seen[k0]
                for k in range(k0 + 1, k1):
                    value = best[k] if best[k] > value else value
                    any_seen |= seen[k]
                out_log_odds[a, b, c] = value if any_seen else np.float32(0.0)
                out_observed[a, b, c] = any_seen


@numba.njit(cache=True)
def _flat(i, j, k, shape):
    return (i * shape[1] + j) * shape[2] + k


@numba.njit(cache=True)
def _touch(c, frame, touch_stamp, touched, n_touched):
    if touch_stamp[c] != frame:
        touch_stamp[c] = frame
        touched[n_touched] = c
        return n_touched + 1
    return n_touched


@numba.njit(cache=True, inline="always")
def _to_cubes(u, v, d, camera, rotation, translation):
    """Pixel (u, v) at disparity d to a point in cube units (z = f·B/d, eq. 6): Intrinsics.back_project
    and the camera's pose in one, for numba, on scalars, without allocating."""
    z = camera[0] * camera[4] / d
    x = (u - camera[2]) * z / camera[0]
    y = (v - camera[3]) * z / camera[1]
    return (rotation[0, 0] * x + rotation[0, 1] * y + rotation[0, 2] * z + translation[0],
            rotation[1, 0] * x + rotation[1, 1] * y + rotation[1, 2] * z + translation[1],
            rotation[2, 0] * x + rotation[2, 1] * y + rotation[2, 2] * z + translation[2])


@numba.njit(cache=True)
def _integrate_frame(log_odds, observed, written, epoch, hit_value, hit_stamp, touch_stamp, touched, frame,
                     u, v, d, far_u, far_v, range_d, camera, rotation, translation, shape, hit_scale, max_hit,
                     miss, clamp_min, clamp_max):
    n_touched = 0
    lo = np.empty(3, np.int64)
    hi = np.empty(3, np.int64)
    for p in range(u.shape[0]):  # eq. 6-7: evidence 1/|C| for each cube C of the region
        lo[:] = 1 << 40
        hi[:] = -(1 << 40)
        for su in (-0.5, 0.5):
            for sv in (-0.5, 0.5):
                for sd in (-0.5, 0.5):
                    q = _to_cubes(u[p] + su, v[p] + sv, max(d[p] + sd, 0.25), camera, rotation, translation)
                    for a in range(3):
                        cell = int(math.floor(q[a]))
                        lo[a] = min(lo[a], cell)
                        hi[a] = max(hi[a], cell)
        hit = hit_scale / ((hi[0] - lo[0] + 1) * (hi[1] - lo[1] + 1) * (hi[2] - lo[2] + 1))
        for i in range(max(lo[0], 0), min(hi[0] + 1, shape[0])):
            for j in range(max(lo[1], 0), min(hi[1] + 1, shape[1])):
                for k in range(max(lo[2], 0), min(hi[2] + 1, shape[2])):
                    c = _flat(i, j, k, shape)
                    if hit_stamp[c] != frame:
                        hit_stamp[c] = frame
                        hit_value[c] = min(hit, max_hit)
                        n_touched = _touch(c, frame, touch_stamp, touched, n_touched)
                    else:
                        hit_value[c] = min(hit_value[c] + hit, max_hit)
    for p in range(u.shape[0]):  # eq. 8: free from the camera to where the region begins
        near = _to_cubes(u[p], v[p], d[p] + 0.5, camera, rotation, translation)
        n_touched = _walk_free(translation[0], translation[1], translation[2], near[0], near[1], near[2],
                               shape, frame, hit_stamp, touch_stamp, touched, n_touched)
    for p in range(far_u.shape[0]):  # beyond max range: free out to it, nothing hit
        end = _to_cubes(far_u[p], far_v[p], range_d, camera, rotation, translation)
        n_touched = _walk_free(translation[0], translation[1], translation[2], end[0], end[1], end[2],
                               shape, frame, hit_stamp, touch_stamp, touched, n_touched)
    for t in range(n_touched):  # each cube once; occupied wins over free
        c = touched[t]
        value = log_odds[c] + (hit_value[c] if hit_stamp[c] == frame else miss)
        log_odds[c] = min(max(value, clamp_min), clamp_max)
        observed[c] = True
        written[c // shape[2]] = epoch  # its x-y column, for coarsened()
    return n_touched


@numba.njit(cache=True, inline="always")
def _axis_setup(start, direction):
    """DDA set-up on one axis: (cell, step, t to the first boundary, t between boundaries)."""
    cell = int(math.floor(start))
    if direction > 0:
        return cell, 1, (cell + 1 - start) / direction, 1.0 / direction
    if direction < 0:
        return cell, -1, (start - cell) / -direction, -1.0 / direction
    return cell, 0, np.inf, np.inf


@numba.njit(cache=True)
def _walk_free(x0, y0, z0, x1, y1, z1, shape, frame, hit_stamp, touch_stamp, touched, n_touched):
    """Amanatides-Woo voxel walk from the camera to a region's near end (cube units), marking free."""
    i, si, ti, di = _axis_setup(x0, x1 - x0)
    j, sj, tj, dj = _axis_setup(y0, y1 - y0)
    k, sk, tk, dk = _axis_setup(z0, z1 - z0)
    i1, j1, k1 = int(math.floor(x1)), int(math.floor(y1)), int(math.floor(z1))
    while not (i == i1 and j == j1 and k == k1):
        if 0 <= i < shape[0] and 0 <= j < shape[1] and 0 <= k < shape[2]:
            c = _flat(i, j, k, shape)
            if hit_stamp[c] != frame:
                n_touched = _touch(c, frame, touch_stamp, touched, n_touched)
        if ti <= tj and ti <= tk:
            if ti > 1.0:
                break
            i += si
            ti += di
        elif tj <= tk:
            if tj > 1.0:
                break
            j += sj
            tj += dj
        else:
            if tk > 1.0:
                break
            k += sk
            tk += dk
    return n_touched


@numba.njit(cache=True, parallel=True)
def _cast_rays(log_odds, origins, dirs, max_steps, occupied_lo):
    n = origins.shape[0]
    shape = log_odds.shape
    dist = np.empty(n)
    hit = np.zeros(n, np.bool_)
    for r in numba.prange(n):
        dist[r], hit[r] = _cast_one(log_odds, origins[r], dirs[r], max_steps, occupied_lo, shape)
    return dist, hit


@numba.njit(cache=True)
def _cast_one(log_odds, start, direction, max_t, occupied_lo, shape):
    i, si, ti, di = _axis_setup(start[0], direction[0])
    j, sj, tj, dj = _axis_setup(start[1], direction[1])
    k, sk, tk, dk = _axis_setup(start[2], direction[2])
    t_entry = 0.0
    while t_entry <= max_t:
        if not (0 <= i < shape[0] and 0 <= j < shape[1] and 0 <= k < shape[2]):
            return t_entry, True  # the room's boundary is known (report §3.1)
        if log_odds[i, j, k] >= occupied_lo:
            return t_entry, True
        if ti <= tj and ti <= tk:
            t_entry = ti
            i += si
            ti += di
        elif tj <= tk:
            t_entry = tj
            j += sj
            tj += dj
        else:
            t_entry = tk
            k += sk
            tk += dk
    return max_t, False


def _grown(mask: np.ndarray, axis: int, before: int, after: int, outside: bool) -> np.ndarray:
    """``mask`` grown along ``axis``: a cube is set if one at most ``before`` cubes before it or
    ``after`` cubes after it is; beyond the grid's ends counts as ``outside``."""
    grown = mask.copy()
    out, src = np.moveaxis(grown, axis, 0), np.moveaxis(mask, axis, 0)
    for k in range(1, before + 1):
        out[k:] |= src[:-k]
    for k in range(1, after + 1):
        out[:-k] |= src[k:]
    if outside:
        out[:before] = True
        out[len(out) - after:] = True
    return grown

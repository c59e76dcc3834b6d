"""Expected value of looks not yet taken: P_Ψ(f) (eq. 1) for every action, and the covering
probability of every candidate position (report §3.3.2-3.3.3).

Paper symbols, named once: ``P_Ψ(f)`` → ``find_prob`` (the probability that action f finds the
target, Σ p(c, τ)·b(c, f); ``b`` itself is a look's ``detection_prob``, per cube); ``Prob_Ψj`` →
``covering_prob``.

An action f is a camera position (a candidate floor position at the head's height) and a camera
setting (world azimuth, tilt). Its expected detection probability sums, over the cubes its view
would cover inside the expected sensed sphere, the target probability times the detector's measured
detectability at that distance, off-axis angle and facing angle — the expected b(c, f). To score
all 544 actions of the report's room in a few milliseconds the belief is read at a coarser
resolution (blocks of cubes, :meth:`TargetBelief.coarse_mass`); the update after a real look is
exact per cube (:mod:`offboard.planning.detection_function`).

The covering probability ``Prob_Ψj`` of a position is the report's mass inside its sensed sphere,
each block weighted by the best detectability any setting from there has on it: the probability
that looking around from there would find the target. Unweighted, the sphere's far shell (where
the detector only sometimes succeeds: SIFT at 4-6 m) makes a distant position look as good as a
near one, and eq. 11 then shuttles between cheap positions whose looks each find little; mass the
position can never see (outside every view, facing away) counts for nothing either way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from offboard.planning.belief import TargetBelief
from offboard.perception.detectability import DetectabilityTable, bin_index, cosine_bin
from offboard.planning.sensed_sphere import SensedSpheres, SphereBins
from shared.geometry import HeadMount, Intrinsics, Pose2D


@dataclass(frozen=True)
class CameraSettings:
    """The camera settings looked at from any position: world azimuth and tilt pairs."""

    azimuth_rad: np.ndarray  # (S,)
    tilt_rad: np.ndarray  # (S,)

    @classmethod
    def from_fov(cls, intrinsics: Intrinsics, tilts_deg: tuple[float, ...] = (0.0, 30.0),
                 overlap: float = 0.4) -> CameraSettings:
        """Azimuths spaced by the horizontal field of view less ``overlap``, widened by 1/cos(tilt)
        at raised tilts (a view's azimuth span grows as it looks up). With the Bumblebee's 66° and
        tilts 0° and 30° this gives 9 + 8 = 17 settings, the report's 17."""
        hfov = intrinsics.hfov_rad
        az, tilt = [], []
        for t in tilts_deg:
            count = max(1, round(2 * math.pi / (hfov * (1 - overlap) / math.cos(math.radians(t)))))
            az += list(-math.pi + (np.arange(count) + 0.5) * 2 * math.pi / count)
            tilt += [math.radians(t)] * count
        return cls(np.array(az), np.array(tilt))

    def __len__(self) -> int:
        return len(self.azimuth_rad)

    def rotations(self, mount: HeadMount) -> np.ndarray:
        """World-from-optical rotation of every setting, shape (S, 3, 3)."""
        return np.stack([mount.camera_in_world(Pose2D(0.0, 0.0, a), 0.0, t).rotation
                         for a, t in zip(self.azimuth_rad, self.tilt_rad)])


@dataclass(frozen=True)
class ActionValues:
    find_prob: np.ndarray  # (P, S): expected P_Ψ(f), eq. 1
    covering_prob: np.ndarray  # (P,): Prob_Ψj, mass inside the sensed sphere weighted by its best detectability


def block_centers(belief: TargetBelief) -> np.ndarray:
    """Centre of the cubes in each coarse block, shape (blocks, 3)."""
    grid, f = belief.grid, belief.coarse_factor
    axes = []
    for a, (n, nc) in enumerate(zip(grid.shape, belief.coarse_shape)):
        first = np.arange(nc) * f
        count = np.minimum(f, n - first)
        axes.append(grid.origin_m[a] + (first + count / 2.0) * grid.resolution_m)
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


class ActionGeometry:
    """Where every coarse block lies as seen from camera positions, one row per position.

    Distances, bins and off-axis angles of the blocks from a position never change; only the
    belief's masses and the sensed spheres' radii do. With them computed once, scoring every action
    is a gather-multiply-add. Rows can be re-placed at new positions (:meth:`place`), so a cache
    can reuse its memory instead of allocating and stacking per decision.
    """

    def __init__(self, belief: TargetBelief, positions_m: np.ndarray, settings: CameraSettings,
                 mount: HeadMount, intrinsics: Intrinsics, table: DetectabilityTable, bins: SphereBins,
                 capacity: int = 0):
        """Rows for ``positions_m`` (P, 2), computed now, and ``capacity`` rows in all (at least P)."""
        positions_m = np.asarray(positions_m, np.float64).reshape(-1, 2)
        rows = max(capacity, len(positions_m))
        self._blocks_m = block_centers(belief)
        n_blk, n_set, n_fac = len(self._blocks_m), len(settings), belief.facing_sectors
        self.positions_m = np.full((rows, 2), np.nan)
        self.distance_m = np.empty((rows, n_blk), np.float32)
        self.sphere_bin = np.empty((rows, n_blk), np.int32)
        self.distance_bin = np.empty((rows, n_blk), np.int16)
        self.facing_bin = np.empty((rows, n_blk, n_fac), np.int8)
        self.off_axis_bin = np.empty((rows, n_blk, n_set), np.int8)
        _check_bins_fit(table, self.distance_bin, self.off_axis_bin, self.facing_bin)
        near, far = table.range_m
        self._view = np.array([bins.el_min_rad, bins.el_max_rad, near, far,
                               math.tan(intrinsics.hfov_rad / 2), math.tan(intrinsics.vfov_rad / 2)])
        self.bins = bins  # the sensed spheres evaluated with it must share them
        self._rotations = np.ascontiguousarray(settings.rotations(mount))
        facings = belief.facing_azimuths_rad
        self._facing_xy = np.column_stack([np.cos(facings), np.sin(facings)])  # NaN: faces the camera
        self._cos_edges = tuple(np.cos(np.radians(e)) for e in (table.off_axis_edges_deg, table.facing_edges_deg))
        self.height_m = mount.height_m
        self.block_margin_m = 0.5 * belief.coarse_factor * belief.grid.resolution_m
        self.table = table
        self.place(np.arange(len(positions_m)), positions_m)

    def cameras_m(self, rows: np.ndarray) -> np.ndarray:
        """Where the camera is (R, 3) for each of ``rows``: its position at the head's height."""
        return np.column_stack([self.positions_m[rows], np.full(len(rows), self.height_m)])

    def place(self, rows: np.ndarray, positions_m: np.ndarray) -> None:
        """Recompute ``rows`` (distinct) for the camera at ``positions_m`` (R, 2)."""
        rows = np.asarray(rows, np.int64)
        if not len(rows):
            return
        self.positions_m[rows] = positions_m
        t = self.table
        _geometry(self._blocks_m, self.cameras_m(rows), rows, self._view, self.bins.el_count, self.bins.az_count,
                  self._rotations, t.distance_edges_m, *self._cos_edges, self._facing_xy, self.distance_m, self.sphere_bin, self.distance_bin,
                  self.facing_bin, self.off_axis_bin)


def _check_bins_fit(table: DetectabilityTable, distance_bin: np.ndarray, off_axis_bin: np.ndarray,
                    facing_bin: np.ndarray) -> None:
    """Refuse a table with more bins than the geometry's small integers hold (kept small: a cache
    holds hundreds of rows); a bin index past them would wrap to a negative one, read as out of view."""
    for name, count, bins in (("distance", table.rate.shape[0], distance_bin),
                              ("off-axis", table.rate.shape[1], off_axis_bin),
                              ("facing", table.rate.shape[2], facing_bin)):
        if count - 1 > np.iinfo(bins.dtype).max:
            raise ValueError(f"the detectability table's {count} {name} bins do not fit the planner's "
                             f"{bins.dtype} bin indices (at most {np.iinfo(bins.dtype).max + 1})")


class GeometryCache:
    """Action geometries of candidate positions, kept by position in the rows of one
    :class:`ActionGeometry`: candidates come and go between decisions, but they stand on a lattice,
    so each one's geometry is computed once (the least recently used row is reused beyond
    ``capacity``)."""

    def __init__(self, belief: TargetBelief, settings: CameraSettings, mount: HeadMount, intrinsics: Intrinsics,
                 table: DetectabilityTable, bins: SphereBins, capacity: int = 256):
        self.geometry = ActionGeometry(belief, np.zeros((0, 2)), settings, mount, intrinsics, table, bins, capacity)
        self._rows: dict[tuple[float, float], int] = {}  # position → row; the dict's order is the recency

    def rows(self, positions_m: np.ndarray) -> np.ndarray:
        """The rows of :attr:`geometry` holding ``positions_m`` (P, 2), computing those not held; the
        distinct positions must fit the capacity."""
        positions_m = np.asarray(positions_m, np.float64).reshape(-1, 2)
        keys = [(round(float(x), 6), round(float(y), 6)) for x, y in positions_m]
        wanted = set(keys)
        capacity = len(self.geometry.positions_m)
        if len(wanted) > capacity:
            raise ValueError(f"{len(wanted)} candidate positions do not fit a geometry cache of {capacity}")
        # rows never used first, then those of the least recently used positions not wanted now
        free = iter([(None, r) for r in range(len(self._rows), capacity)]
                    + [(k, r) for k, r in self._rows.items() if k not in wanted])
        placed: dict[int, np.ndarray] = {}
        for key, xy in zip(keys, positions_m):
            if key in self._rows:
                self._rows[key] = self._rows.pop(key)  # now the most recently used
                continue
            old, row = next(free)
            if old is not None:
                del self._rows[old]
            self._rows[key] = row
            placed[row] = xy
        self.geometry.place(np.fromiter(placed, np.int64, len(placed)),
                            np.array(list(placed.values())).reshape(-1, 2))
        return np.array([self._rows[k] for k in keys], np.int64)


def heavy_blocks(belief: TargetBelief, share: float = 1e-3, most: int = 64) -> np.ndarray:
    """The blocks holding at least ``share`` of the target probability each (at most ``most``, the
    heaviest): after a detection, where the belief has gathered. Whether a look sees them decides
    what it is worth, so :func:`evaluate` judges their occlusion along the exact ray to them, not
    along the axis of their sphere bin (7.5° wide: its axis may hit the shelf the target stands on)."""
    mass = belief.coarse_mass().reshape(-1, belief.facing_sectors).sum(axis=1)
    order = np.argsort(-mass)[:most]
    return order[mass[order] >= share]


def evaluate(geometry: ActionGeometry, rows: np.ndarray, belief: TargetBelief, spheres: SensedSpheres,
             behind_surface_m: float = 0.0, heavy: np.ndarray | None = None) -> ActionValues:
    """Expected detection probability of every (position, setting), covering probability of every
    position, for the positions in ``rows`` of the geometry; ``spheres`` are their sensed spheres,
    in the same order. A block counts up to half a block plus ``behind_surface_m`` beyond its
    direction's sphere radius (the target's centre lies behind the face a look sees, as
    :func:`~offboard.planning.detection_function.look_footprint` counts it), plus the cube size of the map the spheres were cast on: its occupied cubes begin up
    to that much before the surface the real look's stereo depth will see. Without it the planner
    underestimated its looks at a target already detected once (expected 0.39 against 0.51 realised
    on the dev suite), whose mass sits just behind the surface. ``heavy`` (T,): blocks whose
    occlusion is read from ``spheres.toward_m`` (cast toward their centres, in that order) instead."""
    mass = np.ascontiguousarray(belief.coarse_mass().reshape(-1, belief.facing_sectors))
    rows = np.asarray(rows, np.int64)
    _check_inputs(geometry, rows, mass, spheres, heavy)
    radius = spheres.radius_m.reshape(len(rows), -1)
    slot = np.full(len(mass), -1, np.int32)
    if heavy is not None:
        slot[np.asarray(heavy, np.int64)] = np.arange(len(heavy), dtype=np.int32)
    rate = np.ascontiguousarray(geometry.table.rate)
    detection, covering = _score(mass, rows, geometry.distance_m, geometry.sphere_bin, geometry.distance_bin,
                                 geometry.facing_bin, geometry.off_axis_bin, np.ascontiguousarray(radius),
                                 slot, np.ascontiguousarray(spheres.toward_m, np.float64),
                                 geometry.block_margin_m + behind_surface_m + spheres.resolution_m, rate)
    return ActionValues(detection, covering)


def _check_inputs(geometry: ActionGeometry, rows: np.ndarray, mass: np.ndarray, spheres: SensedSpheres,
                  heavy: np.ndarray | None) -> None:
    """Refuse inputs that do not match the rows: the kernel does not check its indices and would
    read past its arrays, into wrong sums."""
    capacity, blocks, sectors = geometry.facing_bin.shape
    if rows.ndim != 1 or (len(rows) and (rows.min() < 0 or rows.max() >= capacity)):
        raise ValueError(f"rows must be a list of the geometry's {capacity} rows, not {rows}")
    if mass.shape != (blocks, sectors):
        raise ValueError(f"the belief's blocks and facings {mass.shape} are not the geometry's {(blocks, sectors)}")
    if spheres.bins != geometry.bins:  # the same counts over other elevations would be read as these
        raise ValueError(f"the spheres' bins {spheres.bins} are not the geometry's {geometry.bins}")
    if spheres.radius_m.shape != (len(rows), geometry.bins.el_count, geometry.bins.az_count):
        raise ValueError(f"spheres.radius_m has shape {spheres.radius_m.shape}, not one sphere per row "
                         f"{(len(rows), geometry.bins.el_count, geometry.bins.az_count)}")
    if heavy is not None and np.shape(spheres.toward_m) != (len(rows), len(heavy)):
        raise ValueError(f"spheres.toward_m has shape {np.shape(spheres.toward_m)}, not one radius per row "
                         f"and heavy block {(len(rows), len(heavy))}")


@numba.njit(cache=True, parallel=True)
def _geometry(centers, positions, rows, geometry, n_el, n_az, rotations, d_edges, o_cos, f_cos, facing_xy,
              distance, sphere_bin, distance_bin, facing_bin, off_axis_bin):
    """Fill ``rows`` of the geometry arrays for the camera at ``positions`` (R, 3): per block,
    distance, sphere bin (-1 out of reach), distance bin, facing bins, off-axis bin per setting (-1
    outside the view). Angles are binned by their cosines (``o_cos``, ``f_cos``: the edges'); a
    facing's cosine is that of :func:`~offboard.perception.detectability.facing_angle`, the face's
    normal ``facing_xy`` dotted with the unit ray back to the camera."""
    el_min, el_max, inner, outer, tan_h, tan_v = geometry
    n_blk, n_set, n_fac = centers.shape[0], rotations.shape[0], facing_xy.shape[0]
    for q in numba.prange(rows.shape[0]):
        p = rows[q]
        distance[p, :] = np.inf
        sphere_bin[p, :] = -1
        distance_bin[p, :] = -1
        facing_bin[p, :, :] = -1
        off_axis_bin[p, :, :] = -1
        for c in range(n_blk):
            wx = centers[c, 0] - positions[q, 0]
            wy = centers[c, 1] - positions[q, 1]
            wz = centers[c, 2] - positions[q, 2]
            dist = math.sqrt(wx * wx + wy * wy + wz * wz)
            if dist < inner or dist > outer:
                continue
            ai = min(int((math.atan2(wy, wx) + math.pi) / (2 * math.pi) * n_az), n_az - 1)
            # floor, not int(): int() rounds half a bin below the lowest up into it
            ei = int(math.floor((math.asin(wz / dist) - el_min) / (el_max - el_min) * n_el))
            if ei < 0 or ei >= n_el:
                continue  # beyond what any tilt can see
            distance[p, c] = dist
            sphere_bin[p, c] = ei * n_az + ai
            distance_bin[p, c] = bin_index(d_edges, dist)
            for s in range(n_fac):
                fx, fy = facing_xy[s, 0], facing_xy[s, 1]
                cosine = 1.0 if math.isnan(fx) else -(fx * wx + fy * wy) / dist
                facing_bin[p, c, s] = cosine_bin(f_cos, max(-1.0, min(1.0, cosine)))
            for a in range(n_set):
                r = rotations[a]
                x = r[0, 0] * wx + r[1, 0] * wy + r[2, 0] * wz
                y = r[0, 1] * wx + r[1, 1] * wy + r[2, 1] * wz
                z = r[0, 2] * wx + r[1, 2] * wy + r[2, 2] * wz
                if z > 0.0 and abs(x) <= tan_h * z and abs(y) <= tan_v * z:
                    off_axis_bin[p, c, a] = cosine_bin(o_cos, max(-1.0, min(z / dist, 1.0)))


@numba.njit(cache=True, parallel=True)
def _score(mass, rows, distance, sphere_bin, distance_bin, facing_bin, off_axis_bin, radius, slot, toward, margin,
           rate):
    """Per row of ``rows`` (a position), the expected detection of each setting and the covering."""
    n_pos, n_blk = rows.shape[0], distance.shape[1]
    n_set, n_fac = off_axis_bin.shape[2], mass.shape[1]
    detection = np.zeros((n_pos, n_set))
    covering = np.zeros(n_pos)
    best = np.zeros((n_pos, n_fac))  # per position: best detectability of the block at hand, per facing
    for p in numba.prange(n_pos):
        g = rows[p]  # the position's row in the geometry
        for c in range(n_blk):
            sb, db = sphere_bin[g, c], distance_bin[g, c]
            if sb < 0 or db < 0:
                continue  # out of reach
            reach = radius[p, sb] if slot[c] < 0 else toward[p, slot[c]]
            if distance[g, c] > reach + margin:
                continue  # behind the first obstacle in that direction
            best[p, :] = 0.0
            for a in range(n_set):
                ob = off_axis_bin[g, c, a]
                if ob < 0:
                    continue
                value = 0.0
                for s in range(n_fac):
                    fb = facing_bin[g, c, s]
                    if fb >= 0:
                        b = rate[db, ob, fb]
                        value += mass[c, s] * b
                        best[p, s] = max(best[p, s], b)
                detection[p, a] += value
            for s in range(n_fac):
                covering[p] += mass[c, s] * best[p, s]
    return detection, covering

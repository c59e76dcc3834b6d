"""Expected value of looks not yet taken: P_Ψ(f) (eq. 1) for every action, and the covering
probability of every candidate position (report §3.3.2-3.3.3).

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
from offboard.perception.detectability import DetectabilityTable, bin_index, facing_angle
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
    detection_prob: np.ndarray  # (P, S): expected P_Ψ(f), eq. 1
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
    """Where every coarse block lies as seen from each camera position, computed once.

    Candidate positions are fixed floor-grid vertices, so distances, bins and off-axis angles of the
    blocks from them never change; only the belief's masses and the sensed spheres' radii do. With
    this cache, scoring every action is a gather-multiply-add.
    """

    def __init__(self, belief: TargetBelief, positions_m: np.ndarray, settings: CameraSettings,
                 mount: HeadMount, intrinsics: Intrinsics, table: DetectabilityTable, bins: SphereBins):
        self.positions_m = np.atleast_2d(np.asarray(positions_m, np.float64))
        self.centers_m = np.column_stack([self.positions_m[:, :2], np.full(len(self.positions_m), mount.height_m)])
        near, far = table.range_m
        geometry = np.array([bins.el_min_rad, bins.el_max_rad, near, far,
                             math.tan(intrinsics.hfov_rad / 2), math.tan(intrinsics.vfov_rad / 2)])
        self.distance_m, self.sphere_bin, self.distance_bin, self.facing_bin, self.off_axis_bin = _geometry(
            block_centers(belief), self.centers_m, geometry, bins.el_count, bins.az_count,
            np.ascontiguousarray(settings.rotations(mount)), table.distance_edges_m, table.off_axis_edges_deg,
            table.facing_edges_deg, belief.facing_azimuths_rad)
        self.block_margin_m = 0.5 * belief.coarse_factor * belief.grid.resolution_m
        self.table = table

    @classmethod
    def stack(cls, parts: list[ActionGeometry]) -> ActionGeometry:
        """One geometry of the positions of ``parts``, in order."""
        whole = object.__new__(cls)
        for name in ("positions_m", "centers_m", "distance_m", "sphere_bin", "distance_bin", "facing_bin",
                     "off_axis_bin"):
            setattr(whole, name, np.concatenate([getattr(p, name) for p in parts]))
        whole.block_margin_m, whole.table = parts[0].block_margin_m, parts[0].table
        return whole


class GeometryCache:
    """Action geometries of single positions, kept by lattice node: candidates come and go between
    decisions, but each is placed on the lattice, so its geometry is computed once (least recently
    used ones are dropped beyond ``capacity``)."""

    def __init__(self, belief: TargetBelief, settings: CameraSettings, mount: HeadMount, intrinsics: Intrinsics,
                 table: DetectabilityTable, bins: SphereBins, lattice_m: float, capacity: int = 256):
        self._make = lambda xy: ActionGeometry(belief, xy[None], settings, mount, intrinsics, table, bins)
        self.lattice_m = lattice_m
        self.capacity = capacity
        self._cache: dict[tuple[int, int], ActionGeometry] = {}

    def rows(self, positions_m: np.ndarray) -> ActionGeometry:
        parts = []
        for xy in np.asarray(positions_m, np.float64):
            key = tuple(int(v) for v in np.round(xy / self.lattice_m))
            part = self._cache.pop(key, None)  # re-inserted below: the dict's order is the recency
            if part is None or not np.allclose(part.positions_m[0], xy):
                part = self._make(xy)
            self._cache[key] = part
            parts.append(part)
        while len(self._cache) > self.capacity:
            del self._cache[next(iter(self._cache))]
        return ActionGeometry.stack(parts)


def heavy_blocks(belief: TargetBelief, share: float = 1e-3, most: int = 64) -> np.ndarray:
    """The blocks holding at least ``share`` of the target probability each (at most ``most``, the
    heaviest): after a detection, where the belief has gathered. Whether a look sees them decides
    what it is worth, so :func:`evaluate` judges their occlusion along the exact ray to them, not
    along the axis of their sphere bin (7.5° wide: its axis may hit the shelf the target stands on)."""
    mass = belief.coarse_mass().reshape(-1, belief.facing_sectors).sum(axis=1)
    order = np.argsort(-mass)[:most]
    return order[mass[order] >= share]


def evaluate(geometry: ActionGeometry, belief: TargetBelief, spheres: SensedSpheres,
             behind_surface_m: float = 0.0, heavy: np.ndarray | None = None) -> ActionValues:
    """Expected detection probability of every (position, setting), covering probability of every
    position; ``spheres`` are the positions' sensed spheres, in the geometry's order. A block counts
    up to half a block plus ``behind_surface_m`` beyond its direction's sphere radius (the target's
    centre lies behind the face a look sees, as :func:`~offboard.planning.detection_function.look_footprint`
    counts it), plus the cube size of the map the spheres were cast on: its occupied cubes begin up
    to that much before the surface the real look's stereo depth will see. Without it the planner
    underestimated its looks at a target already detected once (expected 0.39 against 0.51 realised
    on the dev suite), whose mass sits just behind the surface. ``heavy`` (T,): blocks whose
    occlusion is read from ``spheres.toward_m`` (cast toward their centres, in that order) instead."""
    mass = np.ascontiguousarray(belief.coarse_mass().reshape(-1, belief.facing_sectors))
    radius = spheres.radius_m.reshape(len(geometry.positions_m), -1)
    slot = np.full(len(mass), -1, np.int32)
    if heavy is not None:
        slot[np.asarray(heavy, np.int64)] = np.arange(len(heavy), dtype=np.int32)
    rate = np.ascontiguousarray(geometry.table.rate)
    detection, covering = _score(mass, geometry.distance_m, geometry.sphere_bin, geometry.distance_bin,
                                 geometry.facing_bin, geometry.off_axis_bin, np.ascontiguousarray(radius),
                                 slot, np.ascontiguousarray(spheres.toward_m, np.float64),
                                 geometry.block_margin_m + behind_surface_m + spheres.resolution_m, rate)
    return ActionValues(detection, covering)


@numba.njit(cache=True, parallel=True)
def _geometry(centers, positions, geometry, n_el, n_az, rotations, d_edges, o_edges, f_edges, facings):
    """Per position and block: distance, sphere bin (-1 out of reach), distance bin, facing bins,
    off-axis bin per setting (-1 outside the view)."""
    el_min, el_max, inner, outer, tan_h, tan_v = geometry
    n_pos, n_blk, n_set, n_fac = positions.shape[0], centers.shape[0], rotations.shape[0], facings.shape[0]
    distance = np.full((n_pos, n_blk), np.inf, np.float32)
    sphere_bin = np.full((n_pos, n_blk), -1, np.int32)
    distance_bin = np.full((n_pos, n_blk), -1, np.int16)
    facing_bin = np.full((n_pos, n_blk, n_fac), -1, np.int8)
    off_axis_bin = np.full((n_pos, n_blk, n_set), -1, np.int8)
    for p in numba.prange(n_pos):
        for c in range(n_blk):
            wx = centers[c, 0] - positions[p, 0]
            wy = centers[c, 1] - positions[p, 1]
            wz = centers[c, 2] - positions[p, 2]
            dist = math.sqrt(wx * wx + wy * wy + wz * wz)
            if dist < inner or dist > outer:
                continue
            ai = min(int((math.atan2(wy, wx) + math.pi) / (2 * math.pi) * n_az), n_az - 1)
            ei = int((math.asin(wz / dist) - el_min) / (el_max - el_min) * n_el)
            if ei < 0 or ei >= n_el:
                continue  # beyond what any tilt can see
            distance[p, c] = dist
            sphere_bin[p, c] = ei * n_az + ai
            distance_bin[p, c] = bin_index(d_edges, dist)
            back = math.atan2(-wy, -wx)
            cos_el = math.hypot(wx, wy) / dist
            for s in range(n_fac):
                diff = facing_angle(facings[s], back, cos_el)
                facing_bin[p, c, s] = bin_index(f_edges, math.degrees(diff))
            for a in range(n_set):
                r = rotations[a]
                x = r[0, 0] * wx + r[1, 0] * wy + r[2, 0] * wz
                y = r[0, 1] * wx + r[1, 1] * wy + r[2, 1] * wz
                z = r[0, 2] * wx + r[1, 2] * wy + r[2, 2] * wz
                if z > 0.0 and abs(x) <= tan_h * z and abs(y) <= tan_v * z:
                    off_axis_bin[p, c, a] = bin_index(o_edges, math.degrees(math.acos(min(z / dist, 1.0))))
    return distance, sphere_bin, distance_bin, facing_bin, off_axis_bin


@numba.njit(cache=True, parallel=True)
def _score(mass, distance, sphere_bin, distance_bin, facing_bin, off_axis_bin, radius, slot, toward, margin, rate):
    n_pos, n_blk = distance.shape
    n_set, n_fac = off_axis_bin.shape[2], mass.shape[1]
    detection = np.zeros((n_pos, n_set))
    covering = np.zeros(n_pos)
    best = np.zeros((n_pos, n_fac))  # per position: best detectability of the block at hand, per facing
    for p in numba.prange(n_pos):
        for c in range(n_blk):
            sb, db = sphere_bin[p, c], distance_bin[p, c]
            if sb < 0 or db < 0:
                continue  # out of reach
            reach = radius[p, sb] if slot[c] < 0 else toward[p, slot[c]]
            if distance[p, c] > reach + margin:
                continue  # behind the first obstacle in that direction
            best[p, :] = 0.0
            for a in range(n_set):
                ob = off_axis_bin[p, c, a]
                if ob < 0:
                    continue
                value = 0.0
                for s in range(n_fac):
                    fb = facing_bin[p, c, s]
                    if fb >= 0:
                        b = rate[db, ob, fb]
                        value += mass[c, s] * b
                        best[p, s] = max(best[p, s], b)
                detection[p, a] += value
            for s in range(n_fac):
                covering[p] += mass[c, s] * best[p, s]
    return detection, covering

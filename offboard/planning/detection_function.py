"""The detection function b(c_i, f) of one look that has been taken (report §3.1).

b is zero for a cube whose centre falls outside the image, outside the detector's range, or behind
what the camera actually saw in that direction (occlusion); inside, it is the detector's measured
detectability (:mod:`offboard.perception.detectability`) at that distance, angle off the optical axis and — per
facing sector of the belief — angle between the viewing ray and the face's normal.

Occlusion comes from the look itself: a per-block map of the visible depth, from the stereo of that
frame where it has a disparity and from ray casting the occupancy map elsewhere (:func:`visible_depth`).
The planner's *expected* b for looks not yet taken lives in :mod:`offboard.planning.action_values`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from offboard.perception.detectability import DetectabilityTable, bin_index, facing_angle
from offboard.perception.occupancy import OccupancyGrid
from offboard.perception.voxel_grid import VoxelGrid
from shared.geometry import Intrinsics, RigidTransform


@dataclass(frozen=True)
class LookFootprint:
    """The cubes a look could have detected the target in, and b for each facing sector."""

    cube_index: np.ndarray  # (n,) flat indices into the grid
    detection_prob: np.ndarray  # (n, facing_sectors) float32


def visible_depth(disparity: np.ndarray | None, occupancy: OccupancyGrid, camera_in_world: RigidTransform,
                  intrinsics: Intrinsics, baseline_m: float, block_px: int, max_range_m: float) -> np.ndarray:
    """z-depth (m) up to which each ``block_px`` block of the image was seen: the stereo median
    where the block has disparities, else the occupancy map's first occupied cube along its ray."""
    k = intrinsics
    rows, cols = _block_shape(k, block_px)
    v = (np.arange(rows) + 0.5) * block_px - 0.5
    u = (np.arange(cols) + 0.5) * block_px - 0.5
    uu, vv = np.meshgrid(u, v)
    rays_cam = np.stack([(uu - k.cx_px) / k.fx_px, (vv - k.cy_px) / k.fy_px, np.ones_like(uu)], axis=-1).reshape(-1, 3)
    dirs = rays_cam @ camera_in_world.rotation.T
    hits = occupancy.cast_rays(camera_in_world.translation, dirs, max_range_m)
    depth = (hits.distance_m / np.linalg.norm(rays_cam, axis=1)).reshape(rows, cols)  # along-ray → z
    if disparity is not None:
        padded = np.full((rows * block_px, cols * block_px), np.nan, np.float32)
        padded[:k.height_px, :k.width_px] = disparity
        blocks = padded.reshape(rows, block_px, cols, block_px).transpose(0, 2, 1, 3).reshape(rows, cols, -1)
        valid = np.isfinite(blocks) & (blocks > 0)
        enough = valid.mean(axis=-1) > 0.25
        with np.errstate(invalid="ignore", divide="ignore"):
            stereo = k.fx_px * baseline_m / np.nanmedian(np.where(valid, blocks, np.nan)[enough], axis=-1)
        depth[enough] = np.minimum(stereo, max_range_m)
    return depth.astype(np.float32)


def _block_shape(intrinsics: Intrinsics, block_px: int) -> tuple[int, int]:
    """(rows, columns) of ``block_px`` blocks covering the image, the last ones partly outside it."""
    return -(-intrinsics.height_px // block_px), -(-intrinsics.width_px // block_px)


def look_footprint(grid: VoxelGrid, camera_in_world: RigidTransform, intrinsics: Intrinsics,
                   depth_z: np.ndarray, block_px: int, table: DetectabilityTable,
                   facing_azimuths_rad: np.ndarray, behind_surface_m: float) -> LookFootprint:
    """b(c, f) for every cube the look could have seen.

    ``behind_surface_m``: a cube up to this far behind the visible surface still counts as seen —
    the target's centre lies behind its own front face.
    """
    near, far = table.range_m
    k = intrinsics
    blocks = _block_shape(k, block_px)
    if np.shape(depth_z) != blocks:  # the kernel reads it by block without bounds checks
        raise ValueError(f"depth_z must hold one depth per {block_px}-pixel block, shape {blocks}, "
                         f"not {np.shape(depth_z)}")
    lo, hi = _frustum_bounds(grid, camera_in_world, k, far)
    camera = np.array([k.fx_px, k.fy_px, k.cx_px, k.cy_px, k.width_px, k.height_px, block_px,
                       near, far, behind_surface_m])
    index, prob = _footprint(grid.origin, grid.resolution_m, np.array(grid.shape, np.int64), lo, hi,
                             np.ascontiguousarray(camera_in_world.rotation), camera_in_world.translation,
                             camera, np.ascontiguousarray(depth_z, np.float32), table.distance_edges_m,
                             table.off_axis_edges_deg, table.facing_edges_deg,
                             np.ascontiguousarray(table.rate, np.float32),
                             np.asarray(facing_azimuths_rad, np.float64))
    return LookFootprint(index, prob)


def _frustum_bounds(grid: VoxelGrid, camera_in_world: RigidTransform, k: Intrinsics, far_m: float):
    """Index bounds of the cubes inside the view pyramid out to ``far_m`` (a cube's margin around).
    The pyramid is cut at depth ``far_m``, not at that distance along its edges: the edges are the
    slanted rays, and cut there the box would end 0.78 × ``far_m`` ahead of a camera that looks
    along a room axis, dropping the cubes the middle of the view sees beyond."""
    corners = far_m * np.array([[(u - k.cx_px) / k.fx_px, (v - k.cy_px) / k.fy_px, 1.0]
                                for u in (-0.5, k.width_px - 0.5) for v in (-0.5, k.height_px - 0.5)])
    points = np.vstack([camera_in_world.apply(corners), camera_in_world.translation[None]])
    top = np.array(grid.shape) - 1
    lo = np.clip(grid.index_of(points.min(axis=0) - grid.resolution_m), 0, top)
    hi = np.clip(grid.index_of(points.max(axis=0) + grid.resolution_m), 0, top)
    return lo, hi


@numba.njit(cache=True, inline="always")
def _seen(i, j, k, origin, res, rotation, translation, camera, depth_z, d_edges, o_edges):
    """Distance and off-axis bins of a cube if the look saw it (centre in the image, in range, not
    occluded), else (-1, -1); also the vector from the camera to the cube."""
    fx, fy, cx, cy, width, height, block, near, far, behind = camera
    wx = origin[0] + (i + 0.5) * res - translation[0]
    wy = origin[1] + (j + 0.5) * res - translation[1]
    wz = origin[2] + (k + 0.5) * res - translation[2]
    x = rotation[0, 0] * wx + rotation[1, 0] * wy + rotation[2, 0] * wz  # R^T (c - t)
    y = rotation[0, 1] * wx + rotation[1, 1] * wy + rotation[2, 1] * wz
    z = rotation[0, 2] * wx + rotation[1, 2] * wy + rotation[2, 2] * wz
    if z <= 0.0:
        return -1, -1, wx, wy, wz
    u = fx * x / z + cx
    v = fy * y / z + cy
    if not (-0.5 <= u < width - 0.5 and -0.5 <= v < height - 0.5):
        return -1, -1, wx, wy, wz  # the centre is outside the image
    dist = math.sqrt(x * x + y * y + z * z)
    if dist < near or dist > far:
        return -1, -1, wx, wy, wz  # outside the detector's range
    if z > depth_z[int(v + 0.5) // int(block), int(u + 0.5) // int(block)] + behind:
        return -1, -1, wx, wy, wz  # occluded
    return bin_index(d_edges, dist), bin_index(o_edges, math.degrees(math.acos(min(z / dist, 1.0)))), wx, wy, wz


@numba.njit(cache=True, parallel=True)
def _count_seen(origin, res, lo, hi, rotation, translation, camera, depth_z, d_edges, o_edges):
    counts = np.zeros(hi[0] - lo[0] + 1, np.int64)
    for di in numba.prange(hi[0] - lo[0] + 1):
        for j in range(lo[1], hi[1] + 1):
            for k in range(lo[2], hi[2] + 1):
                a, b, _, _, _ = _seen(lo[0] + di, j, k, origin, res, rotation, translation, camera, depth_z, d_edges, o_edges)
                if a >= 0 and b >= 0:
                    counts[di] += 1
    return counts


@numba.njit(cache=True, parallel=True)
def _fill_seen(origin, res, shape, lo, hi, rotation, translation, camera, depth_z, d_edges, o_edges,
               f_edges, rate, facings, offsets, index, prob):
    for di in numba.prange(hi[0] - lo[0] + 1):
        n = offsets[di]
        i = lo[0] + di
        for j in range(lo[1], hi[1] + 1):
            for k in range(lo[2], hi[2] + 1):
                dbin, obin, wx, wy, wz = _seen(i, j, k, origin, res, rotation, translation, camera, depth_z, d_edges, o_edges)
                if dbin < 0 or obin < 0:
                    continue
                back = math.atan2(-wy, -wx)  # from the cube back towards the camera
                cos_el = math.hypot(wx, wy) / math.sqrt(wx * wx + wy * wy + wz * wz)
                for s in range(facings.shape[0]):
                    diff = facing_angle(facings[s], back, cos_el)
                    fbin = bin_index(f_edges, math.degrees(diff))
                    prob[n, s] = rate[dbin, obin, fbin] if fbin >= 0 else 0.0
                index[n] = (i * shape[1] + j) * shape[2] + k
                n += 1


def _footprint(origin, res, shape, lo, hi, rotation, translation, camera, depth_z, d_edges, o_edges,
               f_edges, rate, facings):
    """Two passes, parallel over x slabs: count the seen cubes per slab, then fill in place."""
    counts = _count_seen(origin, res, lo, hi, rotation, translation, camera, depth_z, d_edges, o_edges)
    offsets = np.concatenate([[0], np.cumsum(counts)[:-1]])
    index = np.empty(int(counts.sum()), np.int64)
    prob = np.empty((index.size, facings.shape[0]), np.float32)
    _fill_seen(origin, res, shape, lo, hi, rotation, translation, camera, depth_z, d_edges, o_edges,
               f_edges, rate, facings, offsets, index, prob)
    return index, prob

"""The tessellation of the search region Ω into cubes c_i (report §3.1).

World coordinates live on the wire; grid indices live inside the planner. Every conversion between
the two is a method of :class:`VoxelGrid`, the object that owns the origin and the resolution.
The occupancy grid and the target belief share one VoxelGrid, so cube ``i`` means the same place
in both.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class VoxelGrid:
    """Cubes of ``resolution_m`` covering the box [origin, origin + size] (the room)."""

    size_m: tuple[float, float, float]
    resolution_m: float = 0.05
    origin_m: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        sizes = (*self.size_m, self.resolution_m)
        if len(self.size_m) != 3 or not all(math.isfinite(s) and s > 0 for s in sizes):
            raise ValueError(f"a voxel grid needs three positive, finite sides and a positive, finite resolution "
                             f"(got {self.size_m}, {self.resolution_m})")

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(int(np.ceil(s / self.resolution_m - 1e-9)) for s in self.size_m)

    @property
    def num_cubes(self) -> int:
        return int(np.prod(self.shape))

    @property
    def origin(self) -> np.ndarray:
        return np.asarray(self.origin_m, dtype=np.float64)

    def index_of(self, points_m: np.ndarray) -> np.ndarray:
        """Integer (i, j, k) of the cube holding each point (..., 3); may be outside the grid."""
        return np.floor((points_m - self.origin) / self.resolution_m).astype(np.int64)

    def axis_centers(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The cubes' centre coordinates along x, y and z (world frame): :meth:`centers` without
        the (nx, ny, nz, 3) array."""
        return tuple(self.origin_m[a] + (np.arange(n) + 0.5) * self.resolution_m for a, n in enumerate(self.shape))

    def squared_distances(self, point_m: np.ndarray, box: tuple[slice, slice, slice] | None = None) -> np.ndarray:
        """Squared distance from ``point_m`` to the centre of every cube (of ``box``, a block of index
        slices, if given), shape (nx, ny, nz) or the box's, without the array of centres."""
        box = box if box is not None else (slice(None),) * 3
        x, y, z = (axis[part] - p for axis, part, p in zip(self.axis_centers(), box, np.asarray(point_m, float)))
        return (x[:, None, None] ** 2 + y[None, :, None] ** 2) + z[None, None, :] ** 2

    def centers(self) -> np.ndarray:
        """Centres of all cubes, shape (nx, ny, nz, 3), world frame."""
        return np.stack(np.meshgrid(*self.axis_centers(), indexing="ij"), axis=-1)

    def center_of(self, index: np.ndarray) -> np.ndarray:
        return self.origin + (np.asarray(index) + 0.5) * self.resolution_m

    def layers(self, low_m: float, high_m: float) -> slice:
        """The layers of cubes that reach between heights ``low_m`` and ``high_m`` (world z). A height
        on a face between layers, up to round-off (0.15 / 0.05 is 2.9999999999999996), is that face."""
        z0, res = self.origin_m[2], self.resolution_m
        return slice(max(int(math.floor((low_m - z0) / res + 1e-9)), 0),
                     min(int(math.ceil((high_m - z0) / res - 1e-9)), self.shape[2]))

    def box_slices(self, min_m: np.ndarray, max_m: np.ndarray) -> tuple[slice, slice, slice]:
        """Index slices of the cubes whose centres lie inside an axis-aligned box."""
        lo = np.ceil((np.asarray(min_m) - self.origin) / self.resolution_m - 0.5).astype(int)
        hi = np.floor((np.asarray(max_m) - self.origin) / self.resolution_m - 0.5).astype(int) + 1
        lo = np.clip(lo, 0, self.shape)
        hi = np.clip(hi, 0, self.shape)
        return tuple(slice(a, max(a, b)) for a, b in zip(lo, hi))

"""The sensed sphere (report §3.3.1): what a camera at one spot could see in every direction.

Space around the camera is divided into solid angles (azimuth × elevation bins). Each has a radius:
the distance to the first occupied cube along its central axis, capped at the detector's outer
range; an inner radius is the detector's near limit. For positions the robot has not visited, the
expected sensed sphere is built the same way from the map so far, unknown space transparent: a
search begins with nearly all of the room unknown, so a sphere that stopped at unknown space would
value no look at all.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from offboard.perception.occupancy import OccupancyGrid


@dataclass(frozen=True)
class SphereBins:
    """Solid angles: ``az_count`` azimuth bins over the full turn, ``el_count`` elevation bins."""

    az_count: int = 48  # 7.5° each
    el_count: int = 18
    el_min_rad: float = math.radians(-75.0)  # lowest tilt (−47°) minus half the vertical field of view
    el_max_rad: float = math.radians(60.0)  # highest tilt (+31°) plus half the vertical field of view

    def axes(self) -> np.ndarray:
        """Unit central axis of every bin, shape (el_count, az_count, 3)."""
        az = -math.pi + (np.arange(self.az_count) + 0.5) * (2 * math.pi / self.az_count)
        el = self.el_min_rad + (np.arange(self.el_count) + 0.5) * (self.el_max_rad - self.el_min_rad) / self.el_count
        ee, aa = np.meshgrid(el, az, indexing="ij")
        return np.stack([np.cos(ee) * np.cos(aa), np.cos(ee) * np.sin(aa), np.sin(ee)], axis=-1)


@dataclass(frozen=True)
class SensedSpheres:
    """Sensed spheres at several camera centres, sharing one binning."""

    bins: SphereBins
    radius_m: np.ndarray  # (P, el_count, az_count): first obstacle or the detector's outer range
    resolution_m: float  # of the map cast on: a ray stops where an occupied cube begins, up to this before its surface
    toward_m: np.ndarray  # (P, T): radius along the exact direction to each of T given points (see sensed_spheres)


def sensed_spheres(occupancy: OccupancyGrid, centers_m: np.ndarray, bins: SphereBins, outer_m: float,
                   toward_m: np.ndarray | None = None) -> SensedSpheres:
    """Ray-cast every bin's axis from every centre on the occupancy map (pass a
    :meth:`~OccupancyGrid.coarsened` map: a radius to within a block is plenty for planning), and
    the exact direction to each point of ``toward_m`` (T, 3): a bin's axis can graze an obstacle
    that the rays to a small, heavily weighted place pass by."""
    centers = np.atleast_2d(np.asarray(centers_m, np.float64))
    axes = bins.axes().reshape(-1, 3)
    radius = _cast(occupancy, np.repeat(centers, len(axes), axis=0), np.tile(axes, (len(centers), 1)),
                   outer_m).reshape(len(centers), bins.el_count, bins.az_count)
    points = np.zeros((0, 3)) if toward_m is None else np.atleast_2d(np.asarray(toward_m, np.float64))
    toward = np.zeros((len(centers), 0))
    if len(points):
        offsets = (points[None, :, :] - centers[:, None, :]).reshape(-1, 3)
        offsets[np.all(offsets == 0, axis=1)] = (1.0, 0.0, 0.0)  # a point at the centre: any direction will do
        toward = _cast(occupancy, np.repeat(centers, len(points), axis=0), offsets,
                       outer_m).reshape(len(centers), len(points))
    return SensedSpheres(bins, radius, occupancy.grid.resolution_m, toward)


def _cast(occupancy: OccupancyGrid, origins: np.ndarray, directions: np.ndarray, outer_m: float) -> np.ndarray:
    """Distance to the first obstacle from each origin along its direction, capped at ``outer_m``."""
    hits = occupancy.cast_rays(origins, directions, outer_m)
    return np.minimum(hits.distance_m, outer_m)

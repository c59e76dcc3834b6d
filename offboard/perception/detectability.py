"""How likely a detector is to find the target from a given viewpoint (report §6.1).

An object-centred, viewpoint-dependent detectability function: the detection rate of one detector
by distance to the target, angle of the target off the optical axis, and angle between the viewing
ray and the normal of the target's pictured face. It is *measured* by running the real detector on
simulated views (``syt-offboard calibrate-detector``) and saved as JSON; the planner's detection
function b(c, f) reads it. :meth:`DetectabilityTable.nominal` gives a smooth stand-in for tests and
for a detector that has not been calibrated yet.

A table holds for the size of face it was measured with. A detector sees a picture by its size in
pixels, so a face k times as large is found as often from k times as far:
:meth:`DetectabilityTable.for_face` rescales the distance axis to the target at hand.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numba
import numpy as np

from shared.geometry import RigidTransform


@dataclass(frozen=True)
class DetectabilityTable:
    detector: str
    distance_edges_m: np.ndarray  # (nd + 1,) bin edges; outside them the rate is 0
    off_axis_edges_deg: np.ndarray  # (no + 1,) angle of the target off the optical axis
    facing_edges_deg: np.ndarray  # (nf + 1,) angle between the viewing ray and the face's normal
    rate: np.ndarray  # (nd, no, nf) detection rate per cell
    samples: np.ndarray  # (nd, no, nf) views measured per cell (0 for a nominal table)
    false_positive_rate: float  # false detections per image without the target
    cost_ms: float  # median cost of the detector per image
    face_size_m: float | None = None  # face_size_m() of the target it was measured with; None: any (nominal)

    def __post_init__(self) -> None:
        shape = (len(self.distance_edges_m) - 1, len(self.off_axis_edges_deg) - 1, len(self.facing_edges_deg) - 1)
        if self.rate.shape != shape or self.samples.shape != shape:
            raise ValueError(f"rate and samples must have shape {shape}, not {self.rate.shape} / {self.samples.shape}")
        if np.any((self.rate < 0) | (self.rate > 1)) or not np.all(np.isfinite(self.rate)):
            raise ValueError("detection rates must lie in [0, 1]")
        for name in ("distance_edges_m", "off_axis_edges_deg", "facing_edges_deg"):
            steps = np.diff(getattr(self, name))
            if steps.size == 0 or steps.min() <= 0 or not np.allclose(steps, steps[0]):
                raise ValueError(f"{name} must be evenly spaced and increasing (bins are looked up by arithmetic)")
        if not 0.0 <= self.false_positive_rate <= 1.0:  # NaN fails too: it would make every update NaN
            raise ValueError(f"false_positive_rate must lie in [0, 1], not {self.false_positive_rate}")
        if not (math.isfinite(self.cost_ms) and self.cost_ms >= 0):
            raise ValueError(f"cost_ms must be a time of at least 0 ms, not {self.cost_ms}")
        if self.face_size_m is not None and not (math.isfinite(self.face_size_m) and self.face_size_m > 0):
            raise ValueError(f"face_size_m must be a positive size in metres, not {self.face_size_m}")

    def for_face(self, face_size_m: float) -> DetectabilityTable:
        """This table for a target whose face has size ``face_size_m`` (see :func:`face_size_m`): its
        distances scaled by the ratio of the sizes (none for a table of no particular size)."""
        if self.face_size_m is None or face_size_m == self.face_size_m:
            return self
        if not (math.isfinite(face_size_m) and face_size_m > 0):
            raise ValueError(f"a face's size must be positive, not {face_size_m}")
        return replace(self, distance_edges_m=self.distance_edges_m * (face_size_m / self.face_size_m),
                       face_size_m=face_size_m)

    def for_sectors(self, sectors: int, steps: int = 9) -> DetectabilityTable:
        """This table for a belief that splits the facing into ``sectors`` equal sectors (1: the
        target faces the camera; then the table as it is). The planner and the update look a
        sector's rate up at the angle to its centre, yet its mass stands for every facing in it. So
        the rate at an angle becomes the mean of the measured rate over the sector around it,
        ``steps`` facings across the sector for each of ``steps`` angles across the bin. The
        spread is taken in the horizontal: an approximation for steep views. With SIFT's table at
        1.5 m and 8 sectors: seen 50-60° off its centre a sector is found at 0.77, not 0.95 (its far
        edge is past 70°); 80-90° off, at 0.17, not 0 (its near edge is at 58-68°). Without this, a
        grazing look rules a sector out by what its centre would show, for the picture at either
        edge of it alike."""
        if sectors < 1:
            raise ValueError(f"a belief needs at least one facing sector, not {sectors}")
        if sectors == 1:
            return self
        width = 360.0 / sectors
        step = self.facing_edges_deg[1] - self.facing_edges_deg[0]
        top = min(180.0, step * math.ceil((self.facing_edges_deg[-1] + width / 2) / step - 1e-9))
        edges = np.arange(0.0, top + step / 2, step)
        within_bin = (np.arange(steps) + 0.5) / steps * step
        across = ((np.arange(steps) + 0.5) / steps - 0.5) * width
        angle = np.abs(edges[:-1, None, None] + within_bin[None, :, None] + across[None, None, :])
        angle = np.where(angle > 180.0, 360.0 - angle, angle).reshape(len(edges) - 1, -1)
        d, o = ((e[:-1] + e[1:]) / 2 for e in (self.distance_edges_m, self.off_axis_edges_deg))  # bin centres
        inside, cells = self._cells(d[:, None, None, None], o[None, :, None, None], angle[None, None])
        rate = np.where(inside, self.rate[cells], 0.0).mean(axis=-1)
        views = np.where(inside, self.samples[cells], 0).max(axis=-1)  # behind the cells it averages
        # facings that are never found are left off the axis: a kernel bins every facing it scans
        used = max(1, int(np.nonzero(rate.max(axis=(0, 1)) > 0)[0].max(initial=0)) + 1)
        return replace(self, facing_edges_deg=edges[:used + 1], rate=rate[..., :used], samples=views[..., :used])

    @property
    def range_m(self) -> tuple[float, float]:
        """Nearest and farthest distance with a non-zero rate: the sensed sphere's inner/outer radius."""
        useful = np.nonzero(self.rate.max(axis=(1, 2)) > 0.05)[0]
        if useful.size == 0:
            return (0.0, 0.0)
        return float(self.distance_edges_m[useful[0]]), float(self.distance_edges_m[useful[-1] + 1])

    def lookup(self, distance_m: np.ndarray, off_axis_deg: np.ndarray, facing_deg: np.ndarray) -> np.ndarray:
        """Detection probability per query (nearest cell; zero outside the measured ranges). Bins by
        the same arithmetic as the planner's :func:`bin_index`, so that both agree on a bin's edge."""
        inside, cells = self._cells(distance_m, off_axis_deg, facing_deg)
        return np.where(inside, self.rate[cells], 0.0)

    def _cells(self, distance_m: np.ndarray, off_axis_deg: np.ndarray,
               facing_deg: np.ndarray) -> tuple[np.ndarray, tuple[np.ndarray, ...]]:
        """The cell of each query (broadcast), clipped into the table, and whether it lies inside."""
        idx = [np.floor((np.asarray(x, float) - edges[0]) / (edges[1] - edges[0])).astype(int) for edges, x in
               ((self.distance_edges_m, distance_m), (self.off_axis_edges_deg, np.abs(off_axis_deg)),
                (self.facing_edges_deg, np.abs(facing_deg)))]
        inside = np.ones(np.broadcast(*idx).shape, bool)
        for i, n in zip(idx, self.rate.shape):
            inside &= (i >= 0) & (i < n)
        return inside, tuple(np.clip(i, 0, n - 1) for i, n in zip(idx, self.rate.shape))

    # --- persistence -------------------------------------------------------------------------------

    def save(self, path: Path) -> None:
        data = {"detector": self.detector, "false_positive_rate": self.false_positive_rate,
                "cost_ms": self.cost_ms, "face_size_m": self.face_size_m,
                **{k: getattr(self, k).tolist() for k in
                   ("distance_edges_m", "off_axis_edges_deg", "facing_edges_deg", "rate", "samples")}}
        Path(path).write_text(json.dumps(data))

    @classmethod
    def load(cls, path: Path) -> DetectabilityTable:
        """A table :meth:`save` wrote; one written before tables knew their face's size holds for any."""
        try:
            data = json.loads(Path(path).read_text())
            return cls(data["detector"], *(np.asarray(data[k], float) for k in
                                           ("distance_edges_m", "off_axis_edges_deg", "facing_edges_deg", "rate")),
                       np.asarray(data["samples"], int), float(data["false_positive_rate"]), float(data["cost_ms"]),
                       None if data.get("face_size_m") is None else float(data["face_size_m"]))
        except (OSError, KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{path}: not a detectability table ({exc})") from None

    @classmethod
    def nominal(cls, detector: str = "nominal", near_m: float = 0.4, far_m: float = 3.0, peak: float = 0.95,
                max_facing_deg: float = 60.0, half_fov_deg: float = 33.0, cost_ms: float = 50.0) -> DetectabilityTable:
        """A smooth stand-in: ``peak`` inside [near, far], falling off towards far, the image edge and
        grazing views; zero beyond ``max_facing_deg``."""
        d_edges = np.round(np.arange(0.0, far_m + 0.5 + 1e-9, 0.25), 6)
        o_edges = np.linspace(0.0, half_fov_deg + 12.0, 10)
        f_edges = np.arange(0.0, 91.0, 10.0)
        d = (d_edges[:-1] + d_edges[1:]) / 2
        o = (o_edges[:-1] + o_edges[1:]) / 2
        f = (f_edges[:-1] + f_edges[1:]) / 2
        by_distance = np.where((d >= near_m) & (d <= far_m), 1.0 - 0.3 * np.clip((d - near_m) / (far_m - near_m), 0, 1) ** 2, 0.0)
        by_off_axis = np.where(o <= half_fov_deg, 1.0 - 0.2 * (o / half_fov_deg) ** 2, 0.0)
        by_facing = np.where(f <= max_facing_deg, np.cos(np.radians(f)) ** 0.5, 0.0)
        rate = peak * by_distance[:, None, None] * by_off_axis[None, :, None] * by_facing[None, None, :]
        return cls(detector, d_edges, o_edges, f_edges, rate, np.zeros(rate.shape, int), 0.0, cost_ms)


def face_size_m(width_m: float, height_m: float) -> float:
    """One size for a pictured face, √(width × height): what a detectability table scales with."""
    return math.sqrt(width_m * height_m)


def off_axis_deg(camera_in_world: RigidTransform, point_m: np.ndarray) -> float:
    """Angle (°) between a camera's optical axis (its z) and the ray from it to ``point_m``: the
    table's second axis."""
    ray = np.asarray(point_m, float) - camera_in_world.translation
    return math.degrees(math.acos(np.clip(ray @ camera_in_world.rotation[:, 2] / np.linalg.norm(ray), -1.0, 1.0)))


def facing_angle_deg(view_azimuth_rad: np.ndarray, facing_azimuth_rad: np.ndarray,
                     view_elevation_rad: np.ndarray | float = 0.0) -> np.ndarray:
    """Angle between the face's (horizontal) normal and the direction from the target back to the
    camera; the ray from the camera to the target has azimuth ``view_azimuth_rad`` and elevation
    ``view_elevation_rad``. The face is seen head-on when its normal points straight back along it."""
    facing = np.asarray(facing_azimuth_rad, float)
    cos = np.cos(view_elevation_rad) * np.cos(facing - (np.asarray(view_azimuth_rad) + math.pi))
    return np.where(np.isnan(facing), 0.0, np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


@numba.njit(cache=True, inline="always")
def facing_angle(facing: float, back: float, cos_elevation: float) -> float:
    """Angle (rad) between a face's normal — horizontal, at azimuth ``facing`` in [0, 2π); NaN means
    it faces the camera — and the 3D direction from the target back to the camera, whose azimuth is
    ``back`` (in [-π, π]) and whose elevation has cosine ``cos_elevation``: a face seen from below or
    above is foreshortened as much as one seen from the side."""
    if math.isnan(facing):
        return 0.0
    return math.acos(max(-1.0, min(1.0, cos_elevation * math.cos(facing - back))))


@numba.njit(cache=True, inline="always")
def bin_index(edges: np.ndarray, value: float) -> int:
    """Bin of ``value`` among evenly spaced ``edges``; -1 outside them."""
    i = int(math.floor((value - edges[0]) / (edges[1] - edges[0])))
    return i if 0 <= i < edges.shape[0] - 1 else -1


@numba.njit(cache=True, inline="always")
def cosine_bin(cos_edges: np.ndarray, cosine: float) -> int:
    """Bin of the angle whose cosine is ``cosine`` (in [-1, 1]) among angle edges in [0°, 180°],
    given as their cosines (``cos_edges``, decreasing); -1 outside them. The same bin as
    :func:`bin_index` of the angle, without the arc cosine: kernels that bin millions of angles
    spend most of their time there."""
    if cosine > cos_edges[0] or cosine <= cos_edges[-1]:
        return -1
    i = 0
    while cosine <= cos_edges[i + 1]:
        i += 1
    return i

"""Odometry correction from stereo: 2D correlative scan matching against the map, fused in an EKF.

Each stereo frame's points between ``band_min_m`` and ``band_max_m`` above the floor are projected to
the floor (a "scan" in the robot frame) and aligned with the map built from *earlier* frames plus the
room's walls (the room's extent is known, report §3.1):

1. **likelihood field** (Thrun, Burgard & Fox, *Probabilistic Robotics* §6.4): the distance from every
   floor cell to the nearest occupied column, by an exact Euclidean distance transform, turned into a
   robust per-point log-likelihood ``log(w·exp(-d²/2σ²) + 1 - w)``;
2. **correlative search** (Olson 2009, "Real-time correlative scan matching"): the summed
   log-likelihood over a coarse (x, y, θ) grid around the predicted pose (the window widens to 3σ of
   the prediction up to a cap: 3σ of a half turn at the odometry model's 3 % is 16°, and a window
   narrower than the error refuses every match until the map, built on the wrong heading, agrees
   with it; a position already farther off than the 0.6 m cap stays so), then a fine grid around
   the best coarse pose. The coarse grid's
   normalised likelihoods give the match's covariance, so a scan that sees a single wall parallel
   to the room's is confident across the wall and not along it (where the likelihood stays high at
   both edges of the window, the covariance says nothing at all, not the window's width). A wall at
   another angle is judged on the room's axes, so its match loses the constraint across it, or at
   45° is refused; docs/trials/slanted-wall-match.patch judges it along the wall, not yet measured
   on its own (the simulator's rooms have no slanted wall);
3. **rejection**: too few points, too few of them on the map, a likelihood that still rises at an
   edge of the window (its optimum may lie beyond, and the grid's moments then describe the window,
   not the match), or (in :class:`PoseTracker`) a Mahalanobis distance to the prediction beyond a χ²
   gate: a bad match never reaches the pose, nor (placed with it) the map;
4. **fusion**: :class:`PoseTracker` is an EKF over the world pose whose prediction is the odometry
   (its covariance grows with the distance driven and the angle turned); an accepted match is its
   measurement. The estimate is kept as an offset transform ``world_from_odom``, so any odometry pose
   maps to a corrected world pose and any corrected waypoint maps back to the robot's odometry frame.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import numba
import numpy as np
from scipy import ndimage

from offboard.perception.occupancy import OccupancyGrid
from offboard.perception.stereo import points_from_disparity
from shared.geometry import HeadMount, Intrinsics, Pose2D, wrap_angle

log = logging.getLogger(__name__)

_NO_INFORMATION = 1e4  # variance (m², rad²) along an axis the match does not constrain
_STILL_M = 0.01  # a displacement this small between two odometry readings is jitter, not travel


@dataclass(frozen=True)
class MatchConfig:
    band_min_m: float = 0.15  # above the floor's stereo noise
    band_max_m: float = 2.2  # below the ceiling, which the map does not hold
    max_range_m: float = 4.5  # stereo depth error grows as z²: farther points blur the match
    stride_px: int = 4  # disparity subsampling: neighbouring pixels repeat the same surface
    max_points: int = 800  # enough to constrain three parameters; bounds the search's cost
    min_points: int = 80  # fewer: the frame sees too little structure to trust
    sigma_m: float = 0.05  # likelihood-field width: stereo noise plus the 5 cm cubes
    hit_weight: float = 0.9  # mixture with a uniform term, so unmapped points do not pull
    evidence_points: float = 20.0  # effective independent points (stereo errors are correlated)
    search_xy_m: float = 0.3  # half-width of the coarse window around the predicted pose
    search_theta_deg: float = 5.0
    max_search_xy_m: float = 0.6  # the window grows to 3σ of the prediction, up to this
    max_search_theta_deg: float = 20.0  # 3σ of a half turn (16°) with room; 63 ms a match at full width
    coarse_xy_m: float = 0.05
    coarse_theta_deg: float = 1.0
    fine_xy_m: float = 0.01
    fine_theta_deg: float = 0.25
    min_inlier_fraction: float = 0.35  # points within 2σ of the map at the best pose
    max_edge_imbalance: float = 0.75  # refused: one edge's marginal likelihood tops the other's by this share
    flat_edge: float = 0.5  # an axis whose marginal likelihood at both edges is this share of its peak: unconstrained
    min_std_m: float = 0.02  # floor of the match's standard deviation (the grid's resolution)
    min_std_deg: float = 0.5


@dataclass(frozen=True)
class LikelihoodField:
    """Per-point log-likelihood on the floor grid, padded beyond the room (the walls are mapped)."""

    values: np.ndarray  # (nx + 2 pad, ny + 2 pad) float64
    resolution_m: float
    pad_cells: int

    def at(self, xy: np.ndarray) -> np.ndarray:
        return _bilinear_many(self.values, self.resolution_m, self.pad_cells, np.atleast_2d(xy))


def _cell_centres(index: np.ndarray, pad_cells: int, resolution_m: float) -> np.ndarray:
    """Coordinates (metres) of the centres of padded-grid cells along one axis (or several)."""
    return (index - pad_cells + 0.5) * resolution_m


def _field_at(sigmas: float, config: MatchConfig) -> float:
    """The per-point log-likelihood ``sigmas`` standard deviations from the nearest mapped surface."""
    w = config.hit_weight
    return math.log(w * math.exp(-0.5 * sigmas ** 2) + 1.0 - w)


@dataclass(frozen=True)
class MatchResult:
    pose: Pose2D  # best world pose of the robot
    covariance: np.ndarray  # (3, 3) over (x, y, heading)
    accepted: bool
    reason: str = ""


# --- scans -----------------------------------------------------------------------------------------

def scan_from_disparity(disparity: np.ndarray, intrinsics: Intrinsics, mount: HeadMount, pan_rad: float,
                        tilt_rad: float, config: MatchConfig = MatchConfig()) -> np.ndarray:
    """Stereo points in the height band, projected to the floor, in the robot frame (N, 2)."""
    pts = points_from_disparity(disparity, intrinsics, mount.baseline_m, stride_px=config.stride_px,
                                max_depth_m=config.max_range_m + mount.height_m)
    robot = mount.camera_in_robot(pan_rad, tilt_rad).apply(pts.xyz_cam_m.astype(np.float64))
    head = np.array([mount.forward_m, 0.0])
    keep = ((robot[:, 2] >= config.band_min_m) & (robot[:, 2] <= config.band_max_m)
            & (np.hypot(*(robot[:, :2] - head).T) <= config.max_range_m))
    xy = robot[keep, :2]
    if xy.shape[0] > config.max_points:  # an even spread over the frame, reproducibly
        xy = xy[np.linspace(0, xy.shape[0] - 1, config.max_points).astype(np.int64)]
    return xy


def likelihood_field(occupied_xy: np.ndarray, resolution_m: float, config: MatchConfig = MatchConfig(),
                     room_xy: tuple[float, float] | None = None, pad_cells: int = 10) -> LikelihoodField:
    """From occupied floor columns (nx, ny), each standing for a surface sample at its centre, plus
    the room's walls (the boundary of ``room_xy``, default the grid's extent) as exact lines.

    Walls are thin, not solid: a point pushed beyond a wall costs as much as one short of it, or
    the search would slide the scan into the wall.
    """
    nx, ny = occupied_xy.shape
    room = room_xy if room_xy is not None else (nx * resolution_m, ny * resolution_m)
    occupied = np.pad(occupied_xy, pad_cells, constant_values=False)
    if occupied.any():
        # Not cv2.distanceTransform's exact mode: its float32 result changes in the last bits with
        # OpenCV's thread count and buffer alignment (opencv/opencv#24082), and a scan match that
        # tips on those bits made repeated runs of one scenario part by millimetres.
        d_map = ndimage.distance_transform_edt(~occupied) * resolution_m
    else:
        d_map = np.full(occupied.shape, np.inf)
    centres = [_cell_centres(np.arange(n + 2 * pad_cells), pad_cells, resolution_m) for n in (nx, ny)]
    d = np.minimum(d_map, _distance_to_walls(*np.meshgrid(*centres, indexing="ij"), room))
    w = config.hit_weight
    return LikelihoodField(np.log(w * np.exp(-0.5 * (d / config.sigma_m) ** 2) + (1.0 - w)), resolution_m, pad_cells)


def _distance_to_walls(x: np.ndarray, y: np.ndarray, room: tuple[float, float]) -> np.ndarray:
    """Distance from points to the boundary of the rectangle [0, room_x] × [0, room_y]."""
    inside = np.minimum(np.minimum(x, room[0] - x), np.minimum(y, room[1] - y))
    ox = np.maximum(np.maximum(-x, x - room[0]), 0.0)
    oy = np.maximum(np.maximum(-y, y - room[1]), 0.0)
    return np.where(inside >= 0.0, inside, np.hypot(ox, oy))


def map_field(occupancy: OccupancyGrid, config: MatchConfig = MatchConfig()) -> LikelihoodField:
    """The likelihood field of an occupancy grid's columns in the scan's height band."""
    occupied = occupancy.occupied()[:, :, occupancy.grid.layers(config.band_min_m, config.band_max_m)].any(axis=2)
    return likelihood_field(occupied, occupancy.grid.resolution_m, config, tuple(occupancy.grid.size_m[:2]))


def structure_in_view(field: LikelihoodField, pose: Pose2D, pans_rad: np.ndarray, hfov_rad: float,
                      config: MatchConfig = MatchConfig(), min_range_m: float = 0.5) -> np.ndarray:
    """For each pan (relative to the robot's heading), how many cells of the field lie within
    ``sigma_m`` of mapped structure (an occupied column or a wall, beyond it too) in the camera's
    horizontal field of view, between ``min_range_m`` and the scan's range from the robot's centre:
    what a scan taken there could be matched against. Occlusion is ignored."""
    # a cell exactly 1 σ away is in, whatever the rounding of the distance and the log
    i, j = np.nonzero(field.values >= _field_at(1.0, config) - 1e-6)
    xy = _cell_centres(np.stack([i, j], axis=1), field.pad_cells, field.resolution_m)
    d = xy - (pose.x_m, pose.y_m)
    r = np.hypot(d[:, 0], d[:, 1])
    keep = (r >= min_range_m) & (r <= config.max_range_m)
    bearing = np.arctan2(d[keep, 1], d[keep, 0]) - pose.heading_rad
    off_axis = np.abs(np.angle(np.exp(1j * (bearing[None, :] - np.asarray(pans_rad)[:, None]))))
    return (off_axis <= hfov_rad / 2).sum(axis=1)


# --- matching --------------------------------------------------------------------------------------

class ScanMatcher:
    """Correlative scan matching of a robot-frame scan against a likelihood field."""

    def __init__(self, config: MatchConfig = MatchConfig()):
        self.config = config

    def match(self, scan_xy: np.ndarray, prior: Pose2D, field: LikelihoodField,
              prior_covariance: np.ndarray | None = None) -> MatchResult:
        """Best pose near ``prior``; the window widens to 3σ of ``prior_covariance`` when that is larger."""
        c = self.config
        _check_finite(scan_xy, prior)
        if scan_xy.shape[0] < c.min_points:
            return MatchResult(prior, np.eye(3), False, "too few points")
        half_xy, half_deg = self._window(prior_covariance)
        coarse = _grid(half_xy, c.coarse_xy_m, half_deg, c.coarse_theta_deg)
        scores = _search(field, scan_xy, prior, *coarse)
        best = np.unravel_index(int(np.argmax(scores)), scores.shape)
        weights = self._weights(scores, scan_xy.shape[0])
        edges = _edge_marginals(weights)
        covariance = _uninformative_along(self._covariance(weights, coarse), edges.min(axis=1) >= c.flat_edge)
        centre = _offset_pose(prior, coarse[0][best[0]], coarse[1][best[1]], coarse[2][best[2]])
        fine = _grid(c.coarse_xy_m, c.fine_xy_m, c.coarse_theta_deg, c.fine_theta_deg)  # one coarse cell round
        fine_scores = _search(field, scan_xy, centre, *fine)
        fb = np.unravel_index(int(np.argmax(fine_scores)), fine_scores.shape)
        pose = _offset_pose(centre, fine[0][fb[0]], fine[1][fb[1]], fine[2][fb[2]])
        inliers = self._inlier_fraction(field, scan_xy, pose)
        reason = ""
        if inliers < c.min_inlier_fraction:
            reason = f"only {inliers:.0%} of the points lie on the map"
        elif np.any(np.abs(edges[:, 1] - edges[:, 0]) > c.max_edge_imbalance):
            reason = "the likelihood rises toward an edge of the search window"  # the true pose may lie beyond
        return MatchResult(pose, covariance, not reason, reason)

    def _window(self, prior_covariance: np.ndarray | None) -> tuple[float, float]:
        c = self.config
        if prior_covariance is None:
            return c.search_xy_m, c.search_theta_deg
        sxy = math.sqrt(max(prior_covariance[0, 0], prior_covariance[1, 1]))
        sdeg = math.degrees(math.sqrt(prior_covariance[2, 2]))
        return (float(np.clip(3.0 * sxy, c.search_xy_m, c.max_search_xy_m)),
                float(np.clip(3.0 * sdeg, c.search_theta_deg, c.max_search_theta_deg)))

    def _weights(self, scores: np.ndarray, n_points: int) -> np.ndarray:
        """The search grid's normalised likelihoods, tempered by the ratio of points to effectively
        independent ones."""
        temper = max(n_points / self.config.evidence_points, 1.0)
        w = np.exp((scores - scores.max()) / temper)
        return w / w.sum()

    def _covariance(self, w: np.ndarray, grid: tuple[np.ndarray, ...]) -> np.ndarray:
        """Olson's covariance: the search grid's poses weighted by their normalised likelihood."""
        c = self.config
        dx, dy, dt = np.meshgrid(grid[0], grid[1], grid[2], indexing="ij")
        v = np.stack([dx.ravel(), dy.ravel(), dt.ravel()], axis=1)
        mean = w.ravel() @ v
        centred = v - mean
        cov = (centred * w.ravel()[:, None]).T @ centred
        return cov + np.diag([c.min_std_m ** 2, c.min_std_m ** 2, math.radians(c.min_std_deg) ** 2])

    def _inlier_fraction(self, field: LikelihoodField, scan_xy: np.ndarray, pose: Pose2D) -> float:
        return float(np.mean(field.at(_to_world(scan_xy, pose)) >= _field_at(2.0, self.config)))


def _check_finite(scan_xy: np.ndarray, prior: Pose2D) -> None:
    """One NaN makes every score NaN, and a refusal would then name the wrong cause."""
    if not np.all(np.isfinite(scan_xy)):
        raise ValueError(f"scan_xy holds {int(np.sum(~np.isfinite(scan_xy)))} non-finite values")
    if not all(math.isfinite(v) for v in (prior.x_m, prior.y_m, prior.heading_rad)):
        raise ValueError(f"prior must be finite, not {prior}")


def _edge_marginals(weights: np.ndarray) -> np.ndarray:
    """(axes, 2): the likelihood marginalised onto each axis of the window, at its first and last
    cell, over its peak. One edge high where the other has fallen: the optimum may lie beyond the
    window (the best pose alone does not tell: a ridge running into the edge, such as a far patch of
    an unmapped object slid onto a wall, peaks inside it). Both edges high: the scan does not
    constrain that axis (along a single wall), and the best pose along it is arbitrary."""
    out = np.empty((weights.ndim, 2))
    for axis in range(weights.ndim):
        marginal = weights.sum(axis=tuple(a for a in range(weights.ndim) if a != axis))
        out[axis] = marginal[0] / marginal.max(), marginal[-1] / marginal.max()
    return out


def _uninformative_along(covariance: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """The covariance with no information along ``axes``: there the grid's spread is the window's
    width, not the match's, and the fusion must not pull toward an arbitrary best pose."""
    out = covariance.copy()
    out[axes, :] = out[:, axes] = 0.0
    out[axes, axes] = _NO_INFORMATION
    return out


def _grid(half_xy: float, step_xy: float, half_deg: float, step_deg: float) -> tuple[np.ndarray, ...]:
    n_xy, n_t = int(round(half_xy / step_xy)), int(round(half_deg / step_deg))
    xy = np.arange(-n_xy, n_xy + 1) * step_xy
    return xy, xy.copy(), np.radians(np.arange(-n_t, n_t + 1) * step_deg)


def _offset_pose(pose: Pose2D, dx: float, dy: float, dtheta: float) -> Pose2D:
    return Pose2D(pose.x_m + dx, pose.y_m + dy, wrap_angle(pose.heading_rad + dtheta))


def _to_world(scan_xy: np.ndarray, pose: Pose2D) -> np.ndarray:
    c, s = math.cos(pose.heading_rad), math.sin(pose.heading_rad)
    return scan_xy @ np.array([[c, s], [-s, c]]) + np.array([pose.x_m, pose.y_m])


def _search(field: LikelihoodField, scan_xy: np.ndarray, pose: Pose2D, dxs: np.ndarray, dys: np.ndarray,
            dthetas: np.ndarray) -> np.ndarray:
    """Summed log-likelihood for every (dx, dy, dθ) offset of ``pose``: shape (len dxs, len dys, len dθ)."""
    return _search_kernel(field.values, field.resolution_m, field.pad_cells, np.ascontiguousarray(scan_xy),
                          pose.x_m, pose.y_m, pose.heading_rad, dxs, dys, dthetas)


@numba.njit(cache=True)
def _bilinear(values, res, pad, x, y):
    gx = x / res + pad - 0.5
    gy = y / res + pad - 0.5
    nx, ny = values.shape
    gx = min(max(gx, 0.0), nx - 1.001)
    gy = min(max(gy, 0.0), ny - 1.001)
    i, j = int(gx), int(gy)
    fx, fy = gx - i, gy - j
    return ((1 - fx) * (1 - fy) * values[i, j] + fx * (1 - fy) * values[i + 1, j]
            + (1 - fx) * fy * values[i, j + 1] + fx * fy * values[i + 1, j + 1])


@numba.njit(cache=True)
def _bilinear_many(values, res, pad, xy):
    out = np.empty(xy.shape[0])
    for k in range(xy.shape[0]):
        out[k] = _bilinear(values, res, pad, xy[k, 0], xy[k, 1])
    return out


@numba.njit(cache=True, parallel=True)
def _search_kernel(values, res, pad, scan, x0, y0, h0, dxs, dys, dthetas):
    out = np.empty((dxs.shape[0], dys.shape[0], dthetas.shape[0]))
    n = scan.shape[0]
    for t in numba.prange(dthetas.shape[0]):
        c, s = math.cos(h0 + dthetas[t]), math.sin(h0 + dthetas[t])
        wx = np.empty(n)
        wy = np.empty(n)
        for k in range(n):
            wx[k] = x0 + c * scan[k, 0] - s * scan[k, 1]
            wy[k] = y0 + s * scan[k, 0] + c * scan[k, 1]
        for a in range(dxs.shape[0]):
            for b in range(dys.shape[0]):
                total = 0.0
                for k in range(n):
                    total += _bilinear(values, res, pad, wx[k] + dxs[a], wy[k] + dys[b])
                out[a, b, t] = total
    return out


# --- fusion ----------------------------------------------------------------------------------------

@dataclass(frozen=True)
class OdometryModel:
    """How fast the odometry's error grows (a little above the simulator's, which a real base also is)."""

    distance_frac: float = 0.03  # std of the distance scale error
    turn_frac: float = 0.03  # std of the turn scale error
    drift_deg_per_m: float = 1.5  # std of the heading drift while driving
    gate_chi2: float = 16.3  # χ²(3) at 99.9 %: a match this far from the prediction is an outlier


class PoseTracker:
    """EKF over the corrected world pose; odometry is the prediction, scan matches the measurements."""

    def __init__(self, odom: Pose2D, world: Pose2D | None = None, model: OdometryModel = OdometryModel(),
                 covariance: np.ndarray | None = None):
        self.model = model
        self._odom = odom
        self.pose = world if world is not None else odom
        self.covariance = covariance if covariance is not None else np.diag([1e-4, 1e-4, math.radians(0.5) ** 2])
        self._set_offset(odom)

    def world_pose(self, odom: Pose2D) -> Pose2D:
        """The corrected world pose for an odometry pose."""
        x, y = self.world_point((odom.x_m, odom.y_m))
        return Pose2D(x, y, wrap_angle(odom.heading_rad + self._rotation))

    def world_point(self, odom_xy: tuple[float, float]) -> tuple[float, float]:
        c, s = math.cos(self._rotation), math.sin(self._rotation)
        return (c * odom_xy[0] - s * odom_xy[1] + self._translation[0],
                s * odom_xy[0] + c * odom_xy[1] + self._translation[1])

    def odom_point(self, world_xy: tuple[float, float]) -> tuple[float, float]:
        """A corrected-world point in the robot's odometry frame (what ``move_to`` expects)."""
        c, s = math.cos(self._rotation), math.sin(self._rotation)
        x, y = world_xy[0] - self._translation[0], world_xy[1] - self._translation[1]
        return c * x + s * y, -s * x + c * y

    def target_shift_m(self, range_m: float) -> float:
        """How far a point ``range_m`` ahead may land from where the pose puts it: the largest
        position σ plus the heading σ's sweep at that range, an upper bound on that point's σ."""
        sxy = math.sqrt(float(np.linalg.eigvalsh(self.covariance[:2, :2])[-1]))
        return sxy + range_m * math.sqrt(float(self.covariance[2, 2]))

    def predict(self, odom: Pose2D) -> Pose2D:
        """Move the estimate with the odometry since the last call and grow its covariance."""
        prev, self._odom = self._odom, odom
        step = prev.inverse().compose(odom)  # the motion in the frame of the base where it began
        distance = math.hypot(step.x_m, step.y_m)
        # under a centimetre the displacement is odometry's jitter: its direction is no turn the base made
        if distance > _STILL_M:
            turn_in, reverse = _first_turn(step)
        else:
            turn_in, reverse = 0.0, False
        turn_out = wrap_angle(step.heading_rad - turn_in)
        direction = self.pose.heading_rad + turn_in + (math.pi if reverse else 0.0)
        self.covariance = _propagate(self.covariance, direction, distance, turn_in, turn_out, self.model)
        self.pose = self.world_pose(odom)
        return self.pose

    def correct(self, odom: Pose2D, measured: Pose2D, covariance: np.ndarray) -> bool:
        """Fuse a scan match taken at ``odom``; False if it fails the χ² gate, and then the estimate
        is only the prediction to ``odom``."""
        self.predict(odom)
        nu = np.array([measured.x_m - self.pose.x_m, measured.y_m - self.pose.y_m,
                       wrap_angle(measured.heading_rad - self.pose.heading_rad)])
        innovation_cov = self.covariance + covariance
        distance2 = float(nu @ np.linalg.solve(innovation_cov, nu))
        if distance2 > self.model.gate_chi2:
            log.debug("scan match rejected: Mahalanobis² %.1f, innovation %s", distance2, np.round(nu, 3))
            return False
        gain = self.covariance @ np.linalg.inv(innovation_cov)
        dx = gain @ nu
        self.pose = Pose2D(self.pose.x_m + dx[0], self.pose.y_m + dx[1], wrap_angle(self.pose.heading_rad + dx[2]))
        self.covariance = (np.eye(3) - gain) @ self.covariance
        self.covariance = 0.5 * (self.covariance + self.covariance.T)
        self._set_offset(odom)
        return True

    def state(self) -> dict:
        """The estimate as plain numbers (a checkpoint); :meth:`restore` gives it back exactly. The
        offset is kept as it is: it was set at the last correction, not at the last odometry."""
        def plain(p: Pose2D) -> list[float]:
            return [float(p.x_m), float(p.y_m), float(p.heading_rad)]

        return {"odom": plain(self._odom), "pose": plain(self.pose),
                "covariance": np.asarray(self.covariance, np.float64).tolist(),
                "rotation": float(self._rotation), "translation": [float(v) for v in self._translation]}

    def restore(self, state: dict) -> None:
        """Take back a :meth:`state`; the robot's odometry carries on from where it was then."""
        covariance = np.array(state["covariance"], np.float64)
        if covariance.shape != (3, 3):
            raise ValueError(f"pose tracker covariance: expected 3 × 3, got {covariance.shape}")
        self._odom, self.pose = Pose2D(*state["odom"]), Pose2D(*state["pose"])
        self.covariance = covariance
        self._rotation, self._translation = float(state["rotation"]), tuple(float(v) for v in state["translation"])

    def _set_offset(self, odom: Pose2D) -> None:
        """``world_from_odom`` such that ``odom`` maps to ``self.pose``."""
        self._rotation = wrap_angle(self.pose.heading_rad - odom.heading_rad)
        c, s = math.cos(self._rotation), math.sin(self._rotation)
        self._translation = (self.pose.x_m - (c * odom.x_m - s * odom.y_m),
                             self.pose.y_m - (s * odom.x_m + c * odom.y_m))


def _first_turn(step: Pose2D) -> tuple[float, bool]:
    """The turn before the drive of an odometry ``step`` (in the frame where it began), and whether the
    drive was backwards. A step ending behind the base is a back-off (no turn, then reverse) or a turn
    past 90° then a forward drive (``move_to`` to a waypoint behind): whichever turns the base less."""
    forward = math.atan2(step.y_m, step.x_m)
    backward = math.atan2(-step.y_m, -step.x_m)

    def turning(turn_in: float) -> float:
        return abs(turn_in) + abs(wrap_angle(step.heading_rad - turn_in))

    return (backward, True) if turning(backward) < turning(forward) else (forward, False)


def _propagate(cov: np.ndarray, direction: float, distance: float, turn_in: float, turn_out: float,
               model: OdometryModel) -> np.ndarray:
    """Covariance after turning ``turn_in``, driving ``distance`` along ``direction``, turning ``turn_out``."""
    c, s = math.cos(direction), math.sin(direction)
    jf = np.array([[1.0, 0.0, -distance * s], [0.0, 1.0, distance * c], [0.0, 0.0, 1.0]])
    drift = math.radians(model.drift_deg_per_m) * distance
    # noise inputs: first turn, distance, heading drift (which also bends the drive sideways), last turn
    jn = np.array([[-distance * s, c, -0.5 * distance * s, 0.0],
                   [distance * c, s, 0.5 * distance * c, 0.0],
                   [1.0, 0.0, 1.0, 1.0]])
    q = np.diag([(model.turn_frac * turn_in) ** 2, (model.distance_frac * distance) ** 2, drift ** 2,
                 (model.turn_frac * turn_out) ** 2])
    return jf @ cov @ jf.T + jn @ q @ jn.T

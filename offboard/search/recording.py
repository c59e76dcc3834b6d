"""Everything the planner sees and decides, logged to Rerun.

Entity tree (it mirrors the frame tree):

- ``world/room`` — the search region's boundary (static);
- ``world/robot`` — the robot's pose; ``world/robot/head`` — pan and tilt;
  ``world/robot/head/camera`` — the left camera (pinhole logged once, static), its image with the
  detection, and the depth from stereo;
- ``world/occupancy`` — occupied cubes coloured by log-odds; ``world/target_prob`` — the most likely
  cubes coloured by probability; ``world/path``, ``world/looks``, ``world/target_estimate``;
- ``maps/target_prob`` — the column-sum target probability map; ``maps/position_prob`` — the
  candidate positions coloured by covering probability (report §5.1). Both maps share one frame,
  the map's pixels (one per cube, x to the right and y up), so a position and its column line up;
- ``plan/utility`` — every action's expected detection probability; ``stats/…`` — scalars;
- ``logs`` — Python logging.

Timelines: ``action`` (one tick per action) and ``robot_time`` (the robot's clock).
"""

from __future__ import annotations

import logging
import math
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from offboard.planning.action_values import ActionValues
from offboard.planning.belief import TargetBelief
from offboard.perception.occupancy import OccupancyGrid
from offboard.perception.voxel_grid import VoxelGrid
from offboard.perception.observation import Observation
from offboard.perception.stereo import depth_from_disparity
from shared.geometry import HeadMount, Intrinsics, Pose2D, RigidTransform

MAX_OCCUPIED_POINTS = 60_000
MAX_PROBABLE_CUBES = 4_000


def blueprint() -> rrb.Blueprint:
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Spatial3DView(origin="world", name="room"),
            rrb.Vertical(
                rrb.Spatial2DView(origin="world/robot/head/camera", name="left camera"),
                rrb.Horizontal(rrb.Spatial2DView(origin="maps/target_prob", name="target probability"),
                               rrb.Spatial2DView(origin="maps/position_prob", name="position probability")),
                rrb.Tabs(rrb.BarChartView(origin="plan/utility", name="action values"),
                         rrb.TimeSeriesView(origin="stats", name="search"),
                         rrb.TextLogView(origin="logs", name="log")),
            ),
            column_shares=[3, 2],
        ),
        collapse_panels=True,
    )


class Recorder:
    """A Rerun recording stream for one search (pass it around; no global state)."""

    def __init__(self, path: Path | None = None, spawn: bool = False, connect_url: str | None = None):
        self.stream = rr.RecordingStream("syt")
        sinks: list = []
        if path is not None:
            sinks.append(rr.FileSink(str(path)))
        if connect_url is not None:
            sinks.append(rr.GrpcSink(connect_url))
        if spawn:
            self.stream.spawn(connect=False)
            sinks.append(rr.GrpcSink())
        self.stream.set_sinks(*sinks, default_blueprint=blueprint())
        self._handler = _ViewerLogHandler(self.stream)
        self._path: list[list[float]] = []
        self._looks: list[np.ndarray] = []

    def attach_logging(self, logger: logging.Logger) -> None:
        """Route Python logging into the viewer (into this recording)."""
        logger.addHandler(self._handler)

    def detach_logging(self, logger: logging.Logger) -> None:
        logger.removeHandler(self._handler)

    def close(self) -> None:
        self.stream.flush()
        self.stream.disconnect()

    # --- once ----------------------------------------------------------------------------------------

    def log_setup(self, room_m: tuple[float, float, float], intrinsics: Intrinsics, mount: HeadMount) -> None:
        s = self.stream
        half = np.array(room_m) / 2
        s.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        s.log("world/room", rr.Boxes3D(centers=[half], half_sizes=[half], colors=[(200, 200, 200)]), static=True)
        head_camera = mount.head_in_robot(0.0, 0.0).inverse().compose(mount.camera_in_robot(0.0, 0.0))
        s.log("world/robot/head/camera", _transform(head_camera), static=True)
        s.log("world/robot/head/camera", rr.Pinhole(image_from_camera=intrinsics.matrix(),
                                                    resolution=[intrinsics.width_px, intrinsics.height_px],
                                                    camera_xyz=rr.ViewCoordinates.RDF, image_plane_distance=0.3),
              static=True)
        s.log("world/robot/body", rr.Cylinders3D(lengths=[0.4], radii=[0.26], centers=[[0, 0, 0.2]],
                                                  colors=[(170, 110, 60)]), static=True)

    # --- per action ----------------------------------------------------------------------------------

    def set_time(self, action: int | None, robot_time_s: float) -> None:
        """What follows is logged at this look (``action``) and robot time; with no ``action``, on the
        robot's clock only (a glance between looks)."""
        if action is None:
            self.stream.disable_timeline("action")
        else:
            self.stream.set_time("action", sequence=action)
        self.stream.set_time("robot_time", duration=robot_time_s)

    def log_pose(self, pose: Pose2D, pan_rad: float, tilt_rad: float, mount: HeadMount) -> None:
        s = self.stream
        s.log("world/robot", _transform(pose.to_transform()))
        head = mount.head_in_robot(pan_rad, tilt_rad)
        s.log("world/robot/head", _transform(head))
        self._path.append([pose.x_m, pose.y_m, 0.02])
        s.log("world/path", rr.LineStrips3D([self._path], colors=[(230, 120, 30)], radii=[0.02]))

    def log_observation(self, obs: Observation, depth_of_field_m: float) -> None:
        s = self.stream
        s.log("world/robot/head/camera/image", rr.Image(obs.capture.left))
        depth = np.nan_to_num(depth_from_disparity(obs.disparity, obs.intrinsics, obs.baseline_m), nan=0.0)  # 0: none
        s.log("world/robot/head/camera/depth", rr.DepthImage(depth, meter=1.0))
        if obs.detection is not None:
            s.log("world/robot/head/camera/image/detection",
                  rr.LineStrips2D([np.vstack([obs.detection.corners_px, obs.detection.corners_px[:1]])],
                                  colors=[(255, 40, 40)], labels=[f"{obs.detection.detector} {obs.detection.score:.2f}"]))
        else:
            s.log("world/robot/head/camera/image/detection", rr.Clear(recursive=False))
        self._looks.append(_fov_wedge(obs.camera_in_world, obs.intrinsics, depth_of_field_m))
        s.log("world/looks", rr.LineStrips3D(self._looks, colors=[(60, 140, 230)], radii=[0.01]))

    def log_target(self, target_m: np.ndarray) -> None:
        self.stream.log("world/target_estimate", rr.Points3D([target_m], radii=[0.08], colors=[(255, 0, 0)],
                                                              labels=["target"]))

    def log_maps(self, belief: TargetBelief, occupancy: OccupancyGrid) -> None:
        s = self.stream
        grid = occupancy.grid
        occupied = occupancy.occupied()
        cubes = np.argwhere(occupied)  # the centres of the cubes shown only: all of them are 161 MB in a 20 m hall
        values = occupancy.log_odds[occupied]
        if len(cubes) > MAX_OCCUPIED_POINTS:
            keep = np.argsort(values)[-MAX_OCCUPIED_POINTS:]
            cubes, values = cubes[keep], values[keep]
        s.log("world/occupancy", rr.Points3D(grid.center_of(cubes), radii=grid.resolution_m / 2,
                                             colors=_ramp(values, occupancy.config.clamp_max)))
        prob = belief.target_prob
        flat = prob.reshape(-1)
        top = np.flatnonzero(flat > 2.0 * belief.prob_inside / flat.size)  # only cubes above twice the average
        if len(top) > MAX_PROBABLE_CUBES:  # selected among those: a partition of the whole grid takes 0.4 s in a 20 m hall
            top = top[np.argpartition(flat[top], -MAX_PROBABLE_CUBES)[-MAX_PROBABLE_CUBES:]]
        top_centers = grid.center_of(np.stack(np.unravel_index(top, grid.shape), axis=-1))
        s.log("world/target_prob", rr.Boxes3D(centers=top_centers, half_sizes=[grid.resolution_m / 2] * 3,
                                              colors=_ramp(flat[top], flat.max() if flat.size else 1.0, hot=True),
                                              fill_mode="solid"))
        s.log("maps/target_prob", rr.Image(_to_image(prob.sum(axis=2))))  # the report's map: each column's sum

    def log_plan(self, values: ActionValues, positions: np.ndarray, grid: VoxelGrid) -> None:
        """Every action's expected detection probability, and the candidate positions (the report's
        grid vertices and the viewpoints aimed at the belief, in metres) coloured by covering
        probability, drawn in the target map's pixels."""
        s = self.stream
        s.log("plan/utility", rr.BarChart(values.find_prob[:-1].reshape(-1)))
        covering = values.covering_prob[:-1]
        s.log("maps/position_prob", rr.Points2D(_map_pixels(grid, positions), radii=0.1 / grid.resolution_m,
                                                colors=_ramp(covering, max(float(covering.max(initial=0.0)), 1e-12), hot=True)))

    def log_stats(self, **scalars: float) -> None:
        for name, value in scalars.items():
            self.stream.log(f"stats/{name}", rr.Scalars(float(value)))


class _ViewerLogHandler(logging.Handler):
    """Python logging into ``logs`` of one recording (rr.LoggingHandler writes to the global one)."""

    def __init__(self, stream: rr.RecordingStream):
        super().__init__(logging.INFO)
        self.stream = stream

    def emit(self, record: logging.LogRecord) -> None:
        level = next(name for at_least, name in _LEVELS if record.levelno >= at_least)  # CRITICAL is an error too
        text = f"{record.name}: {record.getMessage()}"
        if record.exc_info:
            text += "\n" + logging.Formatter().formatException(record.exc_info)
        self.stream.log("logs", rr.TextLog(text, level=level))


_LEVELS = ((logging.ERROR, "ERROR"), (logging.WARNING, "WARN"), (logging.INFO, "INFO"), (logging.NOTSET, "DEBUG"))


def _transform(t: RigidTransform) -> rr.Transform3D:
    return rr.Transform3D(translation=t.translation, mat3x3=t.rotation)


def _fov_wedge(camera: RigidTransform, k: Intrinsics, depth_m: float) -> np.ndarray:
    """The horizontal field of view out to the detector's range, as a closed line on the floor."""
    half = k.hfov_rad / 2
    axis = camera.rotation[:, 2]
    azimuth = math.atan2(axis[1], axis[0])
    origin = np.array([camera.translation[0], camera.translation[1], 0.03])
    arc = [origin + depth_m * np.array([math.cos(a), math.sin(a), 0.0])
           for a in np.linspace(azimuth - half, azimuth + half, 9)]
    return np.vstack([origin, *arc, origin])


def _ramp(values: np.ndarray, top: float, hot: bool = False) -> np.ndarray:
    t = np.clip(np.asarray(values, float) / max(top, 1e-12), 0, 1)
    if hot:
        return (np.stack([255 * np.ones_like(t), 255 * (1 - t), 40 * np.ones_like(t)], axis=-1)).astype(np.uint8)
    return (np.stack([80 + 100 * t, 80 + 100 * t, 90 + 120 * t], axis=-1)).astype(np.uint8)


def _map_pixels(grid: VoxelGrid, xy_m: np.ndarray) -> np.ndarray:
    """Floor points (metres) in the pixels of :func:`_to_image`'s map of ``grid``: a point in cube
    column (i, j) lands in that column's pixel, whose centre is (i + 0.5, ny - j - 0.5)."""
    scaled = (np.asarray(xy_m, float).reshape(-1, 2) - grid.origin[:2]) / grid.resolution_m
    return np.column_stack([scaled[:, 0], grid.shape[1] - scaled[:, 1]])


def _to_image(values: np.ndarray) -> np.ndarray:
    """A floor map (indexed [x, y]) as an image with x to the right and y up, lighter = larger."""
    top = values.max()
    scaled = (255 * values / top).astype(np.uint8) if top > 0 else np.zeros(values.shape, np.uint8)
    return np.flipud(scaled.T)

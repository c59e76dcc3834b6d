"""Frames and the conversions between them, written down once.

Frames (all right-handed, metres, radians inside the code; degrees only at the edges):

- **world**: origin at a floor corner of the room, x and y on the floor, z up.
- **robot**: origin on the floor under the robot's centre, x forward, y left, z up.
  A robot pose is ``(x_m, y_m, heading_rad)`` in the world, heading counter-clockwise from +x.
- **head**: the pan-tilt head, origin at the tilt axis (``HeadMount.forward_m`` ahead of the robot
  centre, ``HeadMount.height_m`` above the floor); rotated by ``pan`` about robot z
  (counter-clockwise positive, i.e. to the left) and then by ``tilt`` about the head's y axis
  (positive looks up). At pan = tilt = 0 it is aligned with the robot frame.
- **camera optical** (OpenCV): x right, y down, z along the viewing axis. The *left* camera is the
  reference of a rectified pair; it sits ``baseline_m / 2`` to the left of the head origin and the
  right camera ``baseline_m / 2`` to the right, so in the left optical frame the right camera is at
  ``x = +baseline_m``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# Columns are the optical axes expressed in the head frame: x_opt = -y_head, y_opt = -z_head,
# z_opt = +x_head.
_HEAD_FROM_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def rot_z(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rot_y(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def wrap_angle(angle_rad: float) -> float:
    """Angle wrapped to [-pi, pi)."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


@dataclass(frozen=True)
class RigidTransform:
    """``T_a_b``: maps points expressed in frame b into frame a (``p_a = R p_b + t``)."""

    rotation: np.ndarray  # (3, 3)
    translation: np.ndarray  # (3,)

    def apply(self, points: np.ndarray) -> np.ndarray:
        """Transform points of shape (..., 3)."""
        return points @ self.rotation.T + self.translation

    def compose(self, other: RigidTransform) -> RigidTransform:
        """``T_a_b.compose(T_b_c) == T_a_c``."""
        return RigidTransform(
            self.rotation @ other.rotation, self.rotation @ other.translation + self.translation
        )

    def inverse(self) -> RigidTransform:
        r_inv = self.rotation.T
        return RigidTransform(r_inv, -r_inv @ self.translation)


@dataclass(frozen=True)
class Pose2D:
    """Robot pose on the floor: position in the world frame and heading (counter-clockwise from +x)."""

    x_m: float
    y_m: float
    heading_rad: float

    def to_transform(self) -> RigidTransform:
        """``T_world_robot``."""
        return RigidTransform(rot_z(self.heading_rad), np.array([self.x_m, self.y_m, 0.0]))

    def moved(self, forward_m: float, turn_rad: float = 0.0) -> Pose2D:
        """The pose after turning by ``turn_rad`` in place, then driving ``forward_m`` straight."""
        heading = wrap_angle(self.heading_rad + turn_rad)
        return Pose2D(
            self.x_m + forward_m * math.cos(heading),
            self.y_m + forward_m * math.sin(heading),
            heading,
        )

    def compose(self, other: Pose2D) -> Pose2D:
        """``other``, given in this pose's frame, in this pose's parent frame."""
        c, s = math.cos(self.heading_rad), math.sin(self.heading_rad)
        return Pose2D(self.x_m + c * other.x_m - s * other.y_m, self.y_m + s * other.x_m + c * other.y_m,
                      wrap_angle(self.heading_rad + other.heading_rad))

    def inverse(self) -> Pose2D:
        """The parent frame's pose seen from this pose."""
        c, s = math.cos(self.heading_rad), math.sin(self.heading_rad)
        return Pose2D(-(c * self.x_m + s * self.y_m), s * self.x_m - c * self.y_m, wrap_angle(-self.heading_rad))

    def distance_to(self, x_m: float, y_m: float) -> float:
        return math.hypot(x_m - self.x_m, y_m - self.y_m)

    def bearing_to(self, x_m: float, y_m: float) -> float:
        """Turn (rad, wrapped) that points the robot at ``(x_m, y_m)``."""
        return wrap_angle(math.atan2(y_m - self.y_m, x_m - self.x_m) - self.heading_rad)


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics of a rectified camera (pixels)."""

    width_px: int
    height_px: int
    fx_px: float
    fy_px: float
    cx_px: float
    cy_px: float

    @classmethod
    def from_fov(cls, width_px: int, height_px: int, hfov_deg: float) -> Intrinsics:
        """Square pixels, principal point at the image centre: f = (W/2) / tan(HFOV/2)."""
        f = (width_px / 2.0) / math.tan(math.radians(hfov_deg) / 2.0)
        return cls(width_px, height_px, f, f, (width_px - 1) / 2.0, (height_px - 1) / 2.0)

    def matrix(self) -> np.ndarray:
        return np.array([[self.fx_px, 0.0, self.cx_px], [0.0, self.fy_px, self.cy_px], [0.0, 0.0, 1.0]])

    @property
    def hfov_rad(self) -> float:
        return 2.0 * math.atan2(self.width_px / 2.0, self.fx_px)

    @property
    def vfov_rad(self) -> float:
        return 2.0 * math.atan2(self.height_px / 2.0, self.fy_px)

    def project(self, points_cam: np.ndarray) -> np.ndarray:
        """Points (..., 3) in the optical frame to pixels (..., 2); points behind give NaN."""
        z = points_cam[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = np.where(z > 0, self.fx_px * points_cam[..., 0] / z + self.cx_px, np.nan)
            v = np.where(z > 0, self.fy_px * points_cam[..., 1] / z + self.cy_px, np.nan)
        return np.stack([u, v], axis=-1)

    def back_project(self, u_px, v_px, z_m) -> np.ndarray:
        """Pixels (u, v) at optical depth z to points (..., 3) in the optical frame: :meth:`project`
        undone. Keeps the inputs' precision (float32 pixels give float32 points)."""
        x = (u_px - self.cx_px) * z_m / self.fx_px
        y = (v_px - self.cy_px) * z_m / self.fy_px
        return np.stack([x, y, np.broadcast_to(z_m, np.shape(x))], axis=-1)

    def pixel_rays(self) -> np.ndarray:
        """Unnormalised ray directions (H, W, 3) through every pixel centre, z = 1."""
        u = (np.arange(self.width_px) - self.cx_px) / self.fx_px
        v = (np.arange(self.height_px) - self.cy_px) / self.fy_px
        uu, vv = np.meshgrid(u, v)
        return np.stack([uu, vv, np.ones_like(uu)], axis=-1)


@dataclass(frozen=True)
class HeadMount:
    """Where the pan-tilt head sits on the robot and how far apart the stereo cameras are."""

    height_m: float = 1.2  # tilt axis above the floor
    forward_m: float = 0.0  # tilt axis ahead of the robot centre
    baseline_m: float = 0.12  # Bumblebee2

    def head_in_robot(self, pan_rad: float, tilt_rad: float) -> RigidTransform:
        """``T_robot_head`` for a pan/tilt setting."""
        return RigidTransform(
            rot_z(pan_rad) @ rot_y(-tilt_rad), np.array([self.forward_m, 0.0, self.height_m])
        )

    def camera_in_robot(self, pan_rad: float, tilt_rad: float, side: str = "left") -> RigidTransform:
        """``T_robot_camera`` of the left (reference) or right optical frame."""
        if side not in ("left", "right"):
            raise ValueError(f"side must be 'left' or 'right', not {side!r}")
        offset = self.baseline_m / 2.0 if side == "left" else -self.baseline_m / 2.0
        head_camera = RigidTransform(_HEAD_FROM_OPTICAL, np.array([0.0, offset, 0.0]))
        return self.head_in_robot(pan_rad, tilt_rad).compose(head_camera)

    def camera_in_world(
        self, pose: Pose2D, pan_rad: float, tilt_rad: float, side: str = "left"
    ) -> RigidTransform:
        """``T_world_camera`` for a robot pose and pan/tilt setting."""
        return pose.to_transform().compose(self.camera_in_robot(pan_rad, tilt_rad, side))

"""Every message between the robot and the planner, as typed frozen dataclasses.

Units are in the field names. Angles on the wire are degrees (readable in a capture of the
traffic); code converts at the edges. Commands carry a ``command_id`` that their reply echoes.
Encoding and strict decoding live in :mod:`shared.codec`; key expressions in :mod:`shared.keys`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from shared.geometry import HeadMount, Intrinsics, Pose2D
from shared.limits import BaseLimits, CameraTiming, PanTiltLimits
from shared.strict import bounds

SCHEMA_VERSION = 1

_COORD = bounds(-1.0e4, 1.0e4)  # metres: generous, but rejects garbage such as 1e300
_TIME = bounds(0.0, 1.0e9)


def _check_id(command_id: str) -> None:
    if not 0 < len(command_id) <= 64:
        raise ValueError(f"command_id must have 1 to 64 characters (got {len(command_id)})")


# --- values ----------------------------------------------------------------------------------------

@dataclass(frozen=True)
class PoseMsg:
    """Robot pose in the world frame as reported by the robot (odometry, possibly drifted)."""

    x_m: float = field(metadata=_COORD)
    y_m: float = field(metadata=_COORD)
    heading_deg: float = field(metadata=bounds(-360.0, 360.0))

    @classmethod
    def from_pose(cls, pose: Pose2D) -> PoseMsg:
        return cls(pose.x_m, pose.y_m, math.degrees(pose.heading_rad))

    def to_pose(self) -> Pose2D:
        return Pose2D(self.x_m, self.y_m, math.radians(self.heading_deg))


@dataclass(frozen=True)
class IntrinsicsMsg:
    width_px: int = field(metadata=bounds(1, 100_000))
    height_px: int = field(metadata=bounds(1, 100_000))
    fx_px: float = field(metadata=bounds(1e-3, 1e6))
    fy_px: float = field(metadata=bounds(1e-3, 1e6))
    cx_px: float = field(metadata=bounds(-1e6, 1e6))
    cy_px: float = field(metadata=bounds(-1e6, 1e6))

    @classmethod
    def from_intrinsics(cls, k: Intrinsics) -> IntrinsicsMsg:
        return cls(k.width_px, k.height_px, k.fx_px, k.fy_px, k.cx_px, k.cy_px)

    def to_intrinsics(self) -> Intrinsics:
        return Intrinsics(self.width_px, self.height_px, self.fx_px, self.fy_px, self.cx_px, self.cy_px)


@dataclass(frozen=True)
class MountMsg:
    height_m: float = field(metadata=bounds(0.0, 10.0))
    forward_m: float = field(metadata=bounds(-5.0, 5.0))
    baseline_m: float = field(metadata=bounds(1e-3, 5.0))

    @classmethod
    def from_mount(cls, m: HeadMount) -> MountMsg:
        return cls(m.height_m, m.forward_m, m.baseline_m)

    def to_mount(self) -> HeadMount:
        return HeadMount(self.height_m, self.forward_m, self.baseline_m)


# --- commands (queries) ----------------------------------------------------------------------------

@dataclass(frozen=True)
class MoveCommand:
    """Rotate in place by ``turn_deg`` (counter-clockwise), then drive ``distance_m`` straight
    (negative backs up); or, with ``waypoint_m``, turn towards that world point and drive to it."""

    command_id: str
    turn_deg: float = field(default=0.0, metadata=bounds(-3600.0, 3600.0))
    distance_m: float = field(default=0.0, metadata=bounds(-1000.0, 1000.0))
    waypoint_m: tuple[float, float] | None = None
    speed_m_s: float | None = field(default=None, metadata=bounds(1e-3, 10.0))  # None: default speed

    def __post_init__(self) -> None:
        _check_id(self.command_id)
        if self.waypoint_m is not None and (self.turn_deg or self.distance_m):
            raise ValueError("give either waypoint_m or turn_deg/distance_m, not both")


@dataclass(frozen=True)
class StopCommand:
    command_id: str

    def __post_init__(self) -> None:
        _check_id(self.command_id)


@dataclass(frozen=True)
class LookCommand:
    """Point the pan-tilt unit (absolute angles; pan counter-clockwise and tilt up are positive)."""

    command_id: str
    pan_deg: float = field(metadata=bounds(-360.0, 360.0))
    tilt_deg: float = field(metadata=bounds(-90.0, 90.0))

    def __post_init__(self) -> None:
        _check_id(self.command_id)


@dataclass(frozen=True)
class CaptureCommand:
    """Take one synchronised, rectified stereo pair. ``png`` saves bandwidth over Wi-Fi."""

    command_id: str
    encoding: Literal["raw", "png"] = "raw"

    def __post_init__(self) -> None:
        _check_id(self.command_id)


@dataclass(frozen=True)
class StateRequest:
    command_id: str

    def __post_init__(self) -> None:
        _check_id(self.command_id)


@dataclass(frozen=True)
class InfoRequest:
    command_id: str

    def __post_init__(self) -> None:
        _check_id(self.command_id)


# --- replies ---------------------------------------------------------------------------------------

@dataclass(frozen=True)
class ErrorReply:
    """A refused or failed command. ``code``: ``protocol`` (malformed), ``limit`` (outside the
    device limits), ``busy`` (the device is executing another command, or the agent's command queue
    is full), ``device`` (hardware fault),
    ``planner`` (a move from a planner whose liveliness token is gone), ``shutdown`` (the agent is
    stopping)."""

    command_id: str
    code: Literal["protocol", "limit", "busy", "device", "planner", "shutdown"]
    message: str


@dataclass(frozen=True)
class MoveResult:
    """``done``: the motion completed; ``stalled``: blocked by an obstacle (stopped at contact);
    ``stopped``: interrupted by a stop command or the watchdog, or never begun (0 m) because a stop
    arrived while it waited in the agent's queue."""

    command_id: str
    status: Literal["done", "stalled", "stopped"]
    pose: PoseMsg
    distance_m: float = field(metadata=bounds(0.0, 1e4))  # distance actually driven
    duration_s: float = field(metadata=_TIME)
    robot_time_s: float = field(metadata=_TIME)  # robot clock when the motion ended


@dataclass(frozen=True)
class StopResult:
    command_id: str
    pose: PoseMsg
    robot_time_s: float = field(metadata=_TIME)


@dataclass(frozen=True)
class LookResult:
    """Where the head stands once the look ends: not where it was asked to go if a stop cut the look
    short, or arrived while it waited in the agent's queue (then it never began)."""

    command_id: str
    pan_deg: float = field(metadata=bounds(-360.0, 360.0))
    tilt_deg: float = field(metadata=bounds(-90.0, 90.0))
    duration_s: float = field(metadata=_TIME)
    robot_time_s: float = field(metadata=_TIME)


@dataclass(frozen=True)
class Capture:
    """A rectified stereo pair (RGB, uint8, H×W×3) and everything needed to place it in the world."""

    command_id: str
    left: np.ndarray
    right: np.ndarray
    pose: PoseMsg  # odometry pose at exposure
    pan_deg: float = field(metadata=bounds(-360.0, 360.0))
    tilt_deg: float = field(metadata=bounds(-90.0, 90.0))
    intrinsics: IntrinsicsMsg
    mount: MountMsg  # includes the stereo baseline
    robot_time_s: float = field(metadata=_TIME)  # robot clock at exposure
    duration_s: float = field(metadata=_TIME)

    def __post_init__(self) -> None:
        for name in ("left", "right"):
            img = getattr(self, name)
            if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
                raise ValueError(f"{name} must be an H×W×3 uint8 RGB image, not {img.dtype} {img.shape}")
            if img.shape[:2] != (self.intrinsics.height_px, self.intrinsics.width_px):
                raise ValueError(f"{name} is {img.shape[1]}×{img.shape[0]} but the intrinsics say "
                                 f"{self.intrinsics.width_px}×{self.intrinsics.height_px}")


@dataclass(frozen=True)
class RobotState:
    """A snapshot of the robot: the ``state`` reply and the steady publications."""

    pose: PoseMsg
    speed_m_s: float = field(metadata=bounds(-100.0, 100.0))
    turn_rate_deg_s: float = field(metadata=bounds(-10_000.0, 10_000.0))
    pan_deg: float = field(metadata=bounds(-360.0, 360.0))
    tilt_deg: float = field(metadata=bounds(-90.0, 90.0))
    base_moving: bool
    pantilt_moving: bool
    stalled: bool
    robot_time_s: float = field(metadata=_TIME)


@dataclass(frozen=True)
class StateReply:
    command_id: str
    state: RobotState


@dataclass(frozen=True)
class Odometry:
    """Published at a steady rate: the base's odometry."""

    seq: int = field(metadata=bounds(0, None))
    pose: PoseMsg
    speed_m_s: float = field(metadata=bounds(-100.0, 100.0))
    turn_rate_deg_s: float = field(metadata=bounds(-10_000.0, 10_000.0))
    moving: bool
    stalled: bool
    robot_time_s: float = field(metadata=_TIME)


@dataclass(frozen=True)
class PanTiltState:
    """Published at a steady rate: the pan-tilt unit's position."""

    seq: int = field(metadata=bounds(0, None))
    pan_deg: float = field(metadata=bounds(-360.0, 360.0))
    tilt_deg: float = field(metadata=bounds(-90.0, 90.0))
    moving: bool
    robot_time_s: float = field(metadata=_TIME)


@dataclass(frozen=True)
class Info:
    """What the robot is: its limits, camera model and backend (``sim`` or ``hardware``)."""

    command_id: str
    robot_id: str
    backend: str
    base: BaseLimits
    pantilt: PanTiltLimits
    camera: CameraTiming
    intrinsics: IntrinsicsMsg
    mount: MountMsg
    watchdog_ms: int = field(metadata=bounds(1, 3_600_000))
    # the robot's clock is the wall clock (hardware, a paced simulator): it runs on while the planner
    # processes, so processing is part of robot time; a fast simulator's clock advances with actions only
    wall_clock: bool = False


HEARTBEAT_PERIOD_S = 0.2  # the planner's beat; the agent's watchdog waits for at least three


@dataclass(frozen=True)
class Heartbeat:
    """Published by the planner every :data:`HEARTBEAT_PERIOD_S` while it drives the robot; the agent's
    watchdog listens for it."""

    planner_id: str
    seq: int = field(metadata=bounds(0, None))


@dataclass(frozen=True)
class SimTruth:
    """Simulator only, for tests and benchmarks (never used by the planner): the true pose."""

    command_id: str
    pose: PoseMsg
    robot_time_s: float = field(metadata=_TIME)


@dataclass(frozen=True)
class SimTeleport:
    """Simulator only, for calibration and tests: put the robot at a pose (truth and odometry)."""

    command_id: str
    pose: PoseMsg

    def __post_init__(self) -> None:
        _check_id(self.command_id)


@dataclass(frozen=True)
class SimReset:
    """Simulator only, for experiment sweeps: start a new run in the same agent — the robot at
    ``start`` (truth and odometry, head at pan 0, tilt 0), the target's bottom-face centre at
    ``target_m`` facing ``target_yaw_deg``, the odometry noise drawn afresh from ``seed``."""

    command_id: str
    start: PoseMsg
    target_m: tuple[float, float, float]
    target_yaw_deg: float = field(metadata=bounds(-360.0, 360.0))
    seed: int = field(default=0, metadata=bounds(0, 2**63 - 1))

    def __post_init__(self) -> None:
        _check_id(self.command_id)
        if len(self.target_m) != 3 or not all(math.isfinite(v) and abs(v) <= 1.0e4 for v in self.target_m):
            raise ValueError(f"target_m must be 3 finite coordinates in metres, got {self.target_m}")


@dataclass(frozen=True)
class SimFault:
    """Simulator only, for tests: the device's next operation (a move, a look, a capture) fails
    ``after_s`` of robot time into it, as a broken driver would: the call raises while the device
    itself goes on (the wheels keep turning) until the agent stops it."""

    command_id: str
    device: Literal["base", "pantilt", "camera"]
    after_s: float = field(default=0.0, metadata=bounds(0.0, 3600.0))

    def __post_init__(self) -> None:
        _check_id(self.command_id)


MESSAGE_TYPES: dict[str, type] = {cls.__name__: cls for cls in (
    MoveCommand, StopCommand, LookCommand, CaptureCommand, StateRequest, InfoRequest,
    ErrorReply, MoveResult, StopResult, LookResult, Capture, RobotState, StateReply, Odometry,
    PanTiltState, Info, Heartbeat, SimTruth, SimTeleport, SimReset, SimFault,
)}

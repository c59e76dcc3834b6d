"""One interface per device, shared by every backend (the simulator and the serial hardware), and
the one error a device raises when it cannot serve.

The agent talks only to these protocols, so the planner never knows which backend answers it.
Angles are radians here; the wire (degrees) is the agent's business.
"""

from __future__ import annotations

import logging
import threading
from dataclasses import dataclass
from typing import Literal, Protocol

import numpy as np

from shared.geometry import HeadMount, Intrinsics, Pose2D
from shared.limits import BaseLimits, PanTiltLimits

log = logging.getLogger(__name__)


class DeviceFault(RuntimeError):
    """The device is unreachable or misbehaving (link down, no reply, refused command).

    The agent answers any exception from a device with an ``ErrorReply`` of code ``device``; the
    message says which device and what went wrong.
    """


@dataclass(frozen=True)
class MotionOutcome:
    status: Literal["done", "stalled", "stopped"]
    distance_m: float  # distance actually driven, along the command: never negative
    duration_s: float  # robot time the motion took


@dataclass(frozen=True)
class BaseReading:
    pose: Pose2D  # odometry: what the robot believes, not the truth
    speed_m_s: float
    turn_rate_rad_s: float
    moving: bool
    stalled: bool


@dataclass(frozen=True)
class PanTiltReading:
    pan_rad: float
    tilt_rad: float
    moving: bool


@dataclass(frozen=True)
class StereoImages:
    left: np.ndarray  # H×W×3 uint8 RGB, rectified
    right: np.ndarray


class Clock(Protocol):
    """The robot's clock. The simulator's runs as fast as the machine allows unless paced."""

    realtime: bool  # the wall clock: it runs on while the planner processes, not only with actions

    def now_s(self) -> float: ...


class Base(Protocol):
    limits: BaseLimits

    def move(self, turn_rad: float, distance_m: float, speed_m_s: float,
             cancel: threading.Event) -> MotionOutcome:
        """Turn in place, then drive straight; block until done, stalled or ``cancel`` is set."""

    def stop(self) -> None:
        """Stop at once; safe to call from any thread, at any time, repeatedly."""

    def reading(self) -> BaseReading: ...

    def close(self) -> None:
        """Stop and release the device."""


class PanTilt(Protocol):
    limits: PanTiltLimits

    def look(self, pan_rad: float, tilt_rad: float, cancel: threading.Event) -> float:
        """Slew to an absolute setting (already checked against the limits); return the time taken."""

    def halt(self) -> None: ...

    def reading(self) -> PanTiltReading: ...

    def close(self) -> None: ...


class StereoCamera(Protocol):
    intrinsics: Intrinsics
    mount: HeadMount

    def capture(self) -> StereoImages:
        """One synchronised, rectified pair."""

    def close(self) -> None: ...


class SimControl(Protocol):
    """What only a simulator can do, for tests, benchmarks and detector calibration."""

    @property
    def true_pose(self) -> Pose2D: ...

    def teleport(self, pose: Pose2D) -> str | None:
        """Put the robot at ``pose`` (truth and odometry); the reason if it cannot stand there."""

    def reset(self, start: Pose2D, target_m: tuple[float, float, float], target_yaw_deg: float,
              seed: int) -> str | None:
        """A new run in the same simulator: the target placed, the robot at ``start``, the head
        centred, the noise reseeded; the reason if that cannot be."""

    def inject_fault(self, device: str, after_s: float) -> None:
        """Make ``device``'s next operation fail ``after_s`` into it (see ``onboard.sim.faults``)."""


@dataclass
class Devices:
    """The robot as the agent sees it."""

    backend: str
    clock: Clock
    base: Base
    pantilt: PanTilt
    camera: StereoCamera

    def close(self) -> None:
        """Base first: a moving robot is the only dangerous thing here. Each is closed whatever the
        others do (a base whose port died must not leave the head slewing and the camera held); the
        first failure is raised once all have been tried."""
        failures = []
        for device in (self.base, self.pantilt, self.camera):
            try:
                device.close()
            except Exception as exc:
                log.exception("closing the %s failed", type(device).__name__)
                failures.append(exc)
        if failures:
            raise failures[0]

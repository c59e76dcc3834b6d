"""The robot's physical limits and timing, shared so the planner's time model matches the agent.

Defaults are those of the report's robot: a Pioneer 3-DX base and a Directed Perception PTU-D46
pan-tilt unit carrying a Bumblebee2 stereo head (their manuals and datasheet). The agent
loads them from its config, refuses commands outside them, and reports them in its ``info`` reply.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from shared.strict import bounds


@dataclass(frozen=True)
class BaseLimits:
    """Differential-drive base (Pioneer 3-DX)."""

    radius_m: float = field(default=0.26, metadata=bounds(0.05, 2.0))  # footprint disc for collisions
    height_m: float = field(default=1.35, metadata=bounds(0.1, 3.0))  # anything lower blocks the base
    # bounded by the P3-DX firmware's 2200 mm/s and 500°/s: it clamps SETV/SETRV beyond them, silently,
    # and the time model would then count on a speed the base never reaches
    max_speed_m_s: float = field(default=1.2, metadata=bounds(0.01, 2.2))  # P3-DX top speed
    default_speed_m_s: float = field(default=0.4, metadata=bounds(0.01, 2.2))  # indoor cruising speed
    accel_m_s2: float = field(default=0.3, metadata=bounds(0.01, 5.0))  # ARIA's TransAccel default
    max_turn_rate_deg_s: float = field(default=300.0, metadata=bounds(1.0, 500.0))
    default_turn_rate_deg_s: float = field(default=60.0, metadata=bounds(1.0, 500.0))
    turn_accel_deg_s2: float = field(default=100.0, metadata=bounds(1.0, 5000.0))
    max_distance_m: float = field(default=20.0, metadata=bounds(0.1, 1000.0))  # one move command
    max_turn_deg: float = field(default=360.0, metadata=bounds(1.0, 3600.0))  # one move command

    def __post_init__(self) -> None:
        if self.default_speed_m_s > self.max_speed_m_s:
            raise ValueError("default_speed_m_s must not exceed max_speed_m_s")
        if self.default_turn_rate_deg_s > self.max_turn_rate_deg_s:
            raise ValueError("default_turn_rate_deg_s must not exceed max_turn_rate_deg_s")

    def drive_time_s(self, distance_m, speed_m_s: float | None = None):
        """Time of a straight drive with a trapezoidal speed profile (a number or an array)."""
        return trapezoid_time_s(np.abs(distance_m), speed_m_s or self.default_speed_m_s, self.accel_m_s2)

    def turn_time_s(self, turn_rad):
        """Time of an in-place rotation at the default turn rate (a number or an array)."""
        return trapezoid_time_s(np.abs(np.degrees(turn_rad)), self.default_turn_rate_deg_s, self.turn_accel_deg_s2)


@dataclass(frozen=True)
class PanTiltLimits:
    """Pan-tilt unit (PTU-D46): position limits and slew speed."""

    pan_min_deg: float = field(default=-159.0, metadata=bounds(-360.0, 0.0))
    pan_max_deg: float = field(default=159.0, metadata=bounds(0.0, 360.0))
    tilt_min_deg: float = field(default=-47.0, metadata=bounds(-90.0, 0.0))
    tilt_max_deg: float = field(default=31.0, metadata=bounds(0.0, 90.0))
    pan_speed_deg_s: float = field(default=60.0, metadata=bounds(1.0, 500.0))
    tilt_speed_deg_s: float = field(default=60.0, metadata=bounds(1.0, 500.0))
    accel_deg_s2: float = field(default=300.0, metadata=bounds(1.0, 5000.0))
    settle_s: float = field(default=0.1, metadata=bounds(0.0, 5.0))  # vibration dies down before capture

    def check(self, pan_deg: float, tilt_deg: float) -> str | None:
        """``None`` if the setting is reachable, else which limit it breaks."""
        if not self.pan_min_deg <= pan_deg <= self.pan_max_deg:
            return f"pan_deg={pan_deg:g} is outside the pan limit [{self.pan_min_deg:g}, {self.pan_max_deg:g}]°"
        if not self.tilt_min_deg <= tilt_deg <= self.tilt_max_deg:
            return (f"tilt_deg={tilt_deg:g} is outside the tilt limit "
                    f"[{self.tilt_min_deg:g}, {self.tilt_max_deg:g}]°")
        return None

    def slew_time_s(self, d_pan_deg, d_tilt_deg):
        """Both axes move at once; the slower one sets the time, plus settling (numbers or arrays)."""
        pan, tilt = np.abs(np.asarray(d_pan_deg, np.float64)), np.abs(np.asarray(d_tilt_deg, np.float64))
        t = np.maximum(trapezoid_time_s(pan, self.pan_speed_deg_s, self.accel_deg_s2),
                       trapezoid_time_s(tilt, self.tilt_speed_deg_s, self.accel_deg_s2)) + self.settle_s
        t = np.where((pan == 0.0) & (tilt == 0.0), 0.0, t)
        return float(t) if t.ndim == 0 else t


@dataclass(frozen=True)
class CameraTiming:
    """Stereo capture timing (Bumblebee2 at 48 fps plus the transfer)."""

    capture_s: float = field(default=0.1, metadata=bounds(0.001, 10.0))  # never 0: a free look is worth ∞ a second


def trapezoid_time_s(distance, top_speed: float, accel: float):
    """Time to cover ``distance`` (a number or an array) from rest to rest with limited speed and
    acceleration."""
    d = np.maximum(np.asarray(distance, np.float64), 0.0)
    ramp = top_speed * top_speed / accel  # distance spent accelerating plus decelerating
    t = np.where(d < ramp, 2.0 * np.sqrt(d / accel), d / top_speed + top_speed / accel)
    t = np.where(d > 0.0, t, 0.0)
    return float(t) if t.ndim == 0 else t

"""Simulated differential-drive base: motion profiles, collisions and drifting odometry.

The true pose moves through the world and stops at contact with a wall or an obstacle (reported as
a stall, like a Pioneer's stall flags). The robot reports its *odometry*, which drifts from the
truth by errors drawn for every motion (see ``OdometryNoise``); the truth is only for tests.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass

import numpy as np

from onboard.config import OdometryNoise
from onboard.devices import BaseReading, MotionOutcome
from onboard.sim.clock import SimClock
from shared.world import World
from shared.geometry import Pose2D, wrap_angle
from shared.limits import BaseLimits


@dataclass(frozen=True)
class Profile:
    """Rest-to-rest trapezoidal (or triangular) profile over a distance or an angle."""

    total: float
    top_speed: float
    accel: float

    @property
    def ramp_time_s(self) -> float:
        return min(self.top_speed / self.accel, math.sqrt(self.total / self.accel))

    @property
    def duration_s(self) -> float:
        t_ramp = self.ramp_time_s
        cruise = self.total - self.accel * t_ramp * t_ramp
        return 2.0 * t_ramp + cruise / (self.accel * t_ramp) if t_ramp > 0 else 0.0

    def at(self, t: float) -> tuple[float, float]:
        """(position, speed) after ``t`` seconds."""
        t_ramp, duration = self.ramp_time_s, self.duration_s
        peak = self.accel * t_ramp
        if t <= 0.0:
            return 0.0, 0.0
        if t >= duration:
            return self.total, 0.0
        if t < t_ramp:
            return 0.5 * self.accel * t * t, self.accel * t
        if t > duration - t_ramp:
            left = duration - t
            return self.total - 0.5 * self.accel * left * left, self.accel * left
        return 0.5 * peak * t_ramp + peak * (t - t_ramp), peak


class SimBase:
    def __init__(self, world: World, limits: BaseLimits, clock: SimClock, noise: OdometryNoise,
                 seed: int = 0, step_s: float = 0.02):
        self.limits = limits
        self._clock = clock
        self._noise = noise
        self._rng = np.random.default_rng(seed)
        self._step_s = step_s
        self._lock = threading.Lock()
        self._halt = threading.Event()
        start = world.start  # a world may say 400°: headings are kept within ±180°, as teleport keeps them
        self._truth = self._odom = Pose2D(start.x_m, start.y_m, wrap_angle(start.heading_rad))
        # the robot is told where it starts; its odometry drifts from there
        self._speed = 0.0
        self._turn_rate = 0.0
        self._moving = False
        self._stalled = False
        self._velocity_errors = (1.0, 1.0, 0.0)  # odometry errors of the current velocity-controlled motion
        room = world.room.size_m
        self._room_xy = (room[0], room[1])
        self._blockers = self._blockers_of(world)

    # --- the Base protocol ---------------------------------------------------------------------------

    def move(self, turn_rad: float, distance_m: float, speed_m_s: float,
             cancel: threading.Event) -> MotionOutcome:
        self._halt.clear()
        scale_d, scale_t, drift = self._draw_odometry_errors()
        with self._lock:
            self._moving, self._stalled = True, False
        try:
            elapsed, status = self._turn(turn_rad, scale_t, cancel)
            driven = 0.0
            if status == "done":
                t, status, driven = self._drive(distance_m, speed_m_s, scale_d, drift, cancel)
                elapsed += t
            return MotionOutcome(status, driven, elapsed)
        finally:
            with self._lock:
                self._moving, self._speed, self._turn_rate = False, 0.0, 0.0

    def stop(self) -> None:
        self._halt.set()

    def reading(self) -> BaseReading:
        with self._lock:
            return BaseReading(self._odom, self._speed, self._turn_rate, self._moving, self._stalled)

    def close(self) -> None:
        self.stop()

    # --- simulation ----------------------------------------------------------------------------------

    @property
    def true_pose(self) -> Pose2D:
        with self._lock:
            return self._truth

    def teleport(self, pose: Pose2D, world: World | None = None) -> str | None:
        """Put the robot at ``pose``, in ``world`` if given (a new run's: its target moved, and the
        base runs into a target on the floor where it is now, not where it was); the reason if it
        cannot stand there (nothing changes then)."""
        blockers = self._blockers if world is None else self._blockers_of(world)
        if self._collides(pose.x_m, pose.y_m, blockers):
            return f"the robot cannot stand at ({pose.x_m:.3f}, {pose.y_m:.3f}): wall or obstacle"
        with self._lock:
            self._truth = self._odom = Pose2D(pose.x_m, pose.y_m, wrap_angle(pose.heading_rad))
            self._stalled = False
            self._blockers = blockers
        return None

    def _blockers_of(self, world: World) -> np.ndarray:
        return np.array([[b.min_m[0], b.min_m[1], b.max_m[0], b.max_m[1]]
                         for b in world.base_blockers(self.limits.height_m)]).reshape(-1, 4)

    def reseed(self, seed: int) -> None:
        """Draw the odometry errors afresh from ``seed`` (a new run repeats whatever came before)."""
        self._rng = np.random.default_rng(seed)

    def collides(self, x_m: float, y_m: float) -> bool:
        """Does the base's footprint disc at (x, y) overlap a wall or a low obstacle?"""
        return self._collides(x_m, y_m, self._blockers)

    def _collides(self, x_m: float, y_m: float, b: np.ndarray) -> bool:
        r = self.limits.radius_m
        if not (r <= x_m <= self._room_xy[0] - r and r <= y_m <= self._room_xy[1] - r):
            return True
        dx = np.maximum(np.maximum(b[:, 0] - x_m, x_m - b[:, 2]), 0.0)
        dy = np.maximum(np.maximum(b[:, 1] - y_m, y_m - b[:, 3]), 0.0)
        return bool(np.any(dx * dx + dy * dy < r * r))

    def step_velocity(self, speed_m_s: float, turn_rate_rad_s: float, dt_s: float) -> bool:
        """One physics step under velocity control, for a byte-level emulator that sets wheel speeds:
        turn, then drive, stopping at contact. Odometry errors are drawn afresh whenever the base
        starts from rest, as for a move. False if the base touched something (a stall)."""
        with self._lock:
            starting = not self._moving
        if starting:
            self._velocity_errors = self._draw_odometry_errors()
        scale_d, scale_t, drift = self._velocity_errors
        self._rotate(turn_rate_rad_s * dt_s, scale_t)
        step = speed_m_s * dt_s
        moved = self._advance_truth(step) if step else 0.0
        blocked = moved < abs(step)
        self._advance_odometry(math.copysign(moved, step), scale_d, drift, 0.0 if blocked else speed_m_s)
        with self._lock:
            self._moving = speed_m_s != 0.0 or turn_rate_rad_s != 0.0
            self._turn_rate, self._stalled = turn_rate_rad_s, blocked
        return not blocked

    def _draw_odometry_errors(self) -> tuple[float, float, float]:
        n = self._noise
        return (1.0 + self._rng.normal(0.0, n.distance_frac),
                1.0 + self._rng.normal(0.0, n.turn_frac),
                math.radians(self._rng.normal(0.0, n.drift_deg_per_m)))

    def _interrupted(self, cancel: threading.Event) -> bool:
        return cancel.is_set() or self._halt.is_set()

    def _turn(self, turn_rad: float, scale: float, cancel: threading.Event) -> tuple[float, str]:
        if turn_rad == 0.0:
            return 0.0, "done"
        sign = math.copysign(1.0, turn_rad)
        profile = Profile(abs(turn_rad), math.radians(self.limits.default_turn_rate_deg_s),
                          math.radians(self.limits.turn_accel_deg_s2))
        t, done_angle = 0.0, 0.0
        while t < profile.duration_s:
            if self._interrupted(cancel):
                return t, "stopped"
            dt = min(self._step_s, profile.duration_s - t)
            if not self._clock.advance(dt, cancel):
                return t, "stopped"
            t += dt
            angle, rate = profile.at(t)
            d_angle = sign * (angle - done_angle)
            done_angle = angle
            self._rotate(d_angle, scale)
            with self._lock:
                self._turn_rate = sign * rate
        return t, "done"

    def _rotate(self, d_angle: float, scale: float) -> None:
        """Turn the truth by ``d_angle`` and the odometry by ``d_angle * scale``."""
        with self._lock:
            self._truth = Pose2D(self._truth.x_m, self._truth.y_m, wrap_angle(self._truth.heading_rad + d_angle))
            self._odom = Pose2D(self._odom.x_m, self._odom.y_m, wrap_angle(self._odom.heading_rad + d_angle * scale))

    def _drive(self, distance_m: float, speed_m_s: float, scale: float, drift_rad_per_m: float,
               cancel: threading.Event) -> tuple[float, str, float]:
        if distance_m == 0.0:
            return 0.0, "done", 0.0
        sign = math.copysign(1.0, distance_m)
        profile = Profile(abs(distance_m), speed_m_s, self.limits.accel_m_s2)
        t, done = 0.0, 0.0
        while t < profile.duration_s:
            if self._interrupted(cancel):
                return t, "stopped", done
            dt = min(self._step_s, profile.duration_s - t)
            if not self._clock.advance(dt, cancel):
                return t, "stopped", done
            t += dt
            position, speed = profile.at(t)
            step = position - done
            moved = self._advance_truth(sign * step)
            self._advance_odometry(sign * moved, scale, drift_rad_per_m, sign * speed)
            done += moved
            if moved < step:
                with self._lock:
                    self._stalled = True
                return t, "stalled", done
        return t, "done", done

    def _advance_truth(self, step_m: float) -> float:
        """Move the true pose by up to ``step_m``; stop at contact. Return the distance moved."""
        pose = self.true_pose
        target = pose.moved(step_m)
        if not self.collides(target.x_m, target.y_m):
            with self._lock:
                self._truth = target
            return abs(step_m)
        lo, hi = 0.0, 1.0  # bisect for the contact point
        for _ in range(12):
            mid = 0.5 * (lo + hi)
            probe = pose.moved(step_m * mid)
            lo, hi = (mid, hi) if not self.collides(probe.x_m, probe.y_m) else (lo, mid)
        with self._lock:
            self._truth = pose.moved(step_m * lo)
        return abs(step_m) * lo

    def _advance_odometry(self, step_m: float, scale: float, drift_rad_per_m: float, speed: float) -> None:
        with self._lock:
            heading = wrap_angle(self._odom.heading_rad + abs(step_m) * drift_rad_per_m)
            self._odom = Pose2D(self._odom.x_m + step_m * scale * math.cos(heading),
                                self._odom.y_m + step_m * scale * math.sin(heading), heading)
            self._speed = speed

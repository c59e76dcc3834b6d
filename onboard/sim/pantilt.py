"""Simulated pan-tilt unit: slews at the PTU-D46's speeds and accelerations, then settles."""

from __future__ import annotations

import math
import threading

from onboard.devices import PanTiltReading
from onboard.sim.clock import SimClock
from shared.limits import PanTiltLimits


class SimPanTilt:
    def __init__(self, limits: PanTiltLimits, clock: SimClock, step_s: float = 0.02):
        self.limits = limits
        self._clock = clock
        self._step_s = step_s
        self._lock = threading.Lock()
        self._halt = threading.Event()
        self._pan = 0.0
        self._tilt = 0.0
        self._moving = False

    def look(self, pan_rad: float, tilt_rad: float, cancel: threading.Event) -> float:
        self._halt.clear()
        start = self.reading()
        d_pan, d_tilt = pan_rad - start.pan_rad, tilt_rad - start.tilt_rad
        duration = self.limits.slew_time_s(math.degrees(d_pan), math.degrees(d_tilt))
        with self._lock:
            self._moving = True
        t = 0.0
        try:
            while t < duration:
                dt = min(self._step_s, duration - t)
                if cancel.is_set() or self._halt.is_set() or not self._clock.advance(dt, cancel):
                    break
                t += dt
                frac = min(t / max(duration - self.limits.settle_s, 1e-9), 1.0)
                with self._lock:  # a straight line in (pan, tilt); the settle time is the tail
                    self._pan = start.pan_rad + frac * d_pan
                    self._tilt = start.tilt_rad + frac * d_tilt
        finally:
            with self._lock:
                self._moving = False
        return t

    def halt(self) -> None:
        self._halt.set()

    def home(self) -> None:
        """Pan 0, tilt 0 at once (the simulator's reset, not a motion)."""
        with self._lock:
            self._pan = self._tilt = 0.0

    def reading(self) -> PanTiltReading:
        with self._lock:
            return PanTiltReading(self._pan, self._tilt, self._moving)

    def close(self) -> None:
        self.halt()

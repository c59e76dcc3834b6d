"""The simulated robot clock.

Every action advances it by the time it would take on the robot. By default it runs as fast as the
machine allows (a 10 s drive takes milliseconds); ``realtime`` paces it with the wall clock, so
that a planner sees the timing of the real robot and a stop can catch a motion halfway.
"""

from __future__ import annotations

import threading
import time


class SimClock:
    def __init__(self, realtime: bool = False):
        self.realtime = realtime
        self._lock = threading.Lock()
        self._elapsed_s = 0.0
        self._wall_start = time.monotonic()

    def now_s(self) -> float:
        if self.realtime:
            return time.monotonic() - self._wall_start
        with self._lock:
            return self._elapsed_s

    def advance(self, dt_s: float, cancel: threading.Event | None = None) -> bool:
        """Let ``dt_s`` of robot time pass; False if ``cancel`` was set meanwhile (realtime only)."""
        if self.realtime:
            if cancel is None:
                time.sleep(dt_s)
                return True
            return not cancel.wait(dt_s)
        with self._lock:
            self._elapsed_s += dt_s
        return True

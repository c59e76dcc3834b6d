"""The serial cable between an emulated device and its host, which a test can cut."""

from __future__ import annotations

import threading


class Cable:
    """Two lines: the device hears the host on one and talks to it on the other.

    ``unplug`` cuts both, or only the device's transmit line (``still_hears``): the failure in which a
    robot still obeys a host that has stopped hearing it. The device runs on either way.
    """

    def __init__(self) -> None:
        self._hears, self._talks = threading.Event(), threading.Event()
        self.plug()

    @property
    def hears(self) -> bool:
        return self._hears.is_set()

    @property
    def talks(self) -> bool:
        return self._talks.is_set()

    def unplug(self, still_hears: bool = False) -> None:
        self._talks.clear()
        if not still_hears:
            self._hears.clear()

    def plug(self) -> None:
        self._hears.set()
        self._talks.set()

"""Injected device faults, so tests can show what the agent does when a driver breaks.

A fault is armed for one device (``sim/fault``) and fires on that device's next operation (a move,
a look, a capture): the operation starts as usual on a thread of its own, and the call raises
:class:`DeviceFault` ``after_s`` of robot time into it, as a driver does when it loses its
controller. The device itself goes on (the wheels keep turning) until someone stops it: making the
robot safe is the agent's job, and a test can see whether it does.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any

from onboard.devices import Clock, DeviceFault, Devices

log = logging.getLogger(__name__)

# the operation of each device that an armed fault breaks
OPERATIONS = {"base": "move", "pantilt": "look", "camera": "capture"}
_POLL_S = 0.002


class FaultInjector:
    """One-shot faults armed per device, and the wrappers through which they fire."""

    def __init__(self, clock: Clock):
        self._clock = clock
        self._lock = threading.Lock()
        self._armed: dict[str, float] = {}

    def arm(self, device: str, after_s: float) -> None:
        if device not in OPERATIONS:
            raise ValueError(f"device must be one of {sorted(OPERATIONS)}, got {device!r}")
        with self._lock:
            self._armed[device] = after_s

    def take(self, device: str) -> float | None:
        """The armed delay of ``device``'s fault, disarming it; None if none is armed."""
        with self._lock:
            return self._armed.pop(device, None)

    def wrap(self, devices: Devices) -> Devices:
        """The same devices, each of whose operation fails when a fault is armed for it."""
        return Devices(devices.backend, devices.clock, _Faulty("base", devices.base, self),
                       _Faulty("pantilt", devices.pantilt, self), _Faulty("camera", devices.camera, self))

    def run_then_fail(self, device: str, operation: Any, after_s: float, args: tuple, kwargs: dict) -> None:
        """Start ``operation`` on its own thread and raise ``after_s`` of robot time later (or once
        it ends, whichever is first), leaving it running."""
        runaway = threading.Thread(target=operation, args=args, kwargs=kwargs, name=f"runaway-{device}", daemon=True)
        deadline = self._clock.now_s() + after_s
        runaway.start()
        time.sleep(_POLL_S)  # let the operation begin: a stop must find it running
        while runaway.is_alive() and self._clock.now_s() < deadline:
            time.sleep(_POLL_S)
        log.warning("injected fault: the %s fails %.3f s into its %s", device, after_s, OPERATIONS[device])
        raise DeviceFault(f"{device}: injected fault {after_s:g} s into the {OPERATIONS[device]} "
                          "(the device was left running)")


class _Faulty:
    """A device whose operation goes through the injector; everything else passes straight on."""

    def __init__(self, name: str, device: Any, faults: FaultInjector):
        self._name = name
        self._device = device
        self._faults = faults

    def __getattr__(self, attr: str) -> Any:
        value = getattr(self._device, attr)
        if attr != OPERATIONS[self._name]:
            return value

        def operation(*args: Any, **kwargs: Any) -> Any:
            after_s = self._faults.take(self._name)
            if after_s is None:
                return value(*args, **kwargs)
            return self._faults.run_then_fail(self._name, value, after_s, args, kwargs)
        return operation

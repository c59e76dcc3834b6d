"""The one error a hardware driver raises when its device cannot serve a request."""

from __future__ import annotations


class DeviceFault(RuntimeError):
    """The device is unreachable or misbehaving (link down, no reply, refused command).

    The agent answers any exception from a device with an ``ErrorReply`` of code ``device``; the
    message says which device and what went wrong.
    """

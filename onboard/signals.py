"""Stopping an onboard program on SIGINT or SIGTERM, whichever of its threads the kernel hands them to.

A process-wide signal may be delivered to any thread that does not block it, and the agent has
dozens: Zenoh's runtime, the device workers. Python runs a handler only in the main thread, when that
thread next runs Python code, and a signal taken on another thread does not wake a main thread asleep
in a lock. So an agent waiting in one endless ``Event.wait()`` went on serving after a SIGTERM sent to
one of Zenoh's threads, and outlived the planner whose death had sent it. The main thread therefore
waits in short slices.
"""

from __future__ import annotations

import signal
import threading

POLL_S = 0.2  # the most a signal taken on another thread waits for its handler


def stop_on_signals() -> threading.Event:
    """An event that SIGINT and SIGTERM set (call from the main thread: only it installs handlers)."""
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    return stop


def wait(stop: threading.Event) -> None:
    """Block until ``stop`` is set, waking every ``POLL_S`` so that pending handlers run."""
    while not stop.wait(POLL_S):
        pass

"""Stopping an onboard program on SIGINT or SIGTERM, whichever of its threads the kernel hands them to.

A process-wide signal may be delivered to any thread that does not block it, and the agent has
dozens: Zenoh's runtime, the device workers. Python runs a handler only in the main thread, when that
thread next runs Python code, and a signal taken on another thread does not wake a main thread asleep
in a lock. So an agent waiting in one endless ``Event.wait()`` went on serving after a SIGTERM sent to
one of Zenoh's threads, and outlived the planner whose death had sent it. The main thread therefore
waits in short slices.

The handler only records the signal; :func:`wait` sets the event. A handler runs between two of the
main thread's bytecodes, which may be inside ``Event.wait`` or ``Event.set`` with the event's lock
held, and that lock is not reentrant: a handler that called ``Event.set`` itself waited there for
itself, and again the agent outlived its planner.
"""

from __future__ import annotations

import logging
import signal
import threading

log = logging.getLogger(__name__)

POLL_S = 0.2  # the most a signal waits for the main thread to act on it

_caught: list[int] = []  # the signals received: the process's, like the handlers


def stop_on_signals() -> threading.Event:
    """An event that :func:`wait` sets once SIGINT or SIGTERM has come (call from the main thread:
    only it installs handlers)."""
    _caught.clear()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _record)
    return threading.Event()


def _record(signum: int, _frame: object) -> None:
    _caught.append(signum)  # takes no lock that the interrupted thread may hold (see the module's docstring)


def wait(stop: threading.Event) -> None:
    """Block until ``stop`` is set, or a signal :func:`stop_on_signals` listens for has come (then
    ``stop`` is set too), looking for one every ``POLL_S``."""
    while not stop.wait(POLL_S):
        if _caught:
            log.info("stopping on %s", signal.Signals(_caught[0]).name)
            stop.set()

"""SIGINT and SIGTERM stop an onboard program wherever they find its main thread.

(That the agent stops when the signal lands on one of its other threads is in ``test_agent.py``.)"""

from __future__ import annotations

import subprocess
import sys
import textwrap

STOPPED_HOLDING_THE_LOCK = textwrap.dedent("""
    import logging, os, signal
    from onboard import signals
    logging.basicConfig(level=logging.INFO)
    stop = signals.stop_on_signals()
    with stop._cond:  # as inside Event.wait or Event.set: CPython's Event holds this lock there
        os.kill(os.getpid(), signal.SIGTERM)  # the handler runs here, before kill returns
    signals.wait(stop)
    print("stopped", flush=True)
""")


def test_a_signal_that_finds_the_main_thread_holding_the_events_lock_still_stops_it():
    done = subprocess.run([sys.executable, "-c", STOPPED_HOLDING_THE_LOCK], capture_output=True, text=True,
                          timeout=10)
    assert (done.returncode, done.stdout) == (0, "stopped\n"), done.stderr
    assert "stopping on SIGTERM" in done.stderr

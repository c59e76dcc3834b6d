"""A simulated robot started for a planner (demo, calibration, experiments, tests) does not outlive it."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap

import pytest
from conftest import wait_until

pytestmark = pytest.mark.integration

PLANNER = textwrap.dedent("""
    import sys, time
    from shared.launch import onboard_agent
    with onboard_agent(["--backend", "sim", "--world", "paper-lab"], None) as agent:
        print(agent.process.pid, flush=True)
        time.sleep(600)
""")


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # a zombie has exited; only its entry waits for a reaper
    with open(f"/proc/{pid}/stat") as stat:
        return stat.read().split(")")[-1].split()[0] != "Z"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the parent-death signal is Linux's")
def test_the_agent_stops_when_its_planner_is_killed_outright():
    planner = subprocess.Popen([sys.executable, "-c", PLANNER], stdout=subprocess.PIPE, text=True)
    agent_pid = int(planner.stdout.readline())
    try:
        assert _alive(agent_pid)
        planner.send_signal(signal.SIGKILL)  # no finally block runs: only the kernel can tell the agent
        planner.wait()
        assert wait_until(lambda: not _alive(agent_pid), 15.0), "the agent outlived its planner"
    finally:
        planner.kill()
        if _alive(agent_pid):  # leave no robot behind, even when the test fails
            os.kill(agent_pid, signal.SIGKILL)

"""A simulated robot started for a planner (demo, calibration, experiments, tests) does not outlive it."""

from __future__ import annotations

import contextlib
import os
import signal
import socket
import subprocess
import sys
import textwrap

import pytest
from conftest import wait_until

from shared.launch import EPHEMERAL_RANGE, LOWEST_PICKED_PORT, free_tcp_port

pytestmark = pytest.mark.integration

PLANNER = textwrap.dedent("""
    import signal, sys, time
    from pathlib import Path
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # as in a shell's background job: the agent inherits it
    from shared.launch import onboard_agent
    from shared.transport import TransportConfig
    with onboard_agent(["--backend", "sim", "--world", "paper-lab"], Path(sys.argv[2])) as agent:
        if sys.argv[1] == "serving":  # else still starting: importing, loading, compiling, no handlers yet
            with TransportConfig(connect=(agent.endpoint,), multicast_scouting=False).open() as session:
                agent.wait_ready(session, "syt")
        print(agent.process.pid, flush=True)
        time.sleep(600)
""")


def _alive(pid: int) -> bool:
    """Running, not a zombie (which has exited; only its entry waits for a reaper) nor gone."""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().split(")")[-1].split()[0] != "Z"
    except FileNotFoundError:
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the parent-death signal is Linux's")
@pytest.mark.parametrize("agent_is", ["starting", "serving"])
def test_the_agent_stops_when_its_planner_is_killed_outright(agent_is, tmp_path):
    agent_log = tmp_path / "agent.log"
    planner = subprocess.Popen([sys.executable, "-c", PLANNER, agent_is, str(agent_log)], stdout=subprocess.PIPE,
                               text=True)
    line = planner.stdout.readline()
    assert line, "the planner did not start its agent"
    agent_pid = int(line)
    try:
        assert _alive(agent_pid)
        planner.send_signal(signal.SIGKILL)  # no finally block runs: only the kernel can tell the agent
        planner.wait()
        assert wait_until(lambda: not _alive(agent_pid), 15.0), \
            f"the agent outlived its planner; its log ends:\n{agent_log.read_text()[-3000:]}"
    finally:
        planner.kill()
        if _alive(agent_pid):  # leave no robot behind, even when the test fails
            with contextlib.suppress(ProcessLookupError):
                os.kill(agent_pid, signal.SIGKILL)


@pytest.mark.skipif(not EPHEMERAL_RANGE.exists(), reason="the ephemeral port range is read from Linux's /proc")
def test_an_agent_port_is_picked_where_outgoing_connections_never_land():
    """A port from the ephemeral range could be taken by any client's connection before the agent
    binds it: CI once lost 14 tests to "Address already in use" that way."""
    low, high = map(int, EPHEMERAL_RANGE.read_text().split())
    ports = {free_tcp_port() for _ in range(20)}
    assert all(LOWEST_PICKED_PORT <= port < low for port in ports), (ports, low, high)
    assert len(ports) > 1  # picked at random, so that two pickers seldom meet
    with socket.socket() as sock:  # and free: it can be bound
        sock.bind(("127.0.0.1", ports.pop()))

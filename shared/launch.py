"""Start an onboard agent as a separate process on a loopback port, and stop it cleanly.

Used by the demo, the benchmarks, the experiments and the tests: the agent is a real ``syt-onboard`` process,
talking to this one over real Zenoh, exactly as on two machines.
"""

from __future__ import annotations

import contextlib
import ctypes
import logging
import os
import random
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import zenoh

from shared.keys import RobotKeys

log = logging.getLogger(__name__)


PR_SET_PDEATHSIG = 1  # prctl(2): the signal the kernel sends a process when its parent dies


def _die_with_parent() -> Callable[[], None] | None:
    """For ``Popen(preexec_fn=...)`` on Linux: the child asks the kernel for SIGTERM when its parent
    dies, however it dies (killed, crashed), so a planner that is gone never leaves its simulated
    robot running. SIGTERM, not SIGINT: the agent shuts down cleanly on either, but a shell that
    starts a job in the background makes its children ignore SIGINT. The C function is looked up
    here, in the parent; the child only calls it before it execs the agent. The kernel reckons the
    parent as the *thread* that started the agent: start one from a thread that lives as long as
    the agent should (every caller here uses its main thread)."""
    if not sys.platform.startswith("linux"):
        return None
    prctl = ctypes.CDLL(None, use_errno=True).prctl
    parent = os.getpid()

    def arm() -> None:
        if prctl(PR_SET_PDEATHSIG, signal.SIGTERM) != 0:
            raise OSError(ctypes.get_errno(), "prctl(PR_SET_PDEATHSIG) failed")  # Popen reports it
        if os.getppid() != parent:  # the parent died before the request was in place
            os._exit(1)

    return arm


EPHEMERAL_RANGE = Path("/proc/sys/net/ipv4/ip_local_port_range")  # Linux: where outgoing ports come from
LOWEST_PICKED_PORT = 10000  # below it sit well-known services' registered ports


def free_tcp_port() -> int:
    """A loopback TCP port free now, for an agent to listen on after this returns.

    Picked below the kernel's ephemeral range: a port from ``bind(0)`` comes from that range, so between
    this check and the agent's bind, any outgoing connection (another test's Zenoh client, say) could
    take it and the agent would die with "Address already in use". Below the range only another
    explicit bind can, and a random pick makes two pickers meeting unlikely."""
    rng = random.SystemRandom()
    ephemeral_low = int(EPHEMERAL_RANGE.read_text().split()[0]) if EPHEMERAL_RANGE.exists() else 0
    for _ in range(100 if ephemeral_low > LOWEST_PICKED_PORT else 0):
        port = rng.randrange(LOWEST_PICKED_PORT, ephemeral_low)
        with socket.socket() as sock, contextlib.suppress(OSError):
            sock.bind(("127.0.0.1", port))
            return port
    with socket.socket() as sock:  # no range known (not Linux), or none free below it
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


@dataclass(frozen=True)
class LoopbackAgent:
    endpoint: str  # what the planner passes to --connect
    process: subprocess.Popen
    log_path: Path | None

    def wait_ready(self, session: zenoh.Session, robot_id: str, timeout_s: float = 300.0) -> None:
        """Wait for the agent's liveliness token; fail at once, with its log, if the process died.
        (Generous: on a fresh checkout the simulator compiles its kernels before it is ready.)"""
        key = RobotKeys(robot_id).agent_alive
        deadline = time.monotonic() + timeout_s
        while not any(r.ok is not None for r in session.liveliness().get(key, timeout=0.5)):
            if self.process.poll() is not None:
                tail = self.log_path.read_text()[-2000:] if self.log_path else "(no log kept)"
                raise RuntimeError(f"the onboard agent exited with {self.process.returncode}:\n{tail}")
            if time.monotonic() > deadline:
                raise TimeoutError(f"the onboard agent did not come up within {timeout_s:g} s")
            time.sleep(0.05)


@contextlib.contextmanager
def onboard_agent(agent_args: list[str], log_path: Path | None = None,
                  protocol: str = "tcp") -> Iterator[LoopbackAgent]:
    """Run ``syt-onboard <agent_args>`` listening on a fresh loopback port (``tls`` with a TLS config), scouting off."""
    endpoint = f"{protocol}/127.0.0.1:{free_tcp_port()}"
    cmd = [sys.executable, "-m", "onboard.cli", *agent_args, "--listen", endpoint, "--no-multicast-scouting"]
    log.info("starting the onboard agent: %s", " ".join(cmd[2:]))
    stderr = open(log_path, "w") if log_path else subprocess.DEVNULL  # noqa: SIM115 - closed below
    process = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=stderr,
                               preexec_fn=_die_with_parent())
    try:
        yield LoopbackAgent(endpoint, process, log_path)
    finally:
        if process.poll() is None:
            process.send_signal(signal.SIGINT)
            try:
                process.wait(timeout=10)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()
        if log_path:
            stderr.close()
        log.info("onboard agent exited with %s", process.returncode)

"""``syt-offboard bench safety --json [--load]``: how fast the robot stops when it loses its planner.

Real processes over Zenoh on loopback: the agent (``syt-onboard --backend sim --realtime``, so robot
time runs with wall time), a planner (:mod:`offboard.bench.safety_actors`: a real RobotClient with
its liveliness token and heartbeats) commanding an 8 m drive at 0.5 m/s, and this process, the
observer. Once the robot cruises, the planner is

- ``kill``: SIGKILLed;
- ``freeze``: SIGSTOPped (killed after the measurement);
- ``link``: cut off: it reaches the agent only through a Zenoh router process (the planner is a
  Zenoh client, so it cannot route around it), and the router is SIGKILLed.

How the stop is observed: the observer polls ``state`` every ``_POLL_S`` on its own session, straight
to the agent (polls are not planner contact: they cannot keep the motion alive). The fault instant
is this process's monotonic clock just before ``kill(2)``. The wall latency runs to the arrival of
the first reply saying the base no longer moves; the robot-time latency runs from the fault instant
mapped onto the robot's clock (the median offset between the robot time in the replies and the
midpoint of their round trips while cruising: the simulator's clock is the same monotonic clock,
so the offset is constant) to the robot time *in* that reply, when the agent read its stopped
state. Both are upper bounds, late by at most one poll (``stop_resolution_ms_max`` says how late).
The distance after the fault is the true pose (``sim/truth``, read just before the fault) to the
true pose after the stop; the simulated base stops at once when told (a Pioneer decelerates).

``--load`` adds the load part: four extra client processes query ``state`` as fast as they can for
10 s while a paper-lab search runs (a fast-clock agent), and again during kill trials; see
:func:`measure_load`.
"""

from __future__ import annotations

import logging
import math
import os
import queue
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import zenoh

from shared import messages as m
from shared.keys import RobotKeys
from shared.launch import LoopbackAgent, free_tcp_port, onboard_agent
from shared.rpc import CommandError, request
from shared.transport import DEFAULT_LEASE_MS, TransportConfig

log = logging.getLogger(__name__)

FAULTS = ("kill", "freeze", "link")
START = (1.0, 1.5, 0.0)  # x, y, heading°: 8 m of open floor ahead
CRUISE_M_S = 0.49  # the fault comes once the base is this fast (0.5 m/s commanded)
HEARTBEAT_PERIOD_S = 0.2  # RobotClient's 5 Hz: the fault falls at a random phase of it
_POLL_S = 0.002
_STOP_TIMEOUT_S = 6.0  # a robot still moving this long after the fault counts as never stopped
# An empty 11 × 4 m room: no obstacle in the way of the drive, the target out of it.
BENCH_WORLD = """
name = "safety-bench"
[room]
size = [11.0, 4.0, 2.5]
[target]
picture = "target"
size = [0.23, 0.23, 0.23]
position = [10.5, 3.5, 0.0]
yaw_deg = 180
[robot]
start = [1.0, 1.5]
heading_deg = 0
"""


@dataclass(frozen=True)
class Trial:
    fault: str
    wall_ms: float  # fault → first reply saying stopped, on this process's clock
    robot_ms: float  # the same, on the robot's clock
    resolution_ms: float  # last "moving" poll sent → first "stopped" reply: how late the stop may be seen
    drift_m: float  # true distance driven after the fault
    stopped: bool


class Actor:
    """One :mod:`offboard.bench.safety_actors` process; it waits, loaded, until :meth:`go`."""

    def __init__(self, role: str, *args: str, lease_ms: int = DEFAULT_LEASE_MS):
        cmd = [sys.executable, "-m", "offboard.bench.safety_actors", "--lease-ms", str(lease_ms), role, *args]
        self.process = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        self._lines: queue.Queue[str] = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.process.stdout:
            self._lines.put(line.strip())
        self._lines.put("")  # end of output

    def expect(self, word: str, timeout_s: float = 30.0) -> str:
        deadline = time.monotonic() + timeout_s
        while (left := deadline - time.monotonic()) > 0:
            try:
                line = self._lines.get(timeout=left)
            except queue.Empty:
                break
            if line.startswith(word):
                return line
            if line == "" and self.process.poll() is not None:
                raise RuntimeError(f"actor {self.process.args[5:]} exited with {self.process.returncode}")
        raise TimeoutError(f"actor {self.process.args[5:]} did not say {word!r} within {timeout_s:g} s")

    def go(self) -> None:
        self.expect("loaded")
        self.process.stdin.write("go\n")
        self.process.stdin.flush()

    def signal(self, sig: int) -> None:
        os.kill(self.process.pid, sig)

    def end(self) -> None:
        if self.process.poll() is None:
            self.process.kill()  # frozen or not
        self.process.wait()


class Observer:
    """This process's own session straight to the agent: polls, truth, teleports."""

    def __init__(self, session: zenoh.Session, robot_id: str = "syt"):
        self.session = session
        self.keys = RobotKeys(robot_id)
        self._n = 0

    def _id(self) -> str:
        self._n += 1
        return f"obs-{self._n}"

    def state(self) -> m.RobotState:
        return request(self.session, self.keys.state, m.StateRequest(self._id()), m.StateReply, 5.0).state

    def truth(self) -> m.PoseMsg:
        return request(self.session, self.keys.sim_truth, m.StateRequest(self._id()), m.SimTruth, 5.0).pose

    def teleport(self, x_m: float, y_m: float, heading_deg: float) -> None:
        """Put the robot back; the base may take a moment to drop the stopped motion."""
        command = m.SimTeleport(self._id(), m.PoseMsg(x_m, y_m, heading_deg))
        deadline = time.monotonic() + 5.0
        while True:
            try:
                request(self.session, self.keys.sim_teleport, command, m.SimTruth, 5.0)
                return
            except CommandError as exc:
                if exc.code != "busy" or time.monotonic() > deadline:
                    raise
                time.sleep(0.02)

    def stop(self) -> None:
        request(self.session, self.keys.stop, m.StopCommand(self._id()), m.StopResult, 5.0)

    def planners(self) -> int:
        """How many planner liveliness tokens the agent's side holds."""
        return sum(r.ok is not None for r in self.session.liveliness().get(self.keys.any_planner_alive, timeout=0.5))

    def wait_no_planner(self, timeout_s: float) -> None:
        deadline = time.monotonic() + timeout_s
        while self.planners():
            if time.monotonic() > deadline:
                raise TimeoutError(f"a planner token outlived its process by {timeout_s:g} s")
            time.sleep(0.02)


def observer_transport(agent: LoopbackAgent) -> TransportConfig:
    return TransportConfig(connect=(agent.endpoint,), multicast_scouting=False)


# --- one trial -------------------------------------------------------------------------------------

def _wait_cruising(observer: Observer) -> float:
    """Poll until the base cruises; the offset robot clock − wall clock (median of the polls)."""
    offsets: list[float] = []
    deadline = time.monotonic() + 15.0
    while time.monotonic() < deadline:
        sent = time.monotonic()
        state = observer.state()
        offsets.append(state.robot_time_s - (sent + time.monotonic()) / 2.0)
        if state.base_moving and state.speed_m_s >= CRUISE_M_S:
            return statistics.median(offsets[-50:])
        time.sleep(_POLL_S)
    raise TimeoutError("the base did not reach cruising speed within 15 s")


def _watch_stop(observer: Observer, fault_s: float, offset_s: float) -> tuple[float, float, float, bool]:
    """Poll until the base stops: (wall ms, robot ms, resolution ms, stopped)."""
    last_sent = fault_s
    while time.monotonic() - fault_s < _STOP_TIMEOUT_S:
        sent = time.monotonic()
        state = observer.state()
        received = time.monotonic()
        if not state.base_moving:
            robot_ms = (state.robot_time_s - (fault_s + offset_s)) * 1000.0
            return (received - fault_s) * 1000.0, robot_ms, (received - last_sent) * 1000.0, True
        last_sent = sent
        time.sleep(_POLL_S)
    return _STOP_TIMEOUT_S * 1000.0, _STOP_TIMEOUT_S * 1000.0, 0.0, False


def run_trial(observer: Observer, agent: LoopbackAgent, fault: str, lease_ms: int,
              rng: np.random.Generator) -> Trial:
    """Drive, inject ``fault``, measure the stop; leave no actor behind."""
    observer.teleport(*START)
    actors: list[Actor] = []
    try:
        endpoint, mode = agent.endpoint, "peer"
        if fault == "link":  # the planner, a client, reaches the agent only through this router
            endpoint, mode = f"tcp/127.0.0.1:{free_tcp_port()}", "client"
            actors.append(Actor("router", endpoint, agent.endpoint, lease_ms=lease_ms))
            actors[-1].go()
            actors[-1].expect("ready")
        actors.append(Actor("planner", endpoint, "--mode", mode, lease_ms=lease_ms))
        actors[-1].go()
        actors[-1].expect("moving")
        offset_s = _wait_cruising(observer)
        time.sleep(rng.uniform(0.0, HEARTBEAT_PERIOD_S))
        victim = actors[0]  # the router if there is one, else the planner
        before = observer.truth()
        fault_s = time.monotonic()
        victim.signal(signal.SIGSTOP if fault == "freeze" else signal.SIGKILL)
        wall_ms, robot_ms, resolution_ms, stopped = _watch_stop(observer, fault_s, offset_s)
        if not stopped:
            log.error("%s: the base was still moving %.0f s after the fault", fault, _STOP_TIMEOUT_S)
            observer.stop()
        time.sleep(0.2)
        after = observer.truth()
        drift_m = math.hypot(after.x_m - before.x_m, after.y_m - before.y_m)
    finally:
        for actor in actors:
            actor.end()
    observer.wait_no_planner(lease_ms / 1000.0 + 5.0)
    log.info("%s: stopped after %.0f ms (robot %.0f ms, ±%.0f), %.3f m", fault, wall_ms, robot_ms,
             resolution_ms, drift_m)
    return Trial(fault, wall_ms, robot_ms, resolution_ms, drift_m, stopped)


# --- the bench -------------------------------------------------------------------------------------

def _percentiles(trials: list[Trial], fault: str) -> dict:
    wall = [t.wall_ms for t in trials if t.fault == fault]
    robot = [t.robot_ms for t in trials if t.fault == fault]
    return {
        f"{fault}_stop_ms_p50": round(float(np.median(wall)), 1),
        f"{fault}_stop_ms_max": round(max(wall), 1),
        f"{fault}_stop_robot_ms_p50": round(float(np.median(robot)), 1),
        f"{fault}_stop_robot_ms_max": round(max(robot), 1),
        f"{fault}_trials": len(wall),
        f"{fault}_never_stopped": sum(not t.stopped for t in trials if t.fault == fault),
    }


def summarize(trials: list[Trial], lease_ms: int, watchdog_ms: int) -> dict:
    result: dict = {}
    for fault in FAULTS:
        if any(t.fault == fault for t in trials):
            result |= _percentiles(trials, fault)
    return result | {
        "lease_ms": lease_ms,
        "watchdog_ms": watchdog_ms,
        "drift_after_fault_m_max": round(max(t.drift_m for t in trials), 3),
        "stop_resolution_ms_max": round(max(t.resolution_ms for t in trials), 1),
        "drive_speed_m_s": 0.5,
    }


def run_trials(agent: LoopbackAgent, trials: int, lease_ms: int, faults: tuple[str, ...] = FAULTS) -> list[Trial]:
    with observer_transport(agent).open() as session:
        agent.wait_ready(session, "syt")
        observer, rng = Observer(session), np.random.default_rng(0)
        return [run_trial(observer, agent, fault, lease_ms, rng) for fault in faults for _ in range(trials)]


def realtime_agent(stack: ExitStack, tmp: Path, lease_ms: int) -> LoopbackAgent:
    world = tmp / "safety-bench.toml"
    world.write_text(BENCH_WORLD)
    return stack.enter_context(onboard_agent(
        ["--backend", "sim", "--realtime", "--world", str(world), "--lease-ms", str(lease_ms)], tmp / "onboard.log"))


def run(trials: int = 20, lease_ms: int = DEFAULT_LEASE_MS, load: bool = False) -> dict:
    """The bench's JSON object (see the module docstring)."""
    with tempfile.TemporaryDirectory() as tmp, ExitStack() as stack:
        agent = realtime_agent(stack, Path(tmp), lease_ms)
        result = summarize(run_trials(agent, trials, lease_ms), lease_ms, watchdog_ms(agent))
        if load:
            from offboard.bench.load import measure_load

            result |= measure_load(agent, Path(tmp), lease_ms, result["kill_stop_ms_p50"])
    return result


def watchdog_ms(agent: LoopbackAgent) -> int:
    """The agent's watchdog, as its ``info`` reply states it."""
    with observer_transport(agent).open() as session:
        return request(session, RobotKeys("syt").info, m.InfoRequest("bench-info"), m.Info, 5.0).watchdog_ms

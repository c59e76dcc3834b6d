"""The load part of ``syt-offboard bench safety --json --load``: four extra client processes
(:mod:`offboard.bench.safety_actors` ``load``) query ``state`` as fast as they can for 10 s.

- **Decisions.** A paper-lab search (``syt-offboard search`` against a fast-clock agent) runs
  ``UNLOADED_RUNS`` times alone, then once under load; every run starts from the same ``sim/reset``
  (start, target, noise seed), so they take the same decisions. Each decision's ``planning_ms``
  comes from the search's recording (``stats/planning_ms`` on the ``action`` timeline; it includes
  the ``state`` query a decision makes). ``load_decision_ms_max_ratio``: the largest, over the
  decisions made while the load ran, of its time under load over its median alone.
- **Odometry.** This process subscribes to ``odometry`` during each load and measures the gaps
  between arrivals (published at 10 Hz: 100 ms when all is well).
- **Stop.** Kill trials (as in :mod:`offboard.bench.safety`) on the real-time agent, the same four
  clients on it for ``STOP_LOAD_S`` (long enough for several trials: one can be unlucky).
"""

from __future__ import annotations

import json
import logging
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import zenoh
from rerun.chunk import RrdReader

from offboard.bench.safety import Actor, Observer, observer_transport, run_trial
from offboard.experiments.world_facts import load_facts
from shared import messages as m
from shared.launch import LoopbackAgent, onboard_agent
from shared.rpc import request

log = logging.getLogger(__name__)

CLIENTS = 4
LOAD_S = 10.0
STOP_LOAD_S = 30.0
UNLOADED_RUNS = 3
TRIAL_S = 4.0  # a kill trial starts only with this much load left: its fault comes ~2.5 s in
WORLD = "paper-lab"


class Load:
    """``CLIENTS`` state hammers on one agent for ``seconds``, and the odometry gaps seen meanwhile."""

    def __init__(self, agent: LoopbackAgent, session: zenoh.Session, observer: Observer, seconds: float):
        self.seconds = seconds
        self._clients = [Actor("load", agent.endpoint, str(seconds)) for _ in range(CLIENTS)]
        self._arrivals: list[float] = []
        self._subscriber = session.declare_subscriber(
            observer.keys.odometry, lambda _: self._arrivals.append(time.monotonic()))
        for client in self._clients:
            client.go()
        for client in self._clients:
            client.expect("ready")
        self.started_s, self.started_unix_s = time.monotonic(), time.time()

    def left_s(self) -> float:
        return self.seconds - (time.monotonic() - self.started_s)

    def finish(self) -> dict:
        """Wait for the clients; their totals and the odometry gaps."""
        reports = [json.loads(client.expect("{", self.seconds + 30.0)) for client in self._clients]
        for client in self._clients:
            client.end()
        self._subscriber.undeclare()
        # while the load ran only: finish() may come long after it (the search it loaded runs on)
        during = [t for t in self._arrivals if self.started_s <= t <= self.started_s + self.seconds]
        gaps = np.diff(during) * 1000.0 if len(during) > 1 else np.array([np.inf])
        return {"qps": sum(r["replies"] for r in reports) / self.seconds, "errors": sum(r["errors"] for r in reports),
                "odometry_gap_ms_max": float(gaps.max()), "odometry_samples": len(during)}


def decision_times(rrd: Path, since_unix_s: float = 0.0, until_unix_s: float = float("inf")) -> dict[int, float]:
    """planning_ms by action number, of the decisions recorded between the two instants."""
    times = {}
    for chunk in RrdReader(rrd).stream():
        if chunk.entity_path != "/stats/planning_ms":
            continue
        batch = chunk.to_record_batch()
        logged = batch.column("log_time").cast("int64").to_pylist()
        for action, ms, ns in zip(batch.column("action").to_pylist(), batch.column("Scalars:scalars").to_pylist(),
                                  logged):
            if since_unix_s <= ns / 1e9 <= until_unix_s:
                times[action] = ms[0]
    return times


def _search(agent: LoopbackAgent, observer: Observer, picture: Path, out: Path) -> Path:
    """One search from the world's own start, target and seed 0; the path of its recording."""
    facts = load_facts(WORLD)
    request(observer.session, observer.keys.sim_reset,
            m.SimReset("bench-reset", m.PoseMsg(*facts.start), facts.target[:3], facts.target[3], 0), m.SimTruth, 30.0)
    done = subprocess.run(
        [sys.executable, "-m", "offboard.cli", "search", "--connect", agent.endpoint, "--no-multicast-scouting",
         "--target-picture", str(picture), "--target-size", ",".join(map(str, facts.target_size_m)),
         "--target-sides", str(facts.target_sides), "--room", ",".join(map(str, facts.room_m)), "--out", str(out)],
        capture_output=True, text=True, timeout=600, check=False)
    if done.returncode not in (0, 3):  # 3: searched, not found
        raise RuntimeError(f"the search failed:\n{done.stderr[-2000:]}")
    return out / "search.rrd"


def measure_decisions(tmp: Path) -> dict:
    picture = tmp / "target.png"
    subprocess.run([sys.executable, "-m", "onboard.cli", "picture", "target", "--out", str(picture)], check=True,
                   capture_output=True)
    with onboard_agent(["--backend", "sim", "--world", WORLD], tmp / "onboard-search.log") as agent, \
            observer_transport(agent).open() as session:
        agent.wait_ready(session, "syt")
        observer = Observer(session)
        alone = [decision_times(_search(agent, observer, picture, tmp / f"alone-{i}")) for i in range(UNLOADED_RUNS)]
        load = Load(agent, session, observer, LOAD_S)
        started = time.monotonic()
        rrd = _search(agent, observer, picture, tmp / "loaded")
        search_s = time.monotonic() - started
        totals = load.finish()
    loaded = decision_times(rrd, load.started_unix_s, load.started_unix_s + LOAD_S)
    alone_ms = {a: float(np.median([run[a] for run in alone if a in run])) for a in loaded
                if any(a in run for run in alone)}
    ratios = [loaded[a] / ms for a, ms in alone_ms.items()]
    if not ratios:
        raise RuntimeError(f"no decision of the loaded search fell within the {LOAD_S:g} s of load "
                           f"(its recording: {rrd}): nothing to compare")
    return {
        "load_state_qps": round(totals["qps"], 1),
        "load_state_errors": totals["errors"],
        "load_decision_ms_max_ratio": round(max(ratios), 2),
        "load_decisions_compared": len(ratios),
        "load_decision_ms_median_alone": round(float(np.median(list(alone_ms.values()))), 1),  # the same decisions
        "load_decision_ms_median_loaded": round(float(np.median([loaded[a] for a in alone_ms])), 1),
        "load_search_wall_s": round(search_s, 1),
        "load_odometry_gap_ms_max_search": round(totals["odometry_gap_ms_max"], 1),
    }


def measure_stop(agent: LoopbackAgent, lease_ms: int) -> dict:
    """Kill trials on the real-time agent while the clients hammer it."""
    with observer_transport(agent).open() as session:
        observer, rng = Observer(session), np.random.default_rng(1)
        load = Load(agent, session, observer, STOP_LOAD_S)
        trials = []
        while load.left_s() > TRIAL_S or not trials:
            trials.append(run_trial(observer, agent, "kill", lease_ms, rng))
        totals = load.finish()
    return {
        "load_kill_stop_ms": round(max(t.wall_ms for t in trials), 1),
        "load_kill_stop_ms_p50": round(float(np.median([t.wall_ms for t in trials])), 1),
        "load_kill_stop_robot_ms": round(max(t.robot_ms for t in trials), 1),
        "load_kill_trials": len(trials),
        "load_kill_never_stopped": sum(not t.stopped for t in trials),
        "load_odometry_gap_ms_max_realtime": round(totals["odometry_gap_ms_max"], 1),
        "load_state_qps_realtime": round(totals["qps"], 1),
    }


def measure_load(agent: LoopbackAgent, tmp: Path, lease_ms: int, unloaded_kill_ms_p50: float) -> dict:
    """The load keys of the bench (``unloaded_kill_ms_p50`` is kept beside them for comparison)."""
    result = measure_stop(agent, lease_ms) | measure_decisions(tmp)
    gaps = (result["load_odometry_gap_ms_max_search"], result["load_odometry_gap_ms_max_realtime"])
    return result | {"load_odometry_gap_ms_max": max(gaps), "unloaded_kill_stop_ms_p50": unloaded_kill_ms_p50}

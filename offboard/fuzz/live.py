"""Live fuzz: malformed and out-of-limit queries to a running agent, then checks that it still serves.

Every query goes to one of the agent's queryables with a payload the codec must refuse (the message
cases of :mod:`shared.fuzz_targets` that must be refused, and no payload at all) or a well-formed
command outside the device limits. Each must be answered with an ``ErrorReply`` of code
``protocol`` (whose message names the broken field) or ``limit``: silence, a success, another code
or a crash is a failure. Queries are kept a few in flight, well under the agent's command queue,
so ``busy`` never legitimately happens. Afterwards the agent must still answer ``state``, the
robot must not have moved, and odometry must still arrive at 10 Hz (measured over 2 s, and over
2 s before the fuzz too, to tell a loaded machine from a degraded agent).
"""

from __future__ import annotations

import collections
import itertools
import logging
import threading
import time
from dataclasses import dataclass, field
from typing import Any

import zenoh

from shared import messages as m
from shared.codec import ProtocolError, decode, encode
from shared.fuzz_targets import message_cases
from shared.fuzzing import Case, for_each_generated, names_field
from shared.keys import RobotKeys
from shared.rpc import request

log = logging.getLogger(__name__)

# The agent's queryables (shared.keys) and the request type each decodes.
QUERYABLES = {"move": "MoveCommand", "stop": "StopCommand", "look": "LookCommand", "capture": "CaptureCommand",
              "state": "StateRequest", "info": "InfoRequest", "sim_truth": "StateRequest",
              "sim_teleport": "SimTeleport", "sim_reset": "SimReset", "sim_fault": "SimFault"}
IN_FLIGHT = 16  # far below the agent's queue of 64: a full queue would answer "busy"
REPLY_TIMEOUT_S = 10.0
ODOMETRY_WINDOW_S = 2.0
ODOMETRY_HZ = 10.0  # the agent's default publish_hz
EXAMPLES_KEPT = 5

@dataclass(frozen=True)
class LiveQuery:
    queryable: str  # a RobotKeys property: "move", "sim_reset"...
    payload: bytes | None
    code: str  # the ErrorReply code it must get
    case: Case


@dataclass
class LiveReport:
    queries: int = 0
    seconds: float = 0.0
    queries_per_s: float = 0.0
    by_code: dict[str, int] = field(default_factory=dict)
    failures: int = 0
    examples: list[str] = field(default_factory=list)
    odometry_max_gap_ms: float | None = None  # during the fuzz
    state_after_ok: bool = False
    pose_unchanged: bool = False
    odometry_hz_before: float = 0.0
    odometry_hz_after: float = 0.0
    agent_alive: bool | None = None  # known when this process started the agent
    agent_tracebacks: int | None = None  # in its log

    @property
    def ok(self) -> bool:
        return (self.failures == 0 and self.state_after_ok and self.pose_unchanged
                and self.odometry_hz_after >= 0.9 * ODOMETRY_HZ
                and self.agent_alive is not False and not self.agent_tracebacks)

    def fail(self, text: str) -> None:
        self.failures += 1
        if len(self.examples) < EXAMPLES_KEPT:
            self.examples.append(text)


def live_queries(count: int, info: m.Info) -> list[LiveQuery]:
    """``count`` queries: malformed payloads for every queryable, and commands outside ``info``'s limits."""
    from hypothesis import strategies as st

    leaves = [q for q in QUERYABLES if info.backend == "sim" or not q.startswith("sim_")]
    refused = {leaf: message_cases(QUERYABLES[leaf]).filter(lambda c: c.must_refuse) for leaf in leaves}
    empty = Case(None, None, True, "no payload")
    limits = _beyond_limits(info, leaves)

    @st.composite
    def queries(draw: st.DrawFn) -> LiveQuery:  # 8 in 10 malformed, 1 empty, 1 outside the limits
        branch, leaf = draw(st.integers(0, 9)), draw(st.sampled_from(leaves))
        if branch < 8:
            return LiveQuery(leaf, (case := draw(refused[leaf])).data, "protocol", case)
        if branch == 8:
            return LiveQuery(leaf, None, "protocol", empty)
        leaf, command = draw(limits)
        return LiveQuery(leaf, encode(command), "limit", Case(command, None, True, f"outside the limits: {command}"))

    found: list[LiveQuery] = []
    for_each_generated(queries(), count, found.append)
    return found[:count]


def _beyond_limits(info: m.Info, leaves: list[str]):
    """Well-formed commands just or far outside the agent's own limits (never one it would carry out)."""
    from hypothesis import strategies as st

    def beyond(limit: float, end: float) -> list:  # from the limit (excluded) to the wire's bound
        if limit == end:
            return []
        lo, hi = sorted((limit, end))
        return [st.floats(lo, hi, exclude_min=lo == limit, exclude_max=hi == limit)]
    pt, base = info.pantilt, info.base
    looks = [*(b.map(lambda p: m.LookCommand("limit", p, 0.0))
               for b in beyond(pt.pan_max_deg, 360.0) + beyond(pt.pan_min_deg, -360.0)),
             *(b.map(lambda t: m.LookCommand("limit", 0.0, t))
               for b in beyond(pt.tilt_max_deg, 90.0) + beyond(pt.tilt_min_deg, -90.0))]
    moves = [*(b.map(lambda d: m.MoveCommand("limit", turn_deg=d)) for b in beyond(base.max_turn_deg, 3600.0)),
             *(b.map(lambda d: m.MoveCommand("limit", distance_m=d)) for b in beyond(base.max_distance_m, 1000.0)),
             *(b.map(lambda v: m.MoveCommand("limit", distance_m=0.5, speed_m_s=v))
               for b in beyond(base.max_speed_m_s, 10.0))]
    outside = st.floats(-1.0e4, -1.0)  # every room spans [0, size]: a negative x is outside any
    sims = [outside.map(lambda x: m.SimTeleport("limit", m.PoseMsg(x, 1.0, 0.0))),
            outside.map(lambda x: m.SimReset("limit", m.PoseMsg(1.0, 1.0, 0.0), (x, 1.0, 0.5), 0.0))]
    commands = [c.map(lambda cmd, leaf=leaf: (leaf, cmd)) for leaf, group in
                (("look", looks), ("move", moves), ("sim_teleport", sims[:1]), ("sim_reset", sims[1:]))
                if leaf in leaves for c in group]
    return st.one_of(*commands)


class _OdometryWatch:
    """Arrival times of the agent's odometry, from a subscriber that never blocks."""

    def __init__(self, session: zenoh.Session, keys: RobotKeys):
        self.times: list[float] = []
        self._lock = threading.Lock()
        self._sub = session.declare_subscriber(keys.odometry, self._on_sample)

    def _on_sample(self, sample: zenoh.Sample) -> None:
        with self._lock:
            self.times.append(time.monotonic())

    def max_gap_ms(self, since: float) -> float | None:
        """The longest wait between two samples since ``since`` (None: fewer than two came)."""
        with self._lock:
            times = [t for t in self.times if t >= since]
        gaps = [b - a for a, b in itertools.pairwise(times)]
        return round(max(gaps) * 1000.0, 1) if gaps else None

    def rate_hz(self, window_s: float) -> float:
        start = time.monotonic()
        time.sleep(window_s)
        with self._lock:
            return sum(1 for t in self.times if start <= t < start + window_s) / window_s

    def close(self) -> None:
        self._sub.undeclare()


def run_live(session: zenoh.Session, robot_id: str, count: int) -> LiveReport:
    """Send ``count`` bad queries to the agent of ``robot_id``, then check that it still serves."""
    keys, report = RobotKeys(robot_id), LiveReport()
    info = request(session, keys.info, m.InfoRequest("fuzz-info"), m.Info, 5.0)
    queries = live_queries(count, info)
    before = request(session, keys.state, m.StateRequest("fuzz-before"), m.StateReply, 5.0).state.pose
    watch = _OdometryWatch(session, keys)
    try:
        report.odometry_hz_before = round(watch.rate_hz(ODOMETRY_WINDOW_S), 2)  # what the machine allows
        started = time.monotonic()
        pending: collections.deque = collections.deque()
        for query in queries:
            key = getattr(keys, query.queryable)
            pending.append((query, session.get(key, payload=query.payload, timeout=REPLY_TIMEOUT_S)))
            if len(pending) >= IN_FLIGHT:
                _judge(*pending.popleft(), report)
        while pending:
            _judge(*pending.popleft(), report)
        report.seconds = round(time.monotonic() - started, 2)
        report.queries = len(queries)
        report.queries_per_s = round(report.queries / max(report.seconds, 1e-9), 1)
        report.odometry_max_gap_ms = watch.max_gap_ms(started)
        after = request(session, keys.state, m.StateRequest("fuzz-after"), m.StateReply, 5.0).state.pose
        report.state_after_ok = True
        report.pose_unchanged = (after.x_m, after.y_m, after.heading_deg) == (before.x_m, before.y_m, before.heading_deg)
        report.odometry_hz_after = round(watch.rate_hz(ODOMETRY_WINDOW_S), 2)
    finally:
        watch.close()
    return report


def _judge(query: LiveQuery, replies: Any, report: LiveReport) -> None:
    """One query's replies: exactly one ErrorReply of the expected code, naming the field."""
    where = f"{query.queryable}: {query.case.how}"
    answers = list(replies)
    if len(answers) != 1:
        report.fail(f"{where}: {len(answers)} replies")
        return
    if answers[0].err is None:
        report.fail(f"{where}: accepted (an ok reply)")
        return
    try:
        error = decode(answers[0].err.payload.to_bytes(), m.ErrorReply)
    except ProtocolError as exc:  # not the agent's answer: Zenoh's own, such as a timeout
        report.fail(f"{where}: no ErrorReply ({answers[0].err.payload.to_bytes()[:100]!r}: {exc})")
        return
    report.by_code[error.code] = report.by_code.get(error.code, 0) + 1
    if error.code != query.code:
        report.fail(f"{where}: code {error.code}, not {query.code}: {error.message}")
    elif query.code == "protocol" and not names_field(ValueError(error.message), query.case):
        report.fail(f"{where}: the message does not name {query.case.field!r}: {error.message}")

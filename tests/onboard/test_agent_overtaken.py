"""A stop overtakes the motions queued before it: the agent runs in this process, so that its
dispatcher can be held while commands queue up (between real processes the queue could not be
filled reliably)."""

from __future__ import annotations

import contextlib
import dataclasses
import math
import threading
import time
from collections.abc import Iterator

import pytest
from conftest import wait_until

from onboard.agent import Agent
from onboard.backends import build_robot
from onboard.config import OnboardConfig, SimConfig
from onboard.sim.world import load_world
from shared import messages as m
from shared.codec import decode, encode
from shared.keys import RobotKeys
from shared.launch import free_tcp_port
from shared.rpc import RobotUnavailable, request
from shared.transport import TransportConfig

pytestmark = pytest.mark.integration

@dataclasses.dataclass
class HeldAgent:
    """An agent in this process, its dispatcher held by the state request "hold" until ``release``."""

    agent: Agent
    base: object
    keys: RobotKeys
    session: object  # a client session that sends no heartbeat
    held: threading.Event
    release: threading.Event


@contextlib.contextmanager
def held_agent(robot_id: str, config: OnboardConfig = OnboardConfig()) -> Iterator[HeldAgent]:
    robot = build_robot(config, load_world("paper-lab", robot_radius_m=config.base.radius_m))
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    stop, held, release = threading.Event(), threading.Event(), threading.Event()
    with TransportConfig(listen=(endpoint,), multicast_scouting=False).open() as agent_session:
        agent = Agent(config, robot.devices, agent_session, robot_id, sim=robot.sim)
        on_state = agent._on_state

        def slow_first_state(query, cmd):  # a device read that hangs: the dispatcher waits with it
            if cmd.command_id == "hold":
                held.set()
                assert release.wait(10.0)
            on_state(query, cmd)
        agent._on_state = slow_first_state
        runner = threading.Thread(target=agent.run, args=(stop,))
        runner.start()
        try:
            with TransportConfig(robot_id=robot_id, connect=(endpoint,), multicast_scouting=False).open() as session:
                keys = RobotKeys(robot_id)
                assert wait_until(lambda: _answers(session, keys), 10.0), "the agent never answered"
                yield HeldAgent(agent, robot.devices.base, keys, session, held, release)
        finally:
            release.set()
            stop.set()
            runner.join(timeout=10.0)


@pytest.mark.parametrize("queue_full", [False, True], ids=["stop-queued", "stop-finds-the-queue-full"])
def test_a_motion_queued_before_a_stop_is_not_started(queue_full):
    """A move and a look wait behind a slow state request; a stop follows them. Until session 56 the
    dispatcher started them in their turn: the stop, once dispatched, cut the move short, and one that
    found the queue full (answered busy) stopped nothing that came after its early stop, so the
    queued move drove its whole way."""
    with held_agent("overtaken") as h:
        agent, base, keys, session = h.agent, h.base, h.keys, h.session
        before = base.true_pose
        ask = lambda key, command: session.get(key, payload=encode(command), timeout=10.0)
        hold = ask(keys.state, m.StateRequest("hold"))
        assert h.held.wait(5.0)
        move = ask(keys.move, m.MoveCommand("queued-move", distance_m=0.5))
        look = ask(keys.look, m.LookCommand("queued-look", pan_deg=40.0, tilt_deg=10.0))
        fillers = [ask(keys.state, m.StateRequest(f"f{i}")) for i in range(agent._commands.maxsize - 2 if queue_full else 3)]
        assert wait_until(lambda: agent._commands.qsize() == 2 + len(fillers), 5.0)  # all in, in order
        stopped = ask(keys.stop, m.StopCommand("stop"))
        if queue_full:
            stop_reply = next(iter(stopped))  # answered at once: no room for it
        else:
            assert wait_until(lambda: agent._commands.qsize() == 3 + len(fillers), 5.0)  # the stop is in
        h.release.set()
        move_reply, look_reply = next(iter(move)), next(iter(look))
        if not queue_full:
            stop_reply = next(iter(stopped))
        for handler in [hold, *fillers]:
            list(handler)
    if queue_full:
        assert decode(stop_reply.err.payload.to_bytes(), m.ErrorReply).code == "busy"
    else:
        assert decode(stop_reply.ok.payload.to_bytes(), m.StopResult).command_id == "stop"
    moved = decode(move_reply.ok.payload.to_bytes(), m.MoveResult)
    looked = decode(look_reply.ok.payload.to_bytes(), m.LookResult)
    assert (moved.status, moved.distance_m) == ("stopped", 0.0)
    assert (looked.pan_deg, looked.tilt_deg) == (0.0, 0.0)  # the head still where it started
    after = base.true_pose
    assert math.hypot(after.x_m - before.x_m, after.y_m - before.y_m) < 1e-9


def test_a_move_that_waited_in_the_queue_is_timed_by_the_watchdog_from_when_it_came():
    """The dispatcher took a command's arrival to be when it took the command up: a move that waited
    (behind a stop's wait for the base, up to 2 s) from a planner silent since gave that planner a
    whole watchdog period more to drive in."""
    config = dataclasses.replace(OnboardConfig(), sim=SimConfig(realtime=True))
    with held_agent("waited", config) as h:  # its client sends no heartbeat: silent from its move on
        before = h.base.true_pose
        hold = h.session.get(h.keys.state, payload=encode(m.StateRequest("hold")), timeout=10.0)
        assert h.held.wait(5.0)
        move = h.session.get(h.keys.move, payload=encode(m.MoveCommand("waited", distance_m=2.0)), timeout=10.0)
        assert wait_until(lambda: h.agent._commands.qsize() == 1, 5.0)
        time.sleep(config.watchdog_ms / 1000.0 + 0.4)  # past the watchdog's period while it waits
        h.release.set()
        moved = decode(next(iter(move)).ok.payload.to_bytes(), m.MoveResult)
        list(hold)
    assert moved.status == "stopped"
    after = h.base.true_pose
    assert math.hypot(after.x_m - before.x_m, after.y_m - before.y_m) < 0.03  # a watchdog period on: ~0.1 m


def _answers(session, keys: RobotKeys) -> bool:
    """Whether the agent's routes are up (a query sent before them reaches nobody)."""
    try:
        request(session, keys.info, m.InfoRequest("ready"), m.Info, 2.0)
    except RobotUnavailable:
        return False
    return True

"""The agent closing while a move is on its way in: the agent runs in this process, so that the one
interleaving that matters can be forced (between real processes it could not be set up reliably)."""

from __future__ import annotations

import itertools
import math
import threading
import time

import pytest
from conftest import wait_until

from onboard.agent import Agent
from onboard.backends import build_robot
from onboard.config import OnboardConfig
from onboard.sim.world import load_world
from shared import messages as m
from shared.keys import RobotKeys
from shared.launch import free_tcp_port
from shared.rpc import CommandError, RobotUnavailable, request
from shared.transport import TransportConfig

pytestmark = pytest.mark.integration


def test_a_move_that_reaches_the_agent_as_it_closes_does_not_drive():
    """A move that had passed the dispatcher's shutdown check when the agent began to close got a
    fresh cancel flag after closing had cancelled the old ones, and drove. Here the move is resolved
    only once closing has begun, and the devices close only once the move has started."""
    config = OnboardConfig()
    robot = build_robot(config, load_world("paper-lab", robot_radius_m=config.base.radius_m))
    base = robot.devices.base
    cancelled_at_start: list[bool] = []
    drive, close = base.move, robot.devices.close

    def recorded_move(turn_rad, distance_m, speed_m_s, cancel):
        cancelled_at_start.append(cancel.is_set())
        return drive(turn_rad, distance_m, speed_m_s, cancel)

    def close_once_the_move_started() -> None:
        wait_until(lambda: cancelled_at_start, 5.0)
        close()
    base.move, robot.devices.close = recorded_move, close_once_the_move_started

    endpoint, stop, reached = f"tcp/127.0.0.1:{free_tcp_port()}", threading.Event(), threading.Event()
    with TransportConfig(listen=(endpoint,), multicast_scouting=False).open() as agent_session:
        agent = Agent(config, robot.devices, agent_session, "closing", sim=robot.sim)
        resolve = agent._resolve_motion

        def resolved_as_the_agent_closes(cmd):
            reached.set()
            stop.set()  # the agent begins to close, with this move already past the dispatcher's check
            assert agent._shutdown.wait(5.0)
            return resolve(cmd)
        agent._resolve_motion = resolved_as_the_agent_closes
        before = base.true_pose
        runner = threading.Thread(target=agent.run, args=(stop,))
        runner.start()
        try:
            _send_moves_until(reached, endpoint)
        finally:
            stop.set()
            runner.join(timeout=10.0)
    assert cancelled_at_start == [True]
    after = base.true_pose
    assert math.hypot(after.x_m - before.x_m, after.y_m - before.y_m) < 1e-9 and after.heading_rad == before.heading_rad


def _send_moves_until(reached: threading.Event, endpoint: str) -> None:
    """Moves of 0.5 m, until one reaches the agent (those sent before its routes exist reach nobody)."""
    ids = (f"c{i}" for i in itertools.count())
    keys = RobotKeys("closing")
    with TransportConfig(robot_id="closing", connect=(endpoint,), multicast_scouting=False).open() as session:
        deadline = time.monotonic() + 10.0
        while not reached.is_set() and time.monotonic() < deadline:
            try:
                request(session, keys.move, m.MoveCommand(next(ids), distance_m=0.5), m.MoveResult, 2.0)
            except (RobotUnavailable, CommandError):  # not there yet, or gone once it closed
                time.sleep(0.05)
    assert reached.is_set(), "no move reached the agent"

"""A reading out of any message's range (an odometry glitch, say): the agent names it to the planner
instead of sending what the planner would refuse, and keeps serving. The agent runs in this process so
that its base can be made to read such a value."""

from __future__ import annotations

import dataclasses
import threading
import time

import pytest
from conftest import wait_until

from onboard.agent import Agent
from onboard.backends import build_robot
from onboard.config import OnboardConfig
from onboard.sim.world import load_world
from shared import messages as m
from shared.codec import decode
from shared.geometry import Pose2D
from shared.keys import RobotKeys
from shared.launch import free_tcp_port
from shared.rpc import CommandError, request
from shared.transport import TransportConfig

pytestmark = pytest.mark.integration


def test_a_reading_out_of_range_is_named_in_an_error_reply_and_not_published():
    config = OnboardConfig()
    robot = build_robot(config, load_world("paper-lab", robot_radius_m=config.base.radius_m))
    base, keys = robot.devices.base, RobotKeys("glitch")
    real_reading, glitch = base.reading, threading.Event()
    base.reading = lambda: (dataclasses.replace(real_reading(), pose=Pose2D(2.0e4, 1.0, 0.0)) if glitch.is_set()
                            else real_reading())
    endpoint = f"tcp/127.0.0.1:{free_tcp_port()}"
    stop, odometry = threading.Event(), []
    with TransportConfig(listen=(endpoint,), multicast_scouting=False).open() as agent_session:
        agent = Agent(config, robot.devices, agent_session, "glitch", sim=robot.sim)
        runner = threading.Thread(target=agent.run, args=(stop,))
        runner.start()
        try:
            with TransportConfig(robot_id="glitch", connect=(endpoint,), multicast_scouting=False).open() as session:
                session.declare_subscriber(keys.odometry, lambda s: odometry.append(s.payload.to_bytes()))
                assert wait_until(lambda: len(odometry) >= 2, 10.0), "no odometry before the glitch"
                glitch.set()
                with pytest.raises(CommandError) as err:
                    request(session, keys.state, m.StateRequest("s1"), m.StateReply, 5.0)
                assert err.value.reply.code == "device" and "pose.x_m" in err.value.reply.message
                time.sleep(0.3)  # the publisher's next ticks
                published = len(odometry)
                time.sleep(0.5)  # five ticks at 10 Hz, none sent
                assert len(odometry) == published
                glitch.clear()
                assert wait_until(lambda: len(odometry) > published, 5.0), "odometry did not come back"
                reply = request(session, keys.state, m.StateRequest("s2"), m.StateReply, 5.0)
                assert reply.state.pose.x_m < 100.0
                assert decode(odometry[-1], m.Odometry).pose.x_m < 100.0
        finally:
            stop.set()
            runner.join(timeout=10.0)

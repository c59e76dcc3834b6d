"""``syt-onboard bench --json``: rendering and round trips over Zenoh on loopback, as medians;
``--backend hardware``: the Pioneer driver's command and stop latencies to the wire and its SIP
parsing, over the emulator (or a real robot's port).

The round trips go to a real agent subprocess, so they include Zenoh, msgpack, the agent's
dispatch and (for captures) rendering: what a planner on the same machine would wait for.
"""

from __future__ import annotations

import json
import logging
import uuid

from onboard.config import OnboardConfig
from onboard.sim.render import StereoRenderer
from onboard.sim.world import load_world
from shared import messages as m
from shared.timing import median_ms
from shared.geometry import Pose2D
from shared.keys import RobotKeys
from shared.launch import onboard_agent
from shared.rpc import request
from shared.transport import TransportConfig

log = logging.getLogger(__name__)


def _render_ms(config: OnboardConfig, repeats: int) -> float:
    world = load_world("paper-lab")
    renderer = StereoRenderer(world, config.camera.intrinsics(), config.camera.mount())
    poses = [Pose2D(x, y, h) for x, y, h in ((4.5, 0.6, 1.57), (2.0, 2.0, 0.0), (7.0, 3.0, 3.0), (4.0, 2.5, -1.0))]
    counter = iter(range(10**9))
    return median_ms(lambda: renderer.render(poses[next(counter) % len(poses)], 0.0, 0.0), repeats)


def _roundtrips_ms(repeats: int) -> dict[str, float]:
    keys = RobotKeys("bench")
    with onboard_agent(["--backend", "sim", "--world", "paper-lab", "--robot", "bench"]) as agent:
        transport = TransportConfig(robot_id="bench", connect=(agent.endpoint,), multicast_scouting=False)
        with transport.open() as session:
            agent.wait_ready(session, "bench")

            def ask(key: str, command, expected):
                return lambda: request(session, key, command(uuid.uuid4().hex[:8]), expected, 10.0)
            return {
                "capture_roundtrip_ms": median_ms(ask(keys.capture, m.CaptureCommand, m.Capture), repeats),
                "state_roundtrip_ms": median_ms(ask(keys.state, m.StateRequest, m.StateReply), repeats * 10),
            }


def run_hardware(port: str | None = None, moves: int = 10) -> str:
    """The Pioneer driver's figures (``onboard.hardware.bench``) on ``port``, or over the emulated robot
    of ``syt-onboard emulate`` in paper-lab when no port is given."""
    from onboard.emulators.robot import EmulatedRobot
    from onboard.hardware import bench as pioneer_bench

    config = OnboardConfig()
    if port is not None:
        return json.dumps(pioneer_bench.run(port, config.base, moves))
    with EmulatedRobot(config, load_world("paper-lab"), "paper-lab") as emulated:
        figures = pioneer_bench.run(emulated.ports()["base"], config.base, moves)
    return json.dumps(figures | {"port": "emulator"})


def run(repeats: int = 30) -> str:
    config = OnboardConfig()
    log.info("rendering %d stereo pairs", repeats)
    figures = {"render_ms": _render_ms(config, repeats)}
    log.info("round trips to an agent subprocess over loopback")
    figures.update(_roundtrips_ms(repeats))
    figures.update({"repeats": repeats, "image": f"{config.camera.width_px}x{config.camera.height_px}"})
    return json.dumps(figures)

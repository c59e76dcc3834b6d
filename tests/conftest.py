"""Shared fixtures: real onboard agents in subprocesses, real Zenoh sessions on loopback."""

from __future__ import annotations

import contextlib
import dataclasses
import math
import time
from collections.abc import Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest

from shared.launch import LoopbackAgent, onboard_agent
from offboard.perception.detection import TargetModel, make_detector
from offboard.perception.occupancy import FloorMap
from offboard.perception.voxel_grid import VoxelGrid
from offboard.planning import priors
from offboard.robot.robot_client import RobotClient
from offboard.search import checkpoint
from offboard.search.loop import Search, SearchConfig
from offboard.search.run import detectability_table
from onboard.sim.textures import load_picture
from shared.transport import TransportConfig

RES = 0.05  # the floor maps' cell size in the navigation tests


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The long tests first (a stable sort keeps the rest in order): the workers, handed tests a few at
    a time (``make test``'s ``--maxschedchunk 1``), then share them from the start, instead of one
    running a whole search alone at the end while the others wait."""
    items.sort(key=lambda item: item.get_closest_marker("long") is None)


def wait_until(predicate, timeout_s: float, poll_s: float = 0.02) -> bool:
    """Poll ``predicate`` until it holds (True) or ``timeout_s`` has passed (False)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(poll_s)
    return False


def bundled_picture(folder: Path, name: str = "target.png") -> Path:
    """The bundled target's picture written as a file, as a user gives one (``syt-onboard picture``)."""
    import subprocess
    import sys

    path = folder / name
    subprocess.run([sys.executable, "-m", "onboard.cli", "picture", "target", "--out", str(path)], check=True,
                   capture_output=True)
    return path


def experiment_args(*argv: str):
    """``syt-offboard experiment``'s arguments as its command line parses them."""
    import argparse

    from offboard.experiments import harness

    parser = argparse.ArgumentParser()
    harness.add_arguments(parser)
    return parser.parse_args(list(argv))


def client_transport(agent: LoopbackAgent, robot_id: str = "syt") -> TransportConfig:
    return TransportConfig(robot_id=robot_id, connect=(agent.endpoint,), multicast_scouting=False)


@contextlib.contextmanager
def running_agent(tmp_path: Path, *args: str) -> Iterator[tuple[LoopbackAgent, RobotClient]]:
    """An agent subprocess plus a connected client; the agent's log is kept for assertions."""
    log_path = tmp_path / "onboard.log"
    with onboard_agent(["--backend", "sim", *args], log_path) as agent:
        transport = client_transport(agent)
        with transport.open() as session, RobotClient(session, transport.robot_id) as robot:
            agent.wait_ready(session, transport.robot_id)
            robot.wait_for_robot()
            yield agent, robot


BOX_WORLD = """
name = "box-room"
[room]
size = [6.0, 4.0, 2.5]
[[obstacle]]
name = "crate"
kind = "crate"
min = [2.5, 2.5, 0.0]
max = [3.5, 4.0, 0.8]
[target]
picture = "target"
size = [0.23, 0.23, 0.23]
position = [3.0, 3.2, 0.8]
yaw_deg = -90
[robot]
start = [1.5, 1.5]
heading_deg = 0
"""


@pytest.fixture
def box_world(tmp_path) -> Path:
    """A 6 × 4 m room with one crate (x 2.5-3.5, y 2.5-4) that tests can reason about exactly."""
    path = tmp_path / "box-room.toml"
    path.write_text(BOX_WORLD)
    return path


@pytest.fixture(scope="module")
def sim_agent(tmp_path_factory) -> Iterator[tuple[LoopbackAgent, RobotClient]]:
    """One fast-clock paper-lab agent shared by a module's tests."""
    with running_agent(tmp_path_factory.mktemp("agent"), "--world", "paper-lab") as pair:
        yield pair


def search_on(robot: RobotClient, dynamic: list | None = None, config: SearchConfig | None = None) -> Search:
    """A search in this process on ``robot``: the bundled target, SIFT, a uniform prior, the
    ``dynamic`` priors (none by default), and ``config`` (by default the defaults with a planned
    processing time, so that its decisions repeat however loaded the machine is)."""
    config = config or SearchConfig(planned_processing_s=0.45)
    model = TargetModel((load_picture("target", Path(".")),), (0.23, 0.23, 0.23))
    detector = make_detector("sift", model, robot.info().intrinsics.to_intrinsics())
    return Search(robot, config, {"sift": (detector, detectability_table("sift", detector, {}))},
                  priors.uniform(VoxelGrid(config.room_m, config.resolution_m)), dynamic or [])


def saved_and_read(folder: Path, search: Search) -> checkpoint.Checkpoint:
    """``search``'s checkpoint, written to ``folder`` and read back (no request or transport: a search
    built afresh in the test takes it)."""
    header, arrays = checkpoint.capture(search)
    header.update(request={}, transport={}, config=dataclasses.asdict(search.config), wall_time_s=0.0)
    checkpoint.write_file(folder / checkpoint.FILE_NAME, header, arrays)
    return checkpoint.read(folder)


@pytest.fixture
def lab_search(sim_agent) -> Search:
    """:func:`search_on` the paper-lab agent."""
    return search_on(sim_agent[1])


def floor_map(occupied: np.ndarray, radius_m: float = 0.0) -> FloorMap:
    """Inflate like OccupancyGrid.floor_map (walls included) by ``radius_m``."""
    r = int(math.ceil(radius_m / RES))
    if r == 0:
        return FloorMap(RES, occupied, occupied.copy(), np.zeros_like(occupied))
    disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    padded = np.pad(occupied, r, constant_values=True).astype(np.uint8)
    blocked = cv2.dilate(padded, disc)[r:-r, r:-r].astype(bool)
    return FloorMap(RES, occupied, blocked, np.zeros_like(occupied))

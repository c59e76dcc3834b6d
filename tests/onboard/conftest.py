"""Fixtures of the onboard tests: a small room with a simulated base for the emulators to move."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import pytest

from onboard.config import OdometryNoise
from onboard.sim.base import SimBase
from onboard.sim.clock import SimClock
from shared.geometry import Pose2D
from shared.limits import BaseLimits
from shared.world import load_world

# A 6 × 4 m room, the robot at (1.5, 1.5) facing +x: the east wall is 4.5 m ahead minus its radius.
EMPTY_ROOM = """
name = "emulator-room"
[room]
size = [6.0, 4.0, 2.5]
[target]
picture = "target"
size = [0.23, 0.23, 0.23]
position = [3.0, 3.8, 0.0]
yaw_deg = -90
[robot]
start = [1.5, 1.5]
heading_deg = 0
"""


@pytest.fixture
def room_base(tmp_path: Path) -> Callable[..., SimBase]:
    """Make a simulated base in the empty room, without odometry noise, optionally elsewhere."""
    path = tmp_path / "room.toml"
    path.write_text(EMPTY_ROOM)

    def make(start: Pose2D | None = None) -> SimBase:
        base = SimBase(load_world(path), BaseLimits(), SimClock(), OdometryNoise(0.0, 0.0, 0.0))
        if start is not None:
            assert base.teleport(start) is None
        return base
    return make

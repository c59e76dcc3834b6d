"""``syt-offboard tour`` against a real agent: a command the robot refuses is named, not a traceback."""

from __future__ import annotations

import pytest
from conftest import running_agent

from offboard.cli import main

pytestmark = pytest.mark.integration


def test_a_tour_whose_look_the_robot_refuses_exits_1_naming_the_limit(tmp_path, caplog):
    config = tmp_path / "onboard.toml"
    config.write_text("[pantilt]\ntilt_max_deg = 20.0\n")  # the tour looks up at 30°
    with running_agent(tmp_path, "--world", "paper-lab", "--config", str(config)) as (agent, _):
        code = main(["tour", "--out", str(tmp_path / "tour"), "--connect", agent.endpoint,
                     "--no-multicast-scouting"])
    assert code == 1
    assert "the robot: " in caplog.text and "limit: tilt_deg=30 is outside the tilt limit" in caplog.text

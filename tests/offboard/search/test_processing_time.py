"""A look's processing time, as the planner's t(f) and the report count it, holds all of the look's
work: here, the dynamic priors' update after it (it once fell outside the clock); and the search's,
the planning that no look followed."""

from __future__ import annotations

import math
import time

import pytest

from conftest import running_agent, search_on
from offboard.planning.planner import Decision

pytestmark = pytest.mark.integration

PRIOR_S = 2.0  # a dynamic prior's update that takes this long (saliency's takes about 0.15 s): longer than a
# look's own processing (0.3-0.7 s in CI, 1.1 s on a machine loaded five times over), so a look that counts
# it is told from one that does not by its own time, not by chance


def test_a_look_s_processing_counts_the_dynamic_priors_update(sim_agent):
    slow_from_look = 3  # the first two looks warm the caches up

    def prior(obs, search) -> None:  # a factor of None leaves the belief as it is
        if search.state.actions >= slow_from_look:
            time.sleep(PRIOR_S)

    search = search_on(sim_agent[1], [prior])
    for setting, azimuth_deg in enumerate((90, 60, 120)):
        search._look(Decision("look", "level", azimuth_rad=math.radians(azimuth_deg), tilt_rad=0.0, setting=setting))
    looks = [look["processing_s"] for look in search.state.look_log]
    assert sum(looks) == pytest.approx(search.state.processing_s, abs=1e-3)
    assert looks[1] < PRIOR_S <= looks[2], looks  # counted in the look that ran it, and only there


def test_the_planning_of_the_decision_to_stop_is_counted(sim_agent):
    search = search_on(sim_agent[1])

    class SlowToStop:  # a policy that deliberates, then gives up
        def decide(self, *args, **kwargs) -> Decision:
            time.sleep(PRIOR_S)
            return Decision("stop", "nothing worth a look", status="exhausted")

    search.policy = SlowToStop()
    search._plans_positions = False  # no widening: the stop stands
    state = search.run()
    assert state.status == "exhausted" and state.actions == 0
    assert state.processing_s >= 0.9 * PRIOR_S * len(state.planning_ms), (state.processing_s, state.planning_ms)


def test_on_a_wall_clock_processing_is_robot_time_and_not_counted_twice(tmp_path):
    """On hardware (or a paced simulator) the robot's clock runs on while the planner processes: the
    budget added the processing to robot time that already held it, and motion counted the capture's
    transfer twice."""
    with running_agent(tmp_path, "--world", "paper-lab", "--realtime") as (_, robot):
        assert robot.info().wall_clock

        def prior(obs, search) -> None:
            if search.state.actions >= 2:
                time.sleep(PRIOR_S)

        search = search_on(robot, [prior])
        for setting, azimuth_deg in enumerate((90, 60)):
            search._look(Decision("look", "level", azimuth_rad=math.radians(azimuth_deg), tilt_rad=0.0, setting=setting))
        robot_s, state = search.robot_time_s(), search.state
        assert state.processing_s > PRIOR_S and search.elapsed_s() == pytest.approx(robot_s, abs=0.05)
        assert state.motion_s + state.processing_s == pytest.approx(robot_s, abs=0.5)  # not robot_s + processing


def test_a_fast_simulators_clock_counts_actions_only(sim_agent):
    search = search_on(sim_agent[1])
    assert not sim_agent[1].info().wall_clock
    search._look(Decision("look", "level", azimuth_rad=math.radians(90), tilt_rad=0.0, setting=0))
    assert search.elapsed_s() == pytest.approx(search.robot_time_s() + search.state.processing_s, abs=1e-3)

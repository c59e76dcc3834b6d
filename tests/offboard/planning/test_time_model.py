"""t(f): the time model's looks and travel, against hand-worked trapezoids of the default limits."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from offboard.planning.time_model import TimeModel
from shared.limits import BaseLimits, CameraTiming, PanTiltLimits

TIME = TimeModel(BaseLimits(), PanTiltLimits(), CameraTiming())  # image_s: 0.1 capture + 0.5 processing


def test_a_look_that_moves_nothing_takes_the_image_time():
    assert TIME.look(0.3, 0.0, 0.0, 0.3, 0.0).time_s == pytest.approx(0.6)


def test_a_pan_is_slewed_in_degrees():
    # 90° at 60°/s after a 12° ramp: 1.5 + 0.2 s, settling 0.1 s, the image 0.6 s (in radians: 0.8 s)
    plan = TIME.look(0.0, 0.0, 0.0, math.pi / 2, 0.0)
    assert (plan.base_turn_rad, plan.pan_rad) == (0.0, pytest.approx(math.pi / 2))
    assert plan.time_s == pytest.approx(2.4)


def test_an_azimuth_beyond_the_pan_limit_turns_the_base_the_rest():
    # pan to the 159° limit and turn 11°: the turn's ramp is 36°, so 2·sqrt(11 / 100) s
    plan = TIME.look(0.0, math.radians(159.0), 0.0, math.radians(170.0), 0.0)
    assert plan.pan_rad == pytest.approx(math.radians(159.0))
    assert plan.base_turn_rad == pytest.approx(math.radians(11.0))
    assert plan.time_s == pytest.approx(2 * math.sqrt(0.11) + 0.6)


@pytest.mark.parametrize("azimuth", [math.pi, -math.pi, 0.3, -2.9])
def test_a_look_is_timed_as_the_planner_times_it(azimuth):
    """One pointing rule for both, right behind the robot too, where the old look() turned the other way."""
    settings = np.array([azimuth, 1.0])
    times = TIME.look_times_s(0.0, 0.5, 0.0, settings, np.zeros(2))
    assert TIME.look(0.0, 0.5, 0.0, azimuth, 0.0).time_s == times[0]


def test_the_tilt_slew_is_priced():
    # 30° tilt: 0.5 + 0.2 s, settling 0.1 s
    times = TIME.look_times_s(0.0, 0.0, 0.0, np.zeros(2), np.radians([0.0, 30.0]))
    np.testing.assert_allclose(times, [0.6, 1.4])


def test_travel_includes_the_turn_towards_the_path():
    # 180° at 60°/s after a 36° ramp: 3 + 0.6 s
    assert TIME.travel_s(0.0, math.pi) == pytest.approx(3.6)
    assert TIME.travel_s(np.array([0.0, np.inf]), 0.0).tolist() == [0.0, math.inf]


@pytest.mark.parametrize("field", ["processing_s", "drive_s_per_m"])
@pytest.mark.parametrize("value", [-0.5, math.nan, math.inf])
def test_a_time_that_is_negative_or_not_finite_is_refused(field, value):
    with pytest.raises(ValueError, match=field):
        replace(TIME, **{field: value})


@pytest.mark.parametrize("length", [-1.0, math.nan, np.array([2.0, -0.1]), -math.inf])
def test_a_path_length_that_is_negative_or_nan_is_refused(length):
    for model in (TIME, replace(TIME, drive_s_per_m=10.0)):
        with pytest.raises(ValueError, match="path_length_m"):
            model.travel_s(length, 0.0)

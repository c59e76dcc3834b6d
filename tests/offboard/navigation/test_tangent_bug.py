"""TangentBug on hand-built floor maps: reaches reachable goals, gives up on unreachable ones in bounded
steps, and never proposes a move through blocked cells."""

from __future__ import annotations

import math

import numpy as np
import pytest

from offboard.navigation.grid_planner import (distance_field, distances_at, is_free, path_length_m, segment_is_free,
                                   shortest_path)
from offboard.navigation.tangent_bug import BugConfig, TangentBug, d_reach, tangent_endpoints, virtual_scan
from conftest import floor_map

RADIUS = 0.26
MAX_STEPS = 400


def room(nx: int = 160, ny: int = 120) -> np.ndarray:
    return np.zeros((nx, ny), bool)


def u_shape() -> np.ndarray:
    """An 8 × 6 m room with a U (2 m deep, 3 m wide) opening toward -x in the middle."""
    occupied = room()
    occupied[60:100, 30:34] = occupied[60:100, 86:90] = True  # arms at y 1.5 and 4.3
    occupied[96:100, 30:90] = True  # the bottom at x = 4.8-5.0
    return occupied


def drive(fmap, start, goal, cost=None, config=BugConfig(), memoryless=False):
    """Execute every proposed move exactly; return the final step, the distance and the visited points.
    ``memoryless``: reset the bug before every step, as the navigator does with a navigation function."""
    bug = TangentBug(goal, config)
    x, travelled, visited = start, 0.0, [start]
    for _ in range(MAX_STEPS):
        if memoryless:
            bug.retarget(goal)
        step = bug.step(fmap, x, cost)
        if step.status != "move":
            return step, travelled, visited
        assert step.mode == "escape" or segment_is_free(fmap, x, step.waypoint), f"blocked move {x} -> {step}"
        travelled += math.dist(x, step.waypoint)
        x = step.waypoint
        visited.append(x)
    pytest.fail(f"no verdict in {MAX_STEPS} steps (at {x}, mode {bug.mode})")


def test_virtual_scan_measures_the_distance_to_blocked_cells():
    occupied = room(100, 100)
    occupied[60:, :] = True  # a wall face at x = 3.0
    scan = virtual_scan(floor_map(occupied), (1.0, 2.5), 360, 3.0)
    assert scan.ranges[0] == pytest.approx(2.0, abs=0.01) and scan.hit[0]
    assert scan.ranges[30] == pytest.approx(2.0 / math.cos(math.radians(30)), abs=0.03)
    assert scan.ranges[90] == pytest.approx(2.5, abs=0.01) and scan.hit[90]  # the room's edge
    assert scan.ranges[180] == pytest.approx(1.0, abs=0.01)


def test_tangent_endpoints_flank_an_obstacle_in_the_way():
    occupied = room(100, 100)
    occupied[50:54, 40:60] = True  # a 1 m wide post across the way, 1.5 m ahead
    scan = virtual_scan(floor_map(occupied), (1.0, 2.5), 360, 3.0)
    ends = tangent_endpoints(scan, jump_m=0.4, clearance_m=0.1)
    near_post = [e for e in ends if 2.4 < e[0] < 2.8]
    assert {e[1] > 2.5 for e in near_post} == {True, False}  # one on each side
    assert all(e[1] > 3.0 or e[1] < 2.0 for e in near_post)  # past the post's edges
    # behind the post the closest free sight is where the rays grazing its corners end, 3 m out
    grazing = math.atan2(0.5, 1.5)
    end = (1.0 + 3.0 * math.cos(grazing), 2.5 + 3.0 * math.sin(grazing))
    assert d_reach(scan, (5.0, 2.5)) == pytest.approx(math.dist(end, (5.0, 2.5)), abs=0.1)


def test_straight_to_a_goal_in_sight():
    fmap = floor_map(room(), RADIUS)
    step, travelled, _ = drive(fmap, (1.0, 1.0), (6.0, 4.0))
    assert step.status == "reached"
    assert travelled == pytest.approx(math.dist((1.0, 1.0), (6.0, 4.0)))


def test_escapes_the_u_shape_and_reaches_the_goal_behind_it():
    fmap = floor_map(u_shape(), RADIUS)
    step, travelled, _ = drive(fmap, (1.0, 3.0), (6.5, 3.0))
    assert step.status == "reached"
    assert travelled < 4 * path_length_m(shortest_path(fmap, (1.0, 3.0), (6.5, 3.0)))


def test_with_path_lengths_as_heuristic_it_drives_near_shortest_paths():
    fmap = floor_map(u_shape(), RADIUS)
    start, goal = (1.0, 3.0), (6.5, 3.0)
    field = distance_field(fmap, goal)
    step, travelled, _ = drive(fmap, start, goal, lambda p: distances_at(fmap, field, p), memoryless=True)
    assert step.status == "reached"
    assert travelled < 1.3 * path_length_m(shortest_path(fmap, start, goal))


def test_corridor():
    occupied = room()
    occupied[20:140, 44:48] = occupied[20:140, 72:76] = True  # a 1.2 m corridor along y = 3.0
    occupied[136:140, 48:72] = True  # closed at its east end
    fmap = floor_map(occupied, RADIUS)
    step, _, visited = drive(fmap, (2.0, 3.0), (7.5, 3.0))  # out of the corridor, round, in behind
    assert step.status == "reached"
    assert min(x for x, _ in visited) < 1.0  # it left through the open west end, x = 1.0
    step, _, _ = drive(fmap, (0.5, 3.0), (6.0, 3.0))  # along it
    assert step.status == "reached"


@pytest.mark.parametrize("seed", range(6))
def test_clutter_reachable_goals_are_reached(seed):
    rng = np.random.default_rng(seed)
    occupied = room()
    for x, y in rng.integers(5, 110, size=(14, 2)):
        w, h = rng.integers(4, 16, size=2)
        occupied[x + 20:x + 20 + w, y:y + h] = True
    fmap = floor_map(occupied, RADIUS)
    free = np.argwhere(~fmap.blocked)
    start = tuple((free[rng.integers(len(free))] + 0.5) * 0.05)
    field = distance_field(fmap, start)
    reachable = free[np.isfinite(field[free[:, 0], free[:, 1]])]
    goal = tuple((reachable[rng.integers(len(reachable))] + 0.5) * 0.05)
    step, _, _ = drive(fmap, start, goal)
    assert step.status == "reached", step.reason


def test_enclosed_goal_is_unreachable_in_bounded_steps():
    occupied = u_shape()
    occupied[120:124, 10:110] = occupied[146:150, 10:110] = True  # a closed pen round the goal
    occupied[120:150, 10:14] = occupied[120:150, 106:110] = True
    fmap = floor_map(occupied, RADIUS)
    step, travelled, _ = drive(fmap, (1.0, 3.0), (6.75, 3.0))
    assert step.status == "unreachable" and "loop" in step.reason
    assert travelled < BugConfig().max_follow_m + 30.0


def test_goal_inside_an_obstacle_is_unreachable():
    fmap = floor_map(u_shape(), RADIUS)
    goal = (4.9, 1.6)
    assert not is_free(fmap, goal)
    step, _, _ = drive(fmap, (1.0, 3.0), goal)
    assert step.status == "unreachable"


def test_a_blocked_goal_straight_along_a_scan_ray_is_unreachable_not_endless():
    """The ray at 0° passes through the goal (on the map's edge, blocked), so the closest free point
    in sight is 0 m from it: once taken for "the goal is in sight", leaving and following called each
    other until Python's recursion limit."""
    fmap = floor_map(np.zeros((40, 40), bool))
    goal = (2.0, 1.025)
    assert not is_free(fmap, goal)
    step, _, _ = drive(fmap, (1.025, 1.025), goal)
    assert step.status == "unreachable"


def test_following_is_bounded_by_max_follow():
    fmap = floor_map(u_shape(), RADIUS)
    step, travelled, _ = drive(fmap, (1.0, 3.0), (4.9, 1.6), config=BugConfig(max_follow_m=3.0, loop_radius_m=0.01))
    assert step.status == "unreachable" and "3 m" in step.reason


def test_a_robot_standing_in_blocked_space_escapes_to_free_space():
    fmap = floor_map(u_shape(), RADIUS)
    step = TangentBug((1.0, 1.0)).step(fmap, (3.5, 1.6))
    assert step.mode == "escape" and is_free(fmap, step.waypoint)
    assert math.dist(step.waypoint, (3.5, 1.6)) < 0.5

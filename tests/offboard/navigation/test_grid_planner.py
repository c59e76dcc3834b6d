"""Global planner on hand-built floor maps: exact distances, collision-free smoothed paths, speed."""

from __future__ import annotations

import math
import time

import cv2
import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from offboard.navigation.grid_planner import (any_angle_field, distance_field, nearest_free_cell, path_length_m,
                                              path_lengths, segment_is_free, shortest_path)
from offboard.perception.occupancy import FloorMap
from conftest import RES, floor_map



def wall_map() -> FloorMap:
    """A 9 × 5 m room with a wall across x = 4.5 m from y = 0 to 3.5 m (gap above)."""
    occupied = np.zeros((180, 100), bool)
    occupied[88:92, :70] = True
    return floor_map(occupied)


def test_distance_field_is_octile_distance_in_the_open():
    field = distance_field(floor_map(np.zeros((40, 30), bool)), (0.025, 0.025))
    i, j = np.meshgrid(np.arange(40), np.arange(30), indexing="ij")
    octile = (np.maximum(i, j) + (math.sqrt(2) - 1) * np.minimum(i, j)) * RES
    assert np.allclose(field, octile)


def test_distance_field_goes_round_walls_and_marks_enclosures_unreachable():
    occupied = np.zeros((180, 100), bool)
    occupied[88:92, :70] = True
    occupied[150:170, 60:62] = occupied[150:170, 80:82] = True  # a closed pen
    occupied[150:152, 60:82] = occupied[168:170, 60:82] = True
    fmap = floor_map(occupied)
    behind, pen, outside = path_lengths(fmap, (1.0, 1.0), np.array([[8.0, 1.0], [8.0, 3.5], [-1.0, 1.0]]))
    detour = math.dist((1.0, 1.0), (4.5, 3.5)) + math.dist((4.5, 3.5), (8.0, 1.0))
    assert detour <= behind <= detour * 1.09  # 8-connected paths are at most ~8 % long
    assert pen == math.inf and outside == math.inf


def test_the_any_angle_field_is_the_straight_distance_in_the_open():
    """SPL's yardstick: the 8-connected field reads a line 22.5° off an axis 8 % long."""
    start = (0.51, 0.32)
    field = any_angle_field(floor_map(np.zeros((120, 90), bool)), start)
    x, y = (np.indices((120, 90)) + 0.5) * RES
    assert np.allclose(field, np.hypot(x - start[0], y - start[1]), rtol=0, atol=1e-9)


def test_the_any_angle_field_goes_round_walls_as_straightened_paths_do():
    fmap = wall_map()
    field, grid = any_angle_field(fmap, (1.0, 1.0)), distance_field(fmap, (1.0, 1.0))
    assert np.array_equal(np.isfinite(field), np.isfinite(grid))  # the same cells reachable
    assert np.all(field[np.isfinite(grid)] <= grid[np.isfinite(grid)] + 1e-9)
    behind = field[int(8.0 / RES), int(1.0 / RES)]
    detour = math.dist((1.0, 1.0), (4.5, 3.5)) + math.dist((4.5, 3.5), (8.025, 1.025))
    assert detour <= behind <= detour * 1.01  # bends at cell centres beside the wall's end
    assert behind <= path_length_m(shortest_path(fmap, (1.0, 1.0), (8.025, 1.025))) + 1e-9
    blocked_start = any_angle_field(fmap, (4.5, 1.0))  # inside the wall: hops out first, as the grid field does
    assert np.array_equal(np.isfinite(blocked_start), np.isfinite(distance_field(fmap, (4.5, 1.0))))


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), start=st.tuples(st.floats(0.1, 2.9), st.floats(0.1, 1.9)))
def test_the_any_angle_field_is_never_longer_than_the_grid_s_on_random_maps(seed, start):
    rng = np.random.default_rng(seed)
    occupied = rng.random((60, 40)) < 0.05
    fmap = floor_map(cv2.dilate(occupied.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool))
    field, grid = any_angle_field(fmap, start), distance_field(fmap, start)
    assert np.array_equal(np.isfinite(field), np.isfinite(grid))
    reach = np.isfinite(grid)
    assert np.all(field[reach] <= grid[reach] + 1e-9)
    x, y = (np.indices(fmap.blocked.shape) + 0.5) * RES
    assert np.all(field[reach] >= np.hypot(x - start[0], y - start[1])[reach] - 1e-9)


def test_blocked_start_starts_from_the_nearest_free_cell():
    fmap = wall_map()
    assert nearest_free_cell(fmap, (4.5, 1.01)) in ((87, 20), (92, 20))
    field = distance_field(fmap, (4.5, 1.0))
    assert np.isfinite(field[10, 10]) and np.isfinite(field[170, 10])
    path = shortest_path(fmap, (4.5, 1.0), (1.0, 1.0))
    assert path is not None and path[0] == (4.5, 1.0) and path_length_m(path) < 3.7


def test_shortest_path_is_smoothed_and_collision_free():
    fmap = wall_map()
    path = shortest_path(fmap, (1.0, 1.0), (8.0, 1.0))
    assert path[0] == (1.0, 1.0) and path[-1] == (8.0, 1.0)
    assert len(path) <= 4  # string pulling leaves the corners only
    assert all(segment_is_free(fmap, a, b) for a, b in zip(path[:-1], path[1:]))
    taut = math.dist((1.0, 1.0), (4.5, 3.5)) + math.dist((4.5, 3.5), (8.0, 1.0))
    assert taut <= path_length_m(path) <= taut + 0.1
    assert shortest_path(fmap, (1.0, 1.0), (2.0, 2.0)) == [(1.0, 1.0), (2.0, 2.0)]


def test_no_path_to_a_blocked_or_enclosed_goal():
    fmap = wall_map()
    assert shortest_path(fmap, (1.0, 1.0), (4.5, 1.0)) is None  # in the wall
    assert shortest_path(fmap, (1.0, 1.0), (10.0, 1.0)) is None  # outside the room
    occupied = fmap.occupied.copy()
    occupied[88:92, :] = True  # the wall now spans the room
    assert shortest_path(floor_map(occupied), (1.0, 1.0), (8.0, 1.0)) is None
    assert path_length_m(None) == math.inf


def test_segment_check_touches_every_cell_and_handles_cell_boundaries():
    occupied = np.zeros((10, 10), bool)
    occupied[5, 5] = True
    fmap = floor_map(occupied)
    assert not segment_is_free(fmap, (0.025, 0.025), (0.475, 0.475))  # through the blocked cell
    assert not segment_is_free(fmap, (0.2, 0.3), (0.3, 0.2))  # diagonally through its corner
    assert segment_is_free(fmap, (0.125, 0.049), (0.025, 0.05))  # ends exactly on a cell boundary
    assert segment_is_free(fmap, (0.3, 0.1), (0.3, 0.1))


def test_distance_field_is_fast_on_a_room_sized_map():
    occupied = np.zeros((180, 100), bool)
    rng = np.random.default_rng(1)
    for x, y in rng.integers(10, 90, size=(12, 2)):
        occupied[2 * x:2 * x + 10, y:y + 8] = True
    fmap = floor_map(occupied, 0.26)
    distance_field(fmap, (0.5, 0.5))  # compile
    times = []
    for _ in range(15):
        start = time.perf_counter()
        distance_field(fmap, (0.5, 0.5))
        times.append(time.perf_counter() - start)
    assert np.median(times) < 0.015  # ~2 ms measured; generous on a shared machine


@settings(max_examples=40, deadline=None)
@example(seed=617, start=(2.0, 1.0), goal=(0.95, 0.1))  # a goal on a corner whose neighbour is blocked
@given(seed=st.integers(0, 10_000), start=st.tuples(st.floats(0.1, 2.9), st.floats(0.1, 1.9)),
       goal=st.tuples(st.floats(0.1, 2.9), st.floats(0.1, 1.9)))
def test_random_maps_paths_agree_with_the_field(seed, start, goal):
    rng = np.random.default_rng(seed)
    occupied = rng.random((60, 40)) < 0.05
    fmap = floor_map(cv2.dilate(occupied.astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool))
    path = shortest_path(fmap, start, goal)
    along_field = path_lengths(fmap, start, np.array([goal]))[0]
    reachable = bool(np.isfinite(along_field)) and not fmap.blocked[int(goal[0] / RES), int(goal[1] / RES)]
    assert (path is not None) == reachable
    if path is not None:
        hops = list(zip(path[:-1], path[1:]))
        start_blocked = fmap.blocked[int(start[0] / RES), int(start[1] / RES)]
        assert all(segment_is_free(fmap, a, b) for a, b in hops[1 if start_blocked else 0:])
        assert path_length_m(path) >= math.dist(start, goal) - 1e-9
        assert path_length_m(path) <= along_field + 2 * RES * math.sqrt(2)


@pytest.mark.parametrize("goal", [(0.0, 0.0), (2.99, 1.99)])
def test_goals_at_the_room_edges(goal):
    fmap = floor_map(np.zeros((60, 40), bool))
    path = shortest_path(fmap, (1.0, 1.0), goal)
    assert path is not None and path[-1] == goal


def test_a_start_on_a_cell_centre_is_kept_when_the_goal_shares_its_cell():
    """The path ends at the goal and begins at the robot, whose next waypoint callers read as path[1]."""
    fmap = floor_map(np.zeros((20, 20), bool))
    centre = ((3 + 0.5) * RES, (3 + 0.5) * RES)
    path = shortest_path(fmap, centre, (0.16, 0.16))
    assert path == [centre, (0.16, 0.16)]
    assert path_length_m(path) == pytest.approx(math.dist(centre, (0.16, 0.16)))
    assert shortest_path(fmap, centre, (0.8, 0.175)) == [centre, (0.8, 0.175)]  # not listed twice


def test_the_distance_field_starts_with_the_hop_to_the_start_cells_centre():
    """Free start cell or not, every cell reads the hop from the start to its cell's centre plus the
    8-connected steps from there (path lengths of the search planner are built on these numbers)."""
    field = distance_field(floor_map(np.zeros((20, 20), bool)), (0.01, 0.04))
    hop = math.dist((0.01, 0.04), (0.025, 0.025))
    assert field[0, 0] == pytest.approx(hop)
    assert field[3, 0] == pytest.approx(hop + 3 * RES)
    assert field[2, 2] == pytest.approx(hop + 2 * math.sqrt(2) * RES)


def test_a_start_outside_the_room_starts_from_the_nearest_edge_cell():
    """Odometry may put the robot a little beyond a wall: its cell is the room's edge cell on that
    side, not one wrapped round to the far side."""
    fmap = floor_map(np.zeros((60, 40), bool))
    field = distance_field(fmap, (-0.3, 1.0))
    assert field[0, 20] == pytest.approx(math.dist((-0.3, 1.0), (0.025, 1.025)))
    path = shortest_path(fmap, (-0.3, 1.0), (0.5, 1.0))
    assert path[0] == (-0.3, 1.0) and path[-1] == (0.5, 1.0)
    assert path_length_m(path) < 0.9


def test_a_star_finds_the_shortest_route_round_an_obstacle():
    """A* with an inadmissible heuristic heads for the goal and settles for the long way round; the
    grid path must be as short as the Dijkstra field says (string pulling only shortens it)."""
    occupied = np.zeros((60, 40), bool)
    occupied[29:31, 6:34] = True  # a wall across x = 1.5 m with gaps at both ends
    fmap = floor_map(occupied)
    start, goal = (20.5 * RES, 35.5 * RES), (50.5 * RES, 5.5 * RES)  # cell centres: the field is exact there
    path = shortest_path(fmap, start, goal)
    assert path_length_m(path) <= distance_field(fmap, start)[50, 5] + 1e-9

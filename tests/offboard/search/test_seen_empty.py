"""What the search takes for empty space: open air stereo has seen through, never the centre of a
target standing on a surface it has seen."""

from __future__ import annotations

from dataclasses import replace

from offboard.perception.occupancy import OccupancyGrid
from offboard.perception.voxel_grid import VoxelGrid
from offboard.search.loop import SearchConfig, seen_empty

TARGET_HALF_M = 0.115  # the bundled target's half size: its centre's height above what it stands on


def test_a_target_seen_through_on_a_table_keeps_its_centre_and_the_open_air_above_is_empty():
    config = SearchConfig()
    grid = VoxelGrid((4.0, 4.0, 2.5), config.resolution_m)
    occupancy = OccupancyGrid(grid)
    top = grid.index_of([1.0, 1.0, 0.72]), grid.index_of([2.0, 2.0, 0.72])
    with occupancy.edit() as (log_odds, observed):
        observed[:] = True
        log_odds[:] = config.empty_log_odds  # seen through everywhere, the target's own cubes too
        log_odds[top[0][0]:top[1][0] + 1, top[0][1]:top[1][1] + 1, top[0][2]] = 1.0  # a table top at 0.72 m
    empty = seen_empty(occupancy, config)
    centre = grid.index_of([1.5, 1.5, 0.72 + TARGET_HALF_M])
    assert not empty[tuple(centre)]
    assert empty[tuple(grid.index_of([1.5, 1.5, 1.3]))]  # far above the table: open air
    assert empty[tuple(grid.index_of([3.0, 3.0, 1.3]))]
    assert config.empty_factor < 1.0  # and the search rules it out by default


def test_a_resting_target_needs_something_to_stand_on_within_its_half_size():
    config = SearchConfig()
    assert config.resting_target  # the default
    grid = VoxelGrid((4.0, 4.0, 2.5), config.resolution_m)
    occupancy = OccupancyGrid(grid)
    low, high = grid.index_of([0.5, 2.5, 0.0]), grid.index_of([1.0, 3.0, 0.5])
    with occupancy.edit() as (log_odds, observed):
        observed[:] = True
        log_odds[:] = config.empty_log_odds
        log_odds[grid.index_of([3.98, 0.0, 0.0])[0]:] = 1.0  # a wall at x = 3.95 m, floor to ceiling
        observed[low[0]:high[0] + 1, low[1]:high[1] + 1, :high[2] + 1] = False  # unknown up to 0.5 m
    resting = seen_empty(occupancy, config)
    anywhere = seen_empty(occupancy, replace(config, resting_target=False))

    def empty(x, y, z, mask):
        return bool(mask[tuple(grid.index_of([x, y, z]))])

    assert empty(3.85, 1.0, 1.3, resting) and not empty(3.85, 1.0, 1.3, anywhere)  # beside the wall, mid-air
    assert empty(2.0, 2.0, 2.42, resting) and not empty(2.0, 2.0, 2.42, anywhere)  # under the ceiling
    assert not empty(2.0, 2.0, TARGET_HALF_M, resting)  # on the floor
    assert not empty(0.75, 2.75, 0.5 + TARGET_HALF_M, resting)  # on what unknown space may hide
    assert not empty(1.05, 2.75, 0.5 + TARGET_HALF_M, resting)  # ... overhanging its edge by less than half
    assert empty(0.75, 2.75, 0.9, resting) and empty(2.0, 2.0, 0.5, resting)  # above either, out of reach
    assert not (resting & ~occupancy.seen_empty(config.empty_log_odds)).any()  # only ever seen-empty cubes

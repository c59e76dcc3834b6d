"""What the search takes for empty space: open air stereo has seen through, never the centre of a
target standing on a surface it has seen."""

from __future__ import annotations

from offboard.perception.occupancy import OccupancyGrid
from offboard.perception.voxel_grid import VoxelGrid
from offboard.search.loop import SearchConfig, seen_empty

TARGET_HALF_M = 0.115  # the bundled target's half size: its centre's height above what it stands on


def test_a_target_seen_through_on_a_table_keeps_its_centre_and_the_open_air_above_is_empty():
    config = SearchConfig()
    grid = VoxelGrid((4.0, 4.0, 2.5), config.resolution_m)
    occupancy = OccupancyGrid(grid)
    occupancy.observed[:] = True
    occupancy.log_odds[:] = config.empty_log_odds  # seen through everywhere, the target's own cubes too
    top = grid.index_of([1.0, 1.0, 0.72]), grid.index_of([2.0, 2.0, 0.72])
    occupancy.log_odds[top[0][0]:top[1][0] + 1, top[0][1]:top[1][1] + 1, top[0][2]] = 1.0  # a table top at 0.72 m
    empty = seen_empty(occupancy, config)
    centre = grid.index_of([1.5, 1.5, 0.72 + TARGET_HALF_M])
    assert not empty[tuple(centre)]
    assert empty[tuple(grid.index_of([1.5, 1.5, 1.3]))]  # far above the table: open air
    assert empty[tuple(grid.index_of([3.0, 3.0, 1.3]))]
    assert config.empty_factor < 1.0  # and the search rules it out by default

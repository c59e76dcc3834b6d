"""The tessellation of the room into cubes refuses sizes it could not tessellate."""

from __future__ import annotations

import pytest

from offboard.perception.voxel_grid import VoxelGrid


@pytest.mark.parametrize(("size", "resolution"), [((4.0, 3.0), 0.05), ((4.0, float("nan"), 2.5), 0.05),
                                                  ((4.0, 3.0, 2.5), float("inf")), ((4.0, 0.0, 2.5), 0.05),
                                                  ((4.0, 3.0, 2.5), -0.05)])
def test_a_grid_needs_three_positive_finite_sides_and_resolution(size, resolution):
    with pytest.raises(ValueError, match="three positive, finite sides"):
        VoxelGrid(size, resolution)


def test_a_grid_covers_its_room_with_whole_cubes():
    assert VoxelGrid((4.0, 3.02, 2.5), 0.05).shape == (80, 61, 50)

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


@pytest.mark.parametrize(("low", "high", "layers"), [
    (0.15, 2.2, (3, 44)),  # faces of layers, though 0.15 / 0.05 is 2.9999999999999996
    (0.1, 1.35, (2, 27)),
    (0.12, 1.33, (2, 27)),  # a height inside a cube takes that cube
    (-1.0, 9.0, (0, 50)),  # clipped to the grid
])
def test_a_height_band_is_the_layers_of_cubes_it_reaches(low, high, layers):
    band = VoxelGrid((4.0, 3.0, 2.5), 0.05).layers(low, high)
    assert (band.start, band.stop) == layers


def test_a_height_band_is_measured_from_the_grids_floor():
    band = VoxelGrid((4.0, 3.0, 2.5), 0.05, origin_m=(0.0, 0.0, -0.5)).layers(0.0, 0.5)
    assert (band.start, band.stop) == (10, 20)

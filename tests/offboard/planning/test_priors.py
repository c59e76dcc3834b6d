"""The dynamic priors (report §3.4 types 2 and 4): what each raises, and that the map-driven one does
not raise the same surface again; and the hints file of type 3."""

import numpy as np
import pytest

from offboard.perception.occupancy import OccupancyGrid
from offboard.perception.voxel_grid import VoxelGrid
from offboard.planning.priors import HintsFile, Saliency, SupportSurfaces
from offboard.search.loop import build_prior
from shared.config import ConfigError, load_config
from shared.geometry import Intrinsics, RigidTransform

K = Intrinsics.from_fov(320, 240, 66.0)
CAMERA = RigidTransform(np.eye(3), np.zeros(3))  # at the origin, looking along +z
FRONT = VoxelGrid((1.0, 1.0, 0.5), 0.1, origin_m=(-0.5, -0.5, 1.0))  # a slab of cubes in front of it
ALL = np.arange(FRONT.num_cubes)


def _picture() -> np.ndarray:
    """Saturated red and blue squares: colours a grey wall never has."""
    tiles = (np.add.outer(np.arange(48) // 8, np.arange(48) // 8) % 2).astype(bool)
    picture = np.zeros((48, 48, 3), np.uint8)
    picture[tiles] = (220, 30, 30)
    picture[~tiles] = (30, 30, 220)
    return picture


def _wall(with_picture: bool) -> np.ndarray:
    rng = np.random.default_rng(0)
    image = np.repeat(rng.integers(90, 140, (K.height_px, K.width_px, 1), dtype=np.uint8), 3, axis=2)
    if with_picture:
        image[96:144, 136:184] = _picture()  # around the image centre
    return image


def test_saliency_raises_the_cubes_seen_where_the_image_looks_like_the_target():
    factor = Saliency((_picture(),), FRONT).factor(_wall(True), ALL, CAMERA, K)
    centre = factor[4:6, 4:6].min()  # the cubes on the optical axis
    corners = np.concatenate([factor[:2, :2].ravel(), factor[-2:, -2:].ravel()])
    assert centre > 1.5 and corners.max() < 1.05 and factor.min() >= 1.0
    assert np.all(Saliency((_picture(),), FRONT).factor(_wall(False), ALL, CAMERA, K) == pytest.approx(1.0, abs=1e-3))


def test_saliency_knows_the_colours_of_every_side_of_a_target():
    """calcHist numbers channels across all its images: given two pictures, it read the first only."""
    green = np.zeros((48, 48, 3), np.uint8)
    green[:] = (30, 200, 40)
    wall = _wall(False)
    wall[96:144, 136:184] = green
    two_sided = Saliency((_picture(), green), FRONT)
    assert two_sided.colour_match(wall)[120, 160] > 0.5
    assert Saliency((_picture(),), FRONT).colour_match(wall)[120, 160] < 0.05


def test_saliency_counts_the_same_sight_once_and_a_restored_one_remembers_it():
    saliency = Saliency((_picture(),), FRONT)
    first = saliency.factor(_wall(True), ALL, CAMERA, K)
    assert np.all(saliency.factor(_wall(True), ALL, CAMERA, K) == 1.0)  # seen again: nothing new
    assert np.all(saliency.factor(_wall(False), ALL, CAMERA, K) == 1.0)  # a duller view takes nothing back
    np.testing.assert_array_equal(saliency.memory(), first)
    restored = Saliency((_picture(),), FRONT)
    restored.restore(saliency.memory())
    assert np.all(restored.factor(_wall(True), ALL, CAMERA, K) == 1.0)
    with pytest.raises(ValueError, match=r"of shape \(10, 10, 5\), not \(10, 10\)"):
        restored.restore(np.ones((10, 10)))


def test_the_space_above_a_mapped_table_is_raised_once():
    grid = VoxelGrid((1.0, 1.0, 1.5), 0.1)
    occupancy = OccupancyGrid(grid)
    with occupancy.edit() as (log_odds, observed):
        observed[:] = True
        log_odds[:] = -2.0  # free
        log_odds[2:6, 2:6, 7] = 3.0  # a 0.4 m table top at 0.7-0.8 m
    support = SupportSurfaces(grid)
    factor = support.update(occupancy)
    boost = support.config.boost
    assert np.all(factor[2:6, 2:6, 8:11] == boost)  # the 0.3 m above its top
    assert np.all(factor[2:6, 2:6, 11:] == 1.0) and np.all(factor[7:, 7:, :] == 1.0)
    assert np.all(support.update(occupancy) == 1.0)  # the same map again: nothing new
    restored = SupportSurfaces(grid)
    restored.restore(support.memory())
    assert np.all(restored.update(occupancy) == 1.0)


def test_a_hints_file_is_read_as_a_config_and_refused_naming_the_file_and_the_problem(tmp_path):
    path = tmp_path / "hints.toml"
    box = 'min = [1.0, 1.0, 0.7]\nmax = [2.0, 2.0, 0.9]\nweight = {}\n'
    path.write_text('[[hint]]\nname = "desk"\n' + box.format(0.6) + '[[hint]]\n' + box.format(0.3))
    assert [(h.name, h.weight) for h in load_config(HintsFile, path).hint] == [("desk", 0.6), ("", 0.3)]
    path.write_text('[[hint]]\n' + box.format(0.6) + '[[hint]]\n' + box.format(0.5))
    with pytest.raises(ConfigError, match="hints.toml.*add up to more than 1"):
        load_config(HintsFile, path)


def test_a_hint_box_the_rooms_cubes_miss_is_refused_naming_it(tmp_path):
    """A box thinner than a cube holds no cube centre: its weight vanished and the prior was uniform."""
    path = tmp_path / "hints.toml"
    path.write_text('[[hint]]\nname = "shelf"\nmin = [0.2, 0.2, 0.51]\nmax = [0.6, 0.6, 0.52]\nweight = 0.9\n')
    with pytest.raises(ConfigError, match="hints.toml.*shelf.*no cube centre"):
        build_prior(VoxelGrid((2.0, 2.0, 1.0), 0.05), [f"hints:{path}"])


def test_a_broken_hints_file_is_named_once(tmp_path):
    path = tmp_path / "hints.toml"
    path.write_text("[[hint]]\nmin = [0.0, 0.0, 0.0]\nmax = [1.0, 1.0, 1.0]\nweight = 2.0\n")
    with pytest.raises(ConfigError) as err:
        build_prior(VoxelGrid((2.0, 2.0, 1.0), 0.05), [f"hints:{path}"])
    assert str(err.value).count(str(path)) == 1 and "hint[0].weight: out of range" in str(err.value)


@pytest.mark.parametrize("others", [[], ["uniform"]])
def test_a_last_seen_point_no_cube_is_near_is_refused_naming_it(others):
    """Centimetres for metres: alone the prior put everything outside the room, mixed it vanished."""
    grid = VoxelGrid((4.0, 3.0, 2.5), 0.05)
    with pytest.raises(ConfigError, match=r"--prior: last seen at \(250.0, 120.0, 80.0\).*no cube holds any of it"):
        build_prior(grid, [*others, "last-seen:250,120,80"])
    near = build_prior(grid, [*others, "last-seen:4.5,1,1"])  # just outside a wall: its tail is inside
    assert near.sum() == pytest.approx(1.0 + len(others))

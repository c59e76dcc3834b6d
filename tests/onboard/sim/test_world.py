"""What the simulator adds to the world format: every texture and picture must be renderable."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from onboard import cli as onboard_cli
from onboard.config import CameraConfig
from onboard.sim import textures
from onboard.sim.render import StereoRenderer
from onboard.sim.world import check_fits, load_world
from shared.geometry import HeadMount
from shared.world import WorldError
from shared.world import load_world as load_world_format

BASE = """\
name = "tiny"
[room]
size = [6.0, 4.0, 2.5]
texture = "brick"

[[obstacle]]
name = "table"
kind = "table"
min = [2.0, 2.0, 0.0]
max = [3.0, 3.0, 0.75]

[target]
picture = "target.png"
size = [0.2, 0.2, 0.2]
position = [2.5, 2.5, 0.75]
yaw_deg = -90

[robot]
start = [1.0, 1.0]
"""
LOW = BASE.replace("size = [6.0, 4.0, 2.5]", "size = [6.0, 4.0, 1.0]").replace("0.75", "0.5")  # under the camera
POSTER = '[[poster]]\nname = "p"\npicture = "nope"\ncenter = [3.0, 4.0, 1.5]\nsize = [0.5, 0.4]\nyaw_deg = -90\n'


def write(tmp_path, text: str, name: str = "w.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def edit(old: str, new: str) -> str:
    assert old in BASE
    return BASE.replace(old, new)


@pytest.mark.parametrize(
    "text, key",
    [
        (edit('picture = "target.png"', 'picture = "mona-lisa"'), "target.picture: unknown picture"),
        (edit('picture = "target.png"', 'picture = "missing.png"'), "target.picture: picture file"),
        (edit('texture = "brick"', 'texture = "marble"'), "room.texture: unknown texture 'marble' (known: brick"),
        (edit('kind = "table"', 'kind = "table"\ntexture = "lava"'), "obstacle[0].texture"),
        (BASE + POSTER, "poster[0].picture"),
    ],
)
def test_what_the_simulator_cannot_render_is_refused_naming_the_key(tmp_path, text, key):
    path = write(tmp_path, text)
    assert load_world_format(path).name == "tiny"  # the format itself has no opinion on names
    with pytest.raises(WorldError) as err:
        load_world(path)
    assert key in str(err.value)
    assert str(tmp_path) in str(err.value)  # and the file


def test_an_unreadable_picture_file_is_refused(tmp_path):
    (tmp_path / "broken.png").write_bytes(b"not a png")
    with pytest.raises(WorldError, match=r"target\.picture: cannot read picture file"):
        load_world(write(tmp_path, edit('picture = "target.png"', 'picture = "broken.png"')))


def test_a_picture_file_next_to_the_world_is_used(tmp_path):
    picture = np.zeros((40, 60, 3), np.uint8)
    picture[:, :30] = (255, 0, 0)  # left half red, to check the RGB order
    cv2.imwrite(str(tmp_path / "mine.png"), cv2.cvtColor(picture, cv2.COLOR_RGB2BGR))
    world = load_world(write(tmp_path, edit('picture = "target.png"', 'picture = "mine.png"')))
    loaded = textures.load_picture(world.target.picture, world.base_dir)
    np.testing.assert_array_equal(loaded, picture)


def test_a_room_lower_than_the_cameras_is_refused_by_the_simulator(tmp_path):
    world = load_world(write(tmp_path, LOW))  # the format cannot know the robot
    with pytest.raises(WorldError, match=r"room\.size: the room is 1 m high, and the robot's cameras are 1\.2 m"):
        check_fits(world, HeadMount())
    with pytest.raises(WorldError, match=r"room\.size: the room is 1 m high"):
        StereoRenderer(world, CameraConfig().intrinsics(), HeadMount())
    check_fits(world, HeadMount(height_m=0.9))  # a shorter robot fits


def test_worlds_check_names_every_world_it_cannot_run_and_passes_the_rest(tmp_path, capsys, caplog):
    good = write(tmp_path, BASE, "good.toml")
    low = write(tmp_path, LOW, "low.toml")
    bad = write(tmp_path, edit('texture = "brick"', 'texture = "marble"'), "bad.toml")
    assert onboard_cli.main(["worlds", "check", str(good), "paper-lab"]) == 0
    assert "2 worlds ok" in capsys.readouterr().out
    assert onboard_cli.main(["worlds", "check", str(good), str(low), str(bad)]) == 2
    errors = [r.getMessage() for r in caplog.records if r.levelname == "ERROR"]
    assert len(errors) == 2 and "room.size" in errors[0] and str(low) in errors[0]
    assert "room.texture: unknown texture 'marble'" in errors[1] and str(bad) in errors[1]


def test_render_refuses_a_room_lower_than_the_cameras_naming_the_file(tmp_path, caplog):
    low = write(tmp_path, LOW, "low.toml")
    assert onboard_cli.main(["render", "--world", str(low), "--out", str(tmp_path / "out")]) == 2
    errors = [r.getMessage() for r in caplog.records if r.levelname == "ERROR"]
    assert errors == [f"room.size: the room is 1 m high, and the robot's cameras are 1.2 m above the floor: the robot "
                      f"does not fit [in {low}]"]
    assert not (tmp_path / "out").exists()


def test_picture_and_texture_library():
    assert textures.load_picture("target.png", "/nonexistent").shape[2] == 3
    np.testing.assert_array_equal(textures.load_picture("target.png"), textures.load_picture("target"))
    for name in textures.picture_names():
        picture = textures.load_picture(name)
        assert picture.dtype == np.uint8 and picture.ndim == 3 and picture.shape[2] == 3
    with pytest.raises(textures.PictureError, match="unknown picture"):
        textures.load_picture("nope")
    assert {"brick", "grass", "gravel", "wood", "carpet", "plaster", "metal", "fabric"} <= set(
        textures.texture_names())
    for name in textures.texture_names():
        image = textures.texture_image(name)
        assert image.shape == (512, 512, 3) and image.std() > 20, name  # textured, for stereo
    assert textures.default_texture("obstacle", "Table") == "wood"
    assert textures.default_texture("obstacle", "spaceship") in textures.texture_names()

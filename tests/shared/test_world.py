"""World files (the format in shared/world.py): the bundled worlds load, every kind of mistake is refused
naming its key. What the simulator adds (textures, pictures) is tested in tests/onboard/sim/test_world.py."""

from __future__ import annotations

import math

import numpy as np
import pytest

from shared.world import WorldError, bundled_world_names, load_world

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

[[obstacle]]
name = "wall-shelf"
kind = "shelf"
min = [0.0, 0.0, 1.6]
max = [1.0, 0.3, 1.65]

[target]
picture = "target.png"
size = [0.2, 0.2, 0.2]
position = [2.5, 2.5, 0.75]
yaw_deg = -90

[robot]
start = [1.0, 1.0]
heading_deg = 90
"""
POSTER = '[[poster]]\nname = "p"\npicture = "rocket"\ncenter = [3.0, 4.0, 1.5]\nsize = [0.5, 0.4]\nyaw_deg = -90\n'
NO_OBSTACLES = BASE[: BASE.index("[[obstacle]]")] + BASE[BASE.index("[target]") :]


def write(tmp_path, text: str, name: str = "w.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def edit(old: str, new: str) -> str:
    assert old in BASE
    return BASE.replace(old, new)


def test_the_bundled_worlds_load():
    assert bundled_world_names() == ["high-shelf", "office", "paper-lab", "paper-lab-one-sided"]
    for name in bundled_world_names():
        world = load_world(name)
        assert world.name == name
        assert world.obstacles and world.posters


def test_paper_lab_matches_the_report():
    world = load_world("paper-lab")
    assert world.room.size_m == (9.0, 5.0, 2.5)
    assert (world.start.x_m, world.start.y_m) == (4.5, 0.6)
    assert world.start.heading_rad == pytest.approx(math.pi / 2)
    kinds = {b.kind for b in world.obstacles}
    assert {"table", "shelf", "chair", "cabinet"} <= kinds
    assert any(b.kind == "table" and b.min_m[0] < 4.5 < b.max_m[0] and b.min_m[1] < 2.5 < b.max_m[1]
               for b in world.obstacles), "a table in the centre of the room"
    free = 0
    for x in range(1, 9):
        for y in range(1, 5):
            try:
                world.with_start(x, y, 0.0)
                free += 1
            except WorldError:
                pass
    assert free >= 28, f"only {free} of the 32 grid vertices are free for the robot"


def test_the_high_shelf_target_sits_high():
    target = load_world("high-shelf").target
    assert 1.9 <= target.box().max_m[2] <= 2.2  # above a level view from the floor in front


def test_a_minimal_valid_world_and_its_defaults(tmp_path):
    world = load_world(write(tmp_path, BASE))
    assert world.base_dir == tmp_path
    assert world.room.floor_texture is None and world.room.texture == "brick"
    assert world.obstacles[0].min_m == (2.0, 2.0, 0.0)
    assert world.target.position_m == (2.5, 2.5, 0.75)  # resting on the table is fine
    np.testing.assert_allclose(world.target.facing(), [0.0, -1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(world.target.center_m(), [2.5, 2.5, 0.85])
    assert world.posters == ()
    with_poster = load_world(write(tmp_path, BASE + POSTER))  # flat on the north wall, facing -y
    np.testing.assert_allclose(with_poster.posters[0].picture_corners_m()[:, 1], 4.0)


@pytest.mark.parametrize(
    ("text", "key"),
    [
        (edit('name = "tiny"', "name = "), "line 1"),
        (edit('name = "tiny"', 'name = "tiny"\n[room'), "line 2"),
        (edit("size = [6.0, 4.0, 2.5]\n", ""), "room.size: missing"),
        (edit("[robot]\nstart = [1.0, 1.0]", "[robot]\nheading = 3.0"), "robot.heading"),
        (edit("[[obstacle]]", "[[obstacles]]"), "obstacles: unknown key"),
        (edit("max = [3.0, 3.0, 0.75]", "maxx = [3.0, 3.0, 0.75]"), "obstacle[0].maxx"),
        (edit('name = "tiny"', "name = 3"), "name: must be a non-empty string"),
        (edit("size = [6.0, 4.0, 2.5]", 'size = "big"'), "room.size"),
        (edit("size = [6.0, 4.0, 2.5]", "size = [6.0, 4.0]"), "room.size"),
        (edit("size = [6.0, 4.0, 2.5]", "size = [6.0, true, 2.5]"), "room.size"),
        (edit("size = [6.0, 4.0, 2.5]", "size = [nan, 4.0, 2.5]"), "room.size: must be finite"),
        (edit("position = [2.5, 2.5, 0.75]", "position = [2.5, inf, 0.75]"), "target.position"),
        (edit("yaw_deg = -90", 'yaw_deg = "south"'), "target.yaw_deg"),
        (edit("yaw_deg = -90", "yaw_deg = -90\nsides = 2"), "target.sides: must be 1 or 4"),
        (edit("size = [0.2, 0.2, 0.2]", "size = [0.2, 0.0, 0.2]"), "target.size"),
        (edit("size = [0.2, 0.2, 0.2]", "size = [0.4, 0.1, 0.3]").replace("yaw_deg = -90", "yaw_deg = -90\nsides = 4"),
         "target.size: a target pictured on 4 sides needs a square footprint (size[0] == size[1]), got [0.4, 0.1, 0.3]"),
        (edit("size = [6.0, 4.0, 2.5]", "size = [6.0, -4.0, 2.5]"), "room.size"),
        # larger than the wire's poses (±10 km) once: it loaded, and then its robot's poses were refused
        (edit("size = [6.0, 4.0, 2.5]", "size = [20000.0, 4.0, 2.5]"), "room.size: every side must be at most 100 m"),
        (edit("max = [3.0, 3.0, 0.75]", "max = [3.0, 2.0, 0.75]"), "obstacle[0].max: max must exceed min"),
        (edit("max = [3.0, 3.0, 0.75]", "max = [6.5, 3.0, 0.75]"),
         "obstacle[0].max: obstacle 'table' lies outside the room [6, 4, 2.5] (max [6.5, 3, 0.75])"),
        (edit("min = [2.0, 2.0, 0.0]", "min = [-0.5, 2.0, 0.0]"), "obstacle[0].min: obstacle 'table' lies outside"),
        (edit("max = [1.0, 0.3, 1.65]", "max = [1.0, 0.3, 2.6]"), "obstacle[1]"),
        (edit("position = [2.5, 2.5, 0.75]", "position = [5.95, 2.5, 0.0]"),
         "target.position: target box lies outside the room [6, 4, 2.5] (its extent is [5.85, 2.4, 0] .. [6.05, 2.6, 0.2])"),
        (edit("position = [2.5, 2.5, 0.75]", "position = [2.5, 2.5, 0.6]"),
         "target.position: target box overlaps obstacle 'table'"),
        (edit("start = [1.0, 1.0]", "start = [7.0, 1.0]"), "robot.start"),
        (edit("start = [1.0, 1.0]", "start = [0.1, 1.0]"), "robot.start"),
        (edit("start = [1.0, 1.0]", "start = [1.8, 2.5]"),
         "robot.start: the robot disc (radius 0.26 m) at (1.800, 2.500) overlaps table 'table'"),
        (NO_OBSTACLES.replace("[target]", "[obstacle]\nname = 'x'\n[target]"), "obstacle: must be an array of tables"),
        (edit("[robot]\nstart = [1.0, 1.0]\nheading_deg = 90\n", "").replace("[room]", "robot = 3\n[room]"),
         "robot: must be a table"),
        (BASE + POSTER.replace("yaw_deg = -90", "yaw_deg = 0"), "poster[0].center: poster 'p' lies outside the room"),
        (BASE + POSTER.replace("size = [0.5, 0.4]\n", ""), "poster[0].size: missing"),
    ],
)
def test_mistakes_are_refused_naming_the_key(tmp_path, text, key):
    with pytest.raises(WorldError) as err:
        load_world(write(tmp_path, text))
    assert key in str(err.value)
    assert str(tmp_path) in str(err.value)  # and the file


@pytest.mark.parametrize(
    ("position", "found"),
    [
        ("[4.0, 2.0, 1.2]", "bottom is 1.2 m high and rests on nothing: the tops at its centre (4, 2) are the floor "
                            "at 0 m ("),
        ("[2.5, 2.5, 0.91]", "bottom is 0.91 m high and rests on nothing: the tops at its centre (2.5, 2.5) are the "
                             "floor at 0 m, 'table' at 0.75 m (tolerance 1 mm)"),  # 16 cm above the table
        ("[3.2, 2.5, 0.75]", "at its centre (3.2, 2.5) are the floor at 0 m ("),  # beside the table, at its height
        ("[0.5, 0.15, 1.2]", "are the floor at 0 m, 'wall-shelf' at 1.65 m"),  # under the shelf, in the air
    ],
)
def test_a_target_in_the_air_is_refused_naming_the_file_its_height_and_the_tops_under_it(tmp_path, position, found):
    with pytest.raises(WorldError) as err:
        load_world(write(tmp_path, edit("position = [2.5, 2.5, 0.75]", f"position = {position}")))
    assert str(err.value).startswith("target.position: the target's ") and found in str(err.value)
    assert str(tmp_path) in str(err.value)


@pytest.mark.parametrize("position", ["[2.5, 2.5, 0.7509]", "[3.0, 2.5, 0.75]", "[0.5, 0.15, 1.65]", "[4.0, 2.0, 0.0]"])
def test_a_target_on_the_floor_or_a_top_under_its_centre_is_accepted_within_a_millimetre(tmp_path, position):
    load_world(write(tmp_path, edit("position = [2.5, 2.5, 0.75]", f"position = {position}")))


def test_a_world_file_with_a_byte_order_mark_loads(tmp_path):
    path = tmp_path / "bom.toml"
    path.write_bytes(b"\xef\xbb\xbf" + BASE.encode())
    assert load_world(path).name == "tiny"


def test_missing_world_file_and_unknown_bundled_name(tmp_path):
    with pytest.raises(WorldError, match="no bundled world of that name"):
        load_world("paper-lap")
    with pytest.raises(WorldError, match="no such world file"):
        load_world(tmp_path / "nowhere.toml")


def test_a_wall_shelf_does_not_block_the_base_but_a_larger_robot_is_checked(tmp_path):
    path = write(tmp_path, edit("start = [1.0, 1.0]", "start = [0.5, 0.3]"))
    assert load_world(path).start.x_m == 0.5  # under the shelf mounted at 1.6 m
    with pytest.raises(WorldError, match="robot.start"):
        load_world(path, robot_radius_m=0.35)


def test_start_overrides_are_validated(tmp_path):
    world = load_world(write(tmp_path, BASE))
    moved = world.with_start(4.0, 1.0, 0.5)
    assert (moved.start.x_m, moved.start.y_m, moved.start.heading_rad) == (4.0, 1.0, 0.5)
    assert world.start.x_m == 1.0  # frozen: the original is unchanged
    with pytest.raises(WorldError, match="robot.start.*overlaps table 'table'"):
        world.with_start(2.5, 2.5, 0.0)
    with pytest.raises(WorldError, match="robot.start.*not inside the room"):
        world.with_start(-1.0, 1.0, 0.0)
    with pytest.raises(WorldError, match="robot.start: must be finite"):
        world.with_start(float("nan"), 1.0, 0.0)


def test_target_overrides_are_validated(tmp_path):
    world = load_world(write(tmp_path, BASE))
    moved = world.with_target(4.0, 3.0, 0.0, 45.0)
    assert moved.target.position_m == (4.0, 3.0, 0.0) and moved.target.yaw_deg == 45.0
    with pytest.raises(WorldError, match="target.position: target box lies outside"):
        world.with_target(5.95, 1.0, 0.0, 0.0)
    with pytest.raises(WorldError, match="target.position: target box lies outside"):
        world.with_target(3.0, 1.0, 2.4, 0.0)
    with pytest.raises(WorldError, match="overlaps obstacle 'table'"):
        world.with_target(2.5, 1.95, 0.0, 45.0)  # the yawed corner cuts into the table
    assert world.with_target(2.5, 1.85, 0.0, 45.0).target.yaw_deg == 45.0  # clear of it
    with pytest.raises(WorldError, match="robot.start"):
        world.with_target(1.0, 1.2, 0.0, 0.0)  # a target on the floor blocks the robot too
    with pytest.raises(WorldError, match="target.position: the target's bottom is 0.5 m high and rests on nothing"):
        world.with_target(4.0, 3.0, 0.5, 0.0)


def test_yawed_target_footprint_and_picture_corners():
    world = load_world("paper-lab").with_target(6.0, 3.5, 0.0, 45.0)
    target = world.target
    box = target.box()
    side = target.size_m[0] * math.sqrt(2.0)
    assert box.max_m[0] - box.min_m[0] == pytest.approx(side)
    assert box.max_m[2] - box.min_m[2] == pytest.approx(target.size_m[2])
    corners = target.picture_corners_m()
    centre = target.center_m() + target.facing() * target.size_m[0] / 2
    np.testing.assert_allclose(corners.mean(axis=0), centre, atol=1e-12)
    # Seen from in front (looking back along the facing), top-left lies left of top-right.
    viewer_right = np.cross(-target.facing(), [0.0, 0.0, 1.0])
    assert (corners[1] - corners[0]) @ viewer_right == pytest.approx(target.size_m[1])
    assert corners[0][2] > corners[3][2]


def test_paper_lab_one_sided_differs_from_paper_lab_only_in_its_target_sides():
    four, one = load_world("paper-lab"), load_world("paper-lab-one-sided")
    assert (four.target.sides, one.target.sides) == (4, 1)
    assert (four.room, four.obstacles, four.posters, four.start) == (one.room, one.obstacles, one.posters, one.start)
    assert four.target.position_m == one.target.position_m and four.target.yaw_deg == one.target.yaw_deg

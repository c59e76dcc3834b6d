"""The shipped suites (generated rooms in shared/worlds/dev and test, rooms written by hand in hand): every
world loads, by path and by its suite name; suite names expand for the experiment harness; each suite says
what it is for."""

from __future__ import annotations

import tomllib

import pytest

from shared.world import (WORLDS_DIR, WorldError, expand_suites, load_world, suite_names, suite_worlds,
                          world_toml)

SUITES = {"dev": (32, 1000), "test": (20, 2000)}


def test_the_suites_and_their_sizes():
    assert suite_names() == ["dev", "hand", "test"]
    for name, (count, seed) in SUITES.items():
        paths = suite_worlds(name)
        assert paths == sorted(paths)
        assert sorted(p.stem for p in paths) == sorted(f"room-{seed}-{k}" for k in range(count))


@pytest.mark.parametrize("suite", [*sorted(SUITES), "hand"])
def test_every_suite_world_loads_one_sided_target_by_path_and_by_name(suite):
    smallest = 3.0 if suite == "hand" else 4.0  # the hand-written corridor is 3 m wide
    for path in suite_worlds(suite):
        world = load_world(path)
        assert world.name == path.stem
        assert (world.target.sides, world.target.picture) == (1, "target")
        assert smallest <= min(world.room.size_m[:2]) and max(world.room.size_m[:2]) <= 12.0
        assert load_world(f"{suite}/{path.stem}") == world


def test_each_suite_readme_says_what_it_is_for_and_the_command_that_made_it():
    for name, (count, seed) in SUITES.items():
        readme = (WORLDS_DIR / name / "README.md").read_text()
        assert f"syt-onboard worlds generate --count {count} --seed {seed} --out shared/worlds/{name}" in readme
    assert "never tune" in (WORLDS_DIR / "test" / "README.md").read_text()
    assert "tune on" in (WORLDS_DIR / "dev" / "README.md").read_text()
    assert "never tune" in (WORLDS_DIR / "hand" / "README.md").read_text()
    assert len(suite_worlds("hand")) == 9


def test_suite_names_expand_to_their_worlds_among_other_worlds():
    expanded = expand_suites(["paper-lab", "dev", "office"])
    assert expanded[0] == "paper-lab" and expanded[-1] == "office"
    assert list(expanded[1:-1]) == [f"dev/{p.stem}" for p in suite_worlds("dev")]
    assert len(expand_suites(["test"])) == 20


def test_a_folder_expands_to_its_world_files_and_an_empty_one_is_refused(tmp_path):
    for name in ("room-7-1.toml", "room-7-0.toml", "notes.md"):
        (tmp_path / name).write_text("")
    assert expand_suites(["paper-lab", str(tmp_path)]) == ("paper-lab", str(tmp_path / "room-7-0.toml"),
                                                           str(tmp_path / "room-7-1.toml"))
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(WorldError, match="empty: a folder with no world files"):
        expand_suites([str(empty)])


def test_unknown_suites_and_suite_paths_are_refused_naming_them():
    with pytest.raises(WorldError, match="nope: no such world suite .*dev, hand, test"):
        suite_worlds("nope")
    with pytest.raises(WorldError, match="nope/room-1000-0: no such world"):
        load_world("nope/room-1000-0")
    with pytest.raises(WorldError, match="dev/room-9: no such world"):
        load_world("dev/room-9")


def test_world_toml_reads_back_as_written():
    data = {"name": 'say "hi"', "room": {"size": [4.0, 5.5, 2.5]}, "obstacle": [{"name": "a", "min": [0.0, 0, 0]}],
            "robot": {"start": [1.0, 1.0], "heading_deg": 15.0}}
    text = world_toml(data, "first line\nsecond line")
    assert text.startswith("# first line\n# second line\n")
    assert tomllib.loads(text) == data

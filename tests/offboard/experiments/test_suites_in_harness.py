"""The experiment harness and the suites of generated rooms: ``--worlds`` takes suite names, and a
suite world's scenarios start with its own target (the one the generator checked can be seen)."""

from __future__ import annotations

import math

from conftest import experiment_args

from offboard.experiments import harness as experiment
from offboard.experiments.world_facts import DRIVE_CLEARANCE_M, SeeingCriteria, load_facts, target_placements, viewpoint
from shared.world import suite_worlds


def _grid(*argv: str) -> experiment.GridSpec:
    return experiment.grid_from_args(experiment_args(*argv))


def test_worlds_takes_suite_names_alone_or_mixed():
    dev = [f"dev/{p.stem}" for p in suite_worlds("dev")]
    assert _grid("--worlds", "dev").worlds == tuple(dev)
    assert _grid("--worlds", "paper-lab,dev").worlds == ("paper-lab", *dev)
    assert len(_grid("--worlds", "test").worlds) == 20
    assert _grid("--worlds", "office").worlds == ("office",)


def test_a_suite_worlds_first_placement_is_its_own_target_and_the_oracle_can_see_it():
    world = load_facts("test/room-2000-0")
    placements = target_placements(world, 2)
    assert placements[0] == world.target and len(placements) == 2
    drive = SeeingCriteria(robot_radius_m=DRIVE_CLEARANCE_M)
    assert math.isfinite(viewpoint(world.truth(world.target), world.start[:2], drive)[1])
    assert target_placements(load_facts("paper-lab"), 4)[0] != load_facts("paper-lab").target  # bundled: tables first


def test_a_room_of_ones_own_is_searched_for_its_own_target_wherever_the_file_lies(tmp_path):
    copy = tmp_path / "my-room.toml"  # as `worlds generate --out DIR` writes it, outside the suites
    original = suite_worlds("dev")[3]
    copy.write_text(original.read_text())
    world = load_facts(str(copy))
    placements = target_placements(world, 2)
    assert placements[0] == world.target and placements[1] != world.target
    assert placements == target_placements(load_facts(f"dev/{original.stem}"), 2)

"""Generated rooms (onboard/sim/world_generator.py) and their check (onboard/sim/world_check.py): every
written world loads and is searchable; the draws vary as promised; a hidden target, an enclosed start
and a start beside the target are refused; a seed gives the same files; the shipped suites are what
the command makes; ``--max-turn-deg`` turns pictures further, or not at all, and leaves the default rooms."""

from __future__ import annotations

import math
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from onboard.cli import main
from onboard.sim import world_generator
from onboard.sim.world import load_world
from onboard.sim.world_check import DRIVE_CLEARANCE_M, WorldRejected, check_world, reachable_floor
from onboard.sim.world_generator import MAX_TURN_DEG, TURN_LIMIT_DEG, draw_checked_world, generate_world, write_worlds
from shared.world import FLOOR_OBSTACLE_MAX_Z_M, WORLDS_DIR, Box, World, parse_world

SEED = 7
KINDS = {"table", "desk", "shelf", "cabinet", "crate", "partition", "sofa"}


@pytest.fixture(scope="module")
def written(tmp_path_factory) -> list[Path]:
    return write_worlds(4, SEED, tmp_path_factory.mktemp("worlds"))


@pytest.fixture(scope="module")
def draws() -> list[dict]:
    """Unchecked draws (no rendering): enough of them to see the variety."""
    return _draws(11, 24)


def _draws(seed: int, count: int, **kwargs) -> list[dict]:
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < count:
        try:
            out.append(generate_world(rng, f"draw-{len(out)}", **kwargs))
        except WorldRejected:
            continue
    return out


def _world(data: dict) -> World:
    return parse_world(data, Path("."))


def test_every_written_world_loads_and_passes_the_check(written):
    assert [p.name for p in written] == [f"room-{SEED}-{k}.toml" for k in range(4)]
    for path in written:
        world = load_world(path)  # the simulator's own loader: format and render checks
        assert world.name == path.stem
        seen = check_world(world)
        assert 0.6 <= seen.distance_m <= 2.5 and seen.off_normal_deg <= 40.0
        assert reachable_floor(world).drivable[int(seen.x_m / 0.05), int(seen.y_m / 0.05)]


def test_rooms_are_4_to_12_m_across_and_2_4_to_3_m_high(draws):
    for data in draws:
        x, y, z = data["room"]["size"]
        assert 4.0 <= x <= 12.0 and 4.0 <= y <= 12.0 and 2.4 <= z <= 3.0
    sizes = np.array([d["room"]["size"][:2] for d in draws])
    assert sizes.min() < 6.0 and sizes.max() > 10.0  # x and y drawn over the whole span


def test_a_batch_has_every_kind_of_furniture_high_wall_shelves_and_varied_textures(draws):
    worlds = [_world(d) for d in draws]
    assert KINDS <= {b.kind for w in worlds for b in w.obstacles}
    # high wall shelves, which leave the floor to the robot
    assert any(b.kind == "shelf" and b.min_m[2] >= FLOOR_OBSTACLE_MAX_Z_M for w in worlds for b in w.obstacles)
    for kind in ("table", "cabinet", "crate"):
        assert len({b.texture for w in worlds for b in w.obstacles if b.kind == kind}) >= 2, kind
    for w in worlds:
        assert all(p.picture not in ("target", "chelsea") for p in w.posters)
    assert any(w.posters for w in worlds)


def test_floor_pieces_leave_gaps_the_robot_drives_through(draws):
    for data in draws:
        world = _world(data)
        floor = world.floor_obstacles()
        for i, a in enumerate(floor):
            for b in floor[i + 1:]:
                dx = max(b.min_m[0] - a.max_m[0], a.min_m[0] - b.max_m[0], 0.0)
                dy = max(b.min_m[1] - a.max_m[1], a.min_m[1] - b.max_m[1], 0.0)
                assert math.hypot(dx, dy) >= 2 * DRIVE_CLEARANCE_M, (world.name, a.name, b.name)


def _support(world: World) -> Box:
    t = world.target
    corners = t.footprint_corners_m()
    return next(b for b in world.obstacles if abs(b.max_m[2] - t.position_m[2]) < 1e-6
                and np.all(corners >= np.array(b.min_m[:2]) - 1e-3) and np.all(corners <= np.array(b.max_m[:2]) + 1e-3))


def test_the_target_stands_on_a_surface_one_sided_facing_open_floor_high_or_low(draws):
    heights = []
    for data in draws:
        world = _world(data)
        t = world.target
        assert (t.sides, t.picture, t.size_m) == (1, "target", (0.23, 0.23, 0.23))
        support = _support(world)  # the whole footprint rests on one top
        assert support.kind in ("table", "desk", "shelf", "cabinet", "crate")
        heights.append(t.position_m[2])
        face = t.center_m()[:2] + t.facing()[:2] * t.size_m[0] / 2
        for d in np.arange(0.1, 1.2, 0.05):  # open floor straight in front of the picture
            p = face + t.facing()[:2] * d
            assert 0 < p[0] < world.room.size_m[0] and 0 < p[1] < world.room.size_m[1], world.name
            assert not any(b.min_m[0] <= p[0] <= b.max_m[0] and b.min_m[1] <= p[1] <= b.max_m[1]
                           for b in world.floor_obstacles()), world.name
    heights = np.array(heights)
    assert np.any((heights >= 1.55) & (heights <= 2.1)) and np.any((heights >= 0.4) & (heights <= 0.8))


def test_the_start_is_drivable_open_floor_away_from_the_target(draws):
    for data in draws:
        world = _world(data)
        s = world.start
        gaps = [s.x_m, s.y_m, world.room.size_m[0] - s.x_m, world.room.size_m[1] - s.y_m]
        for b in world.floor_obstacles():
            gaps.append(math.hypot(max(b.min_m[0] - s.x_m, 0, s.x_m - b.max_m[0]),
                                   max(b.min_m[1] - s.y_m, 0, s.y_m - b.max_m[1])))
        assert min(gaps) >= DRIVE_CLEARANCE_M
        assert reachable_floor(world).drivable.sum() > 100
        assert s.distance_to(*world.target.position_m[:2]) >= 1.5


def _boxed_in(data: dict) -> dict:
    """The same world with a box standing right in front of the target's picture."""
    world = _world(data)
    t, box = world.target, world.target.box()
    axis = int(np.argmax(np.abs(t.facing()[:2])))
    sign = float(np.sign(t.facing()[axis]))
    lo, hi = [0.0, 0.0, box.min_m[2]], [0.0, 0.0, min(box.max_m[2] + 0.6, world.room.size_m[2])]
    front = box.max_m[axis] if sign > 0 else box.min_m[axis]
    lo[axis], hi[axis] = sorted((front + sign * 0.03, front + sign * 0.6))
    centre = t.position_m[1 - axis]
    lo[1 - axis], hi[1 - axis] = centre - 0.4, centre + 0.4
    occluder = {"name": "occluder", "kind": "crate", "min": lo, "max": hi}
    return {**data, "obstacle": [*data["obstacle"], occluder]}


def test_a_target_hidden_behind_a_box_is_rejected(written):
    data = tomllib.loads(written[0].read_text())
    check_world(_world(data))  # seen as generated
    with pytest.raises(WorldRejected, match="hides the target"):
        check_world(_world(_boxed_in(data)))


def test_a_picture_whose_bottom_edge_a_shelf_front_hides_is_rejected():
    """The corners SPL's yardstick must see are the ones the check probes (dev's old room-1000-28)."""
    world = load_world(Path(__file__).with_name("picture-set-back-on-a-high-shelf.toml"))
    with pytest.raises(WorldRejected, match="hides the target"):
        check_world(world)


def test_a_start_near_the_target_or_walled_in_is_rejected(written):
    worlds = [load_world(p) for p in written]
    world = max(worlds, key=lambda w: w.start.distance_to(*w.target.position_m[:2]))
    assert world.start.distance_to(*world.target.position_m[:2]) > 2.6  # out of range from the pen below
    x, y, _ = world.target.position_m
    normal = world.target.facing()
    with pytest.raises(WorldRejected, match="from the target"):
        check_world(world.with_start(x + normal[0] * 0.8, y + normal[1] * 0.8, 0.0))
    s = world.start
    pen = tuple(Box(f"wall-{k}", "partition", lo, hi, None) for k, (lo, hi) in enumerate([
        ((s.x_m - 0.5, s.y_m - 0.5, 0.0), (s.x_m + 0.5, s.y_m - 0.45, 1.0)),
        ((s.x_m - 0.5, s.y_m + 0.45, 0.0), (s.x_m + 0.5, s.y_m + 0.5, 1.0)),
        ((s.x_m - 0.5, s.y_m - 0.5, 0.0), (s.x_m - 0.45, s.y_m + 0.5, 1.0)),
        ((s.x_m + 0.45, s.y_m - 0.5, 0.0), (s.x_m + 0.5, s.y_m + 0.5, 1.0))]))
    with pytest.raises(WorldRejected, match="no reachable pose"):
        check_world(replace(world, obstacles=world.obstacles + pen))


def test_the_same_seed_writes_the_same_files(written, tmp_path):
    again = write_worlds(2, SEED, tmp_path / "again")
    assert [p.read_bytes() for p in again] == [p.read_bytes() for p in written[:2]]
    other = write_worlds(1, SEED + 1, tmp_path / "other")
    assert other[0].read_text() != written[0].read_text()


def test_the_command_writes_the_files(tmp_path, written, capsys):
    assert main(["worlds", "generate", "--count", "1", "--seed", str(SEED), "--out", str(tmp_path)]) == 0
    assert (tmp_path / f"room-{SEED}-0.toml").read_bytes() == written[0].read_bytes()
    with pytest.raises(SystemExit) as refused:
        main(["worlds", "generate", "--count", "0", "--seed", "1", "--out", str(tmp_path)])
    assert refused.value.code == 2 and "--count: must be at least 1" in capsys.readouterr().err


def test_a_negative_seed_is_refused_by_name_before_anything_is_made(tmp_path, capsys):
    with pytest.raises(SystemExit) as refused:
        main(["worlds", "generate", "--count", "1", "--seed", "-1", "--out", str(tmp_path / "new")])
    assert refused.value.code == 2 and "--seed: must be 0 or more, got -1" in capsys.readouterr().err
    with pytest.raises(ValueError, match="seed must be 0 or more, got -1"):
        write_worlds(1, -1, tmp_path / "new")
    assert not (tmp_path / "new").exists()


def test_a_folder_holding_another_batch_is_refused_and_the_batch_itself_rewritten(tmp_path, written, caplog):
    out = tmp_path / "out"
    out.mkdir()
    (out / f"room-{SEED}-0.toml").write_text("stale, of this batch: rewritten")
    (out / f"room-{SEED + 1}-0.toml").write_text("of another batch: left alone")
    command = ["worlds", "generate", "--count", "1", "--seed", str(SEED), "--out", str(out)]
    assert main(command) == 2
    error = [r.getMessage() for r in caplog.records if r.levelname == "ERROR"][-1]
    assert error.startswith(f"{out}: already holds world files this batch (seed {SEED}, count 1) would not write: "
                            f"room-{SEED + 1}-0.toml;")
    assert (out / f"room-{SEED}-0.toml").read_text() == "stale, of this batch: rewritten"  # nothing written
    (out / f"room-{SEED + 1}-0.toml").unlink()
    assert main(command) == 0
    assert (out / f"room-{SEED}-0.toml").read_bytes() == written[0].read_bytes()


def test_an_out_that_is_a_file_is_refused(tmp_path, capsys):
    (tmp_path / "file").write_text("")
    with pytest.raises(SystemExit) as refused:
        main(["worlds", "generate", "--count", "1", "--seed", "1", "--out", str(tmp_path / "file")])
    assert refused.value.code == 2 and "--out must be a folder" in capsys.readouterr().err


@pytest.mark.parametrize("suite, seed", [("dev", 1000), ("test", 2000)])
def test_the_shipped_suites_are_what_the_command_makes(suite, seed, tmp_path):
    text, _ = draw_checked_world(seed, 0, tmp_path)
    assert (WORLDS_DIR / suite / f"room-{seed}-0.toml").read_text() == text


# ----------------------------------------------------------------------------- --max-turn-deg


def _off_axis_deg(yaw_deg: float) -> float:
    return abs((yaw_deg + 45.0) % 90.0 - 45.0)


def test_the_default_turn_asked_for_draws_the_same_rooms(written):
    for seed in (3, 11, 12):
        assert _draws(seed, 3, max_turn_deg=MAX_TURN_DEG) == _draws(seed, 3)
    assert MAX_TURN_DEG == 10.0 and "--max-turn-deg" not in written[0].read_text()


def test_no_turn_faces_every_picture_along_an_axis(draws):
    targets = [d["target"] for d in _draws(11, 24, max_turn_deg=0.0)]
    assert all(t["yaw_deg"] % 90.0 == 0.0 for t in targets)
    assert any(_off_axis_deg(d["target"]["yaw_deg"]) > 0.0 for d in draws)  # the same draws, turned by default


def test_a_45_degree_turn_faces_pictures_between_the_axes_and_no_further(monkeypatch):
    turns, target_on = [], world_generator._target_on  # turns: of every target tried, from square to its edge

    def recorded(rng, support, facing, max_turn_deg):
        target = target_on(rng, support, facing, max_turn_deg)
        turns.append((target["yaw_deg"] - math.degrees(math.atan2(facing[1], facing[0])) + 180.0) % 360.0 - 180.0)
        return target
    monkeypatch.setattr(world_generator, "_target_on", recorded)
    targets = [d["target"] for d in _draws(11, 24, max_turn_deg=45.0)]
    assert max(_off_axis_deg(t["yaw_deg"]) for t in targets) > 30.0
    assert max(abs(t) for t in turns) > 40.0 and all(abs(t) <= 45.05 for t in turns)  # yaw rounded to 0.1°


def test_the_help_names_the_generators_own_turn_bounds(capsys):
    """The command's help is written before the generator is imported (it loads the renderer), so its
    numbers are literals: this keeps them the generator's."""
    with pytest.raises(SystemExit):
        main(["worlds", "generate", "--help"])
    help_text = " ".join(capsys.readouterr().out.split())  # argparse wraps lines
    assert f"0 to {TURN_LIMIT_DEG:g} (default: {MAX_TURN_DEG:g}," in help_text


@pytest.mark.parametrize("turn", ["50", "-1"])
def test_a_turn_outside_0_to_45_degrees_is_refused_by_name_before_anything_is_made(tmp_path, capsys, turn):
    with pytest.raises(SystemExit) as refused:
        main(["worlds", "generate", "--count", "1", "--seed", "1", "--out", str(tmp_path / "new"),
              "--max-turn-deg", turn])
    assert refused.value.code == 2 and f"--max-turn-deg: must be from 0 to 45, got {turn}" in capsys.readouterr().err
    with pytest.raises(ValueError, match=f"max_turn_deg must be from 0 to 45, got {turn}"):
        write_worlds(1, 1, tmp_path / "new", max_turn_deg=float(turn))
    assert not (tmp_path / "new").exists()


def test_the_command_turns_pictures_as_asked_and_the_file_says_so(tmp_path):
    assert main(["worlds", "generate", "--count", "1", "--seed", str(SEED), "--out", str(tmp_path),
                 "--max-turn-deg", "45"]) == 0
    text = (tmp_path / f"room-{SEED}-0.toml").read_text()
    assert text.startswith(f"# Generated by `syt-onboard worlds generate --seed {SEED} --max-turn-deg 45.0` (world 0")
    assert load_world(tmp_path / f"room-{SEED}-0.toml").name == f"room-{SEED}-0"

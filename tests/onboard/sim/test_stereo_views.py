"""``syt-onboard worlds views``: rendered pairs with true depth, from reachable floor, repeatable."""

from __future__ import annotations

import json

import numpy as np
import pytest

from onboard.cli import main
from onboard.sim.world import load_world
from onboard.sim.stereo_views import sample_views
from onboard.sim.world_check import reachable_floor


def _views(tmp_path, name, seed=3):
    assert main(["worlds", "views", "--worlds", "office", "--per-world", "2", "--seed", str(seed),
                 "--out", str(tmp_path / name)]) == 0
    return json.loads((tmp_path / name / "views.json").read_text())


def test_views_stand_on_reachable_floor_with_true_depth(tmp_path):
    index = _views(tmp_path, "a")
    assert len(index["views"]) == 2 and index["baseline_m"] > 0
    floor = reachable_floor(load_world("office"))
    for view in index["views"]:
        x, y, _ = view["pose"]
        assert view["world"] == "office" and floor.drivable[floor.cell(x, y)]
        depth = np.load(tmp_path / "a" / view["folder"] / "depth.npy")
        assert depth.shape == (480, 640) and np.isfinite(depth).all() and depth.min() > 0


def test_the_same_seed_gives_the_same_views(tmp_path):
    first = _views(tmp_path, "a")["views"]
    assert _views(tmp_path, "b")["views"] == first
    left = [(tmp_path / run / first[0]["folder"] / "left.png").read_bytes() for run in ("a", "b")]
    assert left[0] == left[1]
    assert _views(tmp_path, "c", seed=4)["views"] != first


def test_each_world_draws_from_the_seed_and_its_own_name():
    alone = sample_views("office", load_world("office"), 3, seed=5)
    assert sample_views("office", load_world("office"), 3, seed=5) == alone
    assert sample_views("paper-lab", load_world("paper-lab"), 3, seed=5) != alone


def test_bad_arguments_are_refused(tmp_path, capsys):
    with pytest.raises(SystemExit) as refused:
        main(["worlds", "views", "--worlds", "office", "--per-world", "0", "--out", str(tmp_path)])
    assert refused.value.code == 2 and "--per-world: must be at least 1" in capsys.readouterr().err
    assert main(["worlds", "views", "--worlds", "no-such-room", "--out", str(tmp_path)]) == 2

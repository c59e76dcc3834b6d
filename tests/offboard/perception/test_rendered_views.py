"""Scoring stereo on rendered views with true depth: a phantom wall is caught, and SGBM avoids it."""

from __future__ import annotations

import json
import shutil

import cv2
import numpy as np
import pytest

from offboard.cli import main
from offboard.perception import rendered_views
from offboard.perception.rendered_views import ViewScores, count_pixels, score_views
from offboard.perception.stereo import StereoConfig
from onboard.sim.stereo_views import View, write_view_set
from shared.geometry import Pose2D

SAD, DEFAULT = StereoConfig(method="sad", block_size=9), StereoConfig()
# dev/room-1000-0's brick wall seen square-on from 7.4 m: its texture repeats every 1.2 m, and SAD
# matches it one period over, which puts a phantom wall B / (B + 1.2 m) of the way there, 0.67 m off.
PHANTOM_VIEW = View("dev/room-1000-0", Pose2D(7.29, 6.95, -3.124), -0.15)
PLAIN_VIEW = View("dev/room-1000-0", Pose2D(2.0, 2.0, 0.5), 0.0)


@pytest.fixture(scope="module")
def views(tmp_path_factory):
    out = tmp_path_factory.mktemp("views")
    write_view_set([PHANTOM_VIEW, PLAIN_VIEW], out)
    return out


def test_pixels_are_counted_against_the_truth():
    truth = np.array([10.0, 10.0, 10.0, 10.0, 3.0, np.inf])
    disparity = np.array([10.5, 13.0, 14.0, np.nan, 8.0, 20.0])
    counts = count_pixels(disparity, truth)
    assert (counts.known, counts.answered, counts.bad) == (5, 4, 3)
    assert counts.phantom == 2  # 14 at 10 and 8 at 3; 13 at 10 is 3 px off but under 4/3 of it
    assert counts.phantom_view  # 2 of 6 pixels
    assert not count_pixels(np.array([10.5, 13.0]), np.array([10.0, 10.0])).phantom_view


def test_views_are_scored_over_their_pooled_pixels_and_a_blind_matcher_as_a_wrong_one():
    truth = np.array([10.0, 10.0, 10.0, 10.0])
    pooled = ViewScores.of([count_pixels(np.array([10.5, 13.0, np.nan, np.nan]), truth),
                            count_pixels(np.array([10.0, 10.0, 10.0, np.nan]), truth)])
    assert (pooled.bad2, pooled.density, pooled.views) == (pytest.approx(1 / 5), pytest.approx(5 / 8), 2)
    blind = ViewScores.of([count_pixels(np.full(4, np.nan), truth)])
    assert (blind.bad2, blind.density, blind.phantom_share) == (1.0, 0.0, 0.0)


def test_the_matcher_gets_each_view_in_rgb_order(tmp_path, monkeypatch):
    rgb = np.zeros((4, 6, 3), np.uint8)
    rgb[..., 0] = 200  # red: a PNG file holds it first, OpenCV reads it last
    (tmp_path / "view").mkdir()
    for name in ("left.png", "right.png"):
        cv2.imwrite(str(tmp_path / "view" / name), cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    np.save(tmp_path / "view" / "depth.npy", np.ones((4, 6), np.float32))
    (tmp_path / "views.json").write_text(json.dumps({"fx_px": 500.0, "baseline_m": 0.12,
                                                     "views": [{"world": "w", "folder": "view"}]}))
    seen = []

    class Recording:
        def __init__(self, config):
            pass

        def disparity(self, left, right):
            seen.extend([left, right])
            return np.full(left.shape[:2], np.nan)

    monkeypatch.setattr(rendered_views, "StereoMatcher", Recording)
    score_views(tmp_path, {"default": DEFAULT})
    assert len(seen) == 2 and all(np.array_equal(image, rgb) for image in seen)


def test_sad_builds_a_phantom_wall_and_the_default_does_not(views):
    scores = score_views(views, {"sad": SAD, "default": DEFAULT})
    assert scores["sad"].phantom_views == 1 and scores["sad"].phantom_share > 0.01
    assert scores["default"].phantom_views == 0 and scores["default"].phantom_share < 0.002
    for s in scores.values():
        assert s.views == 2 and s.density > 0.8


def test_the_bench_prints_both_matchers(views, capsys):
    assert main(["bench", "stereo", "--views", str(views), "--json"]) == 0
    figures = json.loads(capsys.readouterr().out)
    assert figures["default"] == "sgbm" and figures["worlds"] == ["dev/room-1000-0"]
    assert figures["sad"]["phantom_views"] == 1 and figures["sgbm"]["phantom_views"] == 0
    assert main(["bench", "stereo", "--json"]) == 2  # no --views


def test_broken_views_are_refused_by_name(views, tmp_path):
    with pytest.raises(ValueError, match="views.json"):
        score_views(tmp_path, {"default": DEFAULT})
    assert main(["bench", "stereo", "--views", str(tmp_path), "--json"]) == 2
    broken = tmp_path / "broken"
    shutil.copytree(views, broken)
    (broken / "view-0001" / "depth.npy").unlink()
    with pytest.raises(ValueError, match="view-0001.*depth.npy"):
        score_views(broken, {"default": DEFAULT})
    index = json.loads((broken / "views.json").read_text())
    del index["views"][0]["world"]
    (broken / "views.json").write_text(json.dumps(index))
    with pytest.raises(ValueError, match="views.json"):
        score_views(broken, {"default": DEFAULT})

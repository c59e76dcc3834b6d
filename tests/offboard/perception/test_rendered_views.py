"""Scoring stereo on rendered views with true depth: a phantom wall is caught, and SGBM avoids it."""

from __future__ import annotations

import json
import math
import shutil

import pytest

from offboard.cli import main
from offboard.perception.rendered_views import score_views
from offboard.perception.stereo import StereoConfig
from onboard.config import CameraConfig
from onboard.sim.preview import write_preview
from onboard.sim.world import load_world
from shared.geometry import Pose2D

# dev/room-1000-0's far wall seen square-on from 7 m: its texture repeats every 0.8 m, and SAD
# matches it one period over, which puts a phantom wall 0.65 m in front of the camera.
PHANTOM_VIEW = (Pose2D(7.29, 6.95, -3.124), -0.15)
PLAIN_VIEW = (Pose2D(2.0, 2.0, 0.5), 0.0)


@pytest.fixture(scope="module")
def views(tmp_path_factory):
    out = tmp_path_factory.mktemp("views")
    camera = CameraConfig()
    world = load_world("dev/room-1000-0")
    entries = []
    for k, (pose, tilt) in enumerate((PHANTOM_VIEW, PLAIN_VIEW)):
        write_preview(world, pose, 0.0, tilt, out / f"view-{k}", camera.intrinsics(), camera.mount())
        entries.append({"world": "dev/room-1000-0", "pose": [pose.x_m, pose.y_m, math.degrees(pose.heading_rad)],
                        "tilt_deg": math.degrees(tilt), "folder": f"view-{k}"})
    (out / "views.json").write_text(json.dumps({"seed": None, "fx_px": camera.intrinsics().fx_px,
                                                "baseline_m": camera.baseline_m, "views": entries}))
    return out


def test_sad_builds_a_phantom_wall_and_the_default_does_not(views):
    sad = score_views(views, StereoConfig(method="sad", block_size=9))
    default = score_views(views, StereoConfig())
    assert sad.phantom_views == 1 and sad.phantom_share > 0.01
    assert default.phantom_views == 0 and default.phantom_share < 0.002
    for scores in (sad, default):
        assert scores.views == 2 and scores.density > 0.8


def test_the_bench_prints_both_matchers(views, capsys):
    assert main(["bench", "stereo", "--views", str(views), "--json"]) == 0
    figures = json.loads(capsys.readouterr().out)
    assert figures["default"] == "sgbm" and figures["worlds"] == ["dev/room-1000-0"]
    assert figures["sad"]["phantom_views"] == 1 and figures["sgbm"]["phantom_views"] == 0


def test_a_directory_without_views_is_refused_by_name(tmp_path):
    with pytest.raises(ValueError, match="views.json"):
        score_views(tmp_path, StereoConfig())
    assert main(["bench", "stereo", "--views", str(tmp_path), "--json"]) == 2


def test_a_view_with_missing_depth_is_refused_by_name(views, tmp_path):
    broken = tmp_path / "broken"
    shutil.copytree(views, broken)
    (broken / "view-1" / "depth.npy").unlink()
    with pytest.raises(ValueError, match="view-1.*depth.npy"):
        score_views(broken, StereoConfig())

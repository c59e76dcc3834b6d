"""The detector's table checked where the target was: the table's rate from the true camera of each look,
against whether the detector fired, before and after a run's first miss in view, and by distance and angle."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest

from offboard.experiments.calibration import Look, parse_look
from offboard.experiments.target_views import (by_distance, by_off_normal, by_rate, target_view, target_views,
                                               target_views_md, viewed_runs)
from offboard.experiments.world_facts import Obstacle, Truth, detector_table
from offboard.perception.detectability import DetectabilityTable
from shared.world import WORLDS_DIR

TABLE = DetectabilityTable.nominal(near_m=0.5, far_m=4.0, peak=0.95, max_facing_deg=70.0)
# a 6 × 5 m room; the target's centre at the camera's 1.2 m, its picture facing -y
TRUTH = Truth((6.0, 5.0, 2.5), (), (3.0, 4.0, 1.2), -90.0)
TABLE_TOP = replace(TRUTH, target_center_m=(3.0, 4.0, 0.74 + 0.115))  # standing on a desk, 0.35 m below the camera


def _look(x: float, y: float, heading_deg: float, pan_deg: float = 0.0, detected: bool = False,
          tilt_deg: float = 0.0) -> Look:
    return Look(1, 0.1, 0.1, detected, 1.0, 1.0, (x, y, heading_deg), (x, y, heading_deg), (pan_deg, tilt_deg))


def test_a_look_at_the_picture_gets_the_tables_rate_and_one_away_or_blocked_gets_none():
    head_on = target_view(TRUTH, _look(3.0, 2.0, 90.0), TABLE)  # 1.9 m in front, on the optical axis
    assert head_on.rate == TABLE.lookup([1.885], [0.0], [0.0])[0] > 0.8
    assert head_on.distance_m == pytest.approx(1.885, abs=0.01) and head_on.off_normal_deg < 2.0
    oblique = target_view(TRUTH, _look(1.586, 2.471, 0.0, pan_deg=45.0), TABLE)  # 2 m away, 45° off the normal
    assert 0.0 < oblique.rate < head_on.rate and oblique.off_normal_deg == pytest.approx(45.0, abs=2.5)
    assert target_view(TRUTH, _look(3.0, 2.0, -90.0), TABLE) is None  # it looks away
    assert target_view(TRUTH, _look(3.0, 2.0, 90.0, tilt_deg=40.0), TABLE) is None  # the picture below the image
    assert target_view(TRUTH, _look(3.0, 4.8, -90.0), TABLE).rate == 0.0  # behind the picture: its back
    wall = Truth(TRUTH.room_m, (Obstacle((2.0, 3.0, 0.0), (4.0, 3.1, 2.0)),), TRUTH.target_center_m, -90.0)
    assert target_view(wall, _look(3.0, 2.0, 90.0), TABLE) is None  # a partition in between
    untracked = Look(1, 0.1, 0.1, False, 1.0, 1.0, (3.0, 2.0, 90.0), None, (0.0, 0.0))  # outside the harness
    assert target_view(TRUTH, untracked, TABLE) is None


def test_looks_are_binned_by_table_rate_and_split_at_the_runs_first_miss_in_view():
    away = _look(3.0, 2.0, -90.0)  # not in view: counted as logged, not binned
    near, far = _look(3.0, 2.0, 90.0), _look(3.0, 0.3, 90.0)  # rates above 0.8, and lower at 3.6 m
    found = replace(near, detected=True)
    again = replace(found, action=9)  # the same view taken again: the same image, so no new draw
    viewed, logged, repeated = target_views([(TRUTH, [away, far, found, again], TABLE), (TRUTH, [found], TABLE)])
    assert logged == 5 and len(viewed) == 3 and repeated == 1  # run 1's view is its own first
    rates = by_rate(viewed)
    top, far_rate = rates[-1], target_view(TRUTH, far, TABLE).rate
    low = next(g for g in rates if far_rate in [v.view.rate for v in g.looks])
    assert [(v.detected, v.after_miss) for v in low.looks] == [(False, False)]
    assert [(v.detected, v.after_miss) for v in top.looks] == [(True, True), (True, False)]  # run 0's came after its miss
    assert top.detection_rate() == 1.0 and top.count(True) == 1 and top.runs == 2 and low.detection_rate() == 0.0
    assert [len(g.looks) for g in by_distance(viewed)] == [2, 1, 0]  # under 2 m, 2-4 m, 4 m or more
    assert [len(g.looks) for g in by_off_normal(viewed)] == [3, 0, 0]  # all nearly head-on
    text = "\n".join(target_views_md(viewed, logged, repeated, "two runs"))
    assert "5 looks logged" in text and "in 3 of them" in text and "1 more looks in view repeated one" in text
    assert "| [0.8, 1] | 2 (2) | " in text and "| 1.00 (1) | 1.00 (1) |" in text
    assert "| [2, 4) m | 1 (1) | " in text and "| ≥ 4 m | 0 (0) | — | — |" in text and "| [60, 90]° | 0 (0) |" in text
    assert target_views_md(viewed, 0, 0, "an old sweep") == []  # looks from before the head's angles were logged


def test_a_look_logs_the_heads_angles_and_a_malformed_one_is_refused():
    line = {"action": 1, "expected_p": 0.1, "realised_p": 0.1, "detected": False, "processing_s": 1.0,
            "motion_s": 1.0, "pan_deg": 12.5, "tilt_deg": 30.0}
    assert parse_look(json.dumps(line)).head_deg == (12.5, 30.0)
    with pytest.raises(ValueError, match="run/looks.jsonl:3: tilt_deg = 'up' is not a finite float"):
        parse_look(json.dumps({**line, "tilt_deg": "up"}), "run/looks.jsonl:3")
    with pytest.raises(ValueError, match="pan_deg = None"):  # one angle without the other
        parse_look(json.dumps({k: v for k, v in line.items() if k != "pan_deg"}))


def test_a_run_whose_truth_cannot_be_had_is_left_out_by_name_and_the_rest_kept():
    seen = [_look(3.0, 2.0, 90.0)]
    row = {"key": "ok", "world": "office", "target": "4.3,2.6,0.74,-90", "detector": "sift"}
    rows = [row, {**row, "key": "gone", "world": "test/room-9999-0"}, {**row, "key": "short", "target": "1,2,3"},
            {**row, "key": "nan", "target": "nan,nan,nan,nan"}, {**row, "key": "auto", "detector": "auto"},
            {**row, "key": "old", "world": "nowhere"}]
    runs, left_out = viewed_runs(rows, [seen] * 5 + [[replace(seen[0], head_deg=None)]])  # "old": no angles logged
    assert len(runs) == 1 and runs[0][0].target_center_m[:2] == (4.3, 2.6)
    assert [why.split(":")[0] for why in left_out] == ["gone", "short", "nan", "auto"]
    assert "room-9999-0" in left_out[0] and "'1,2,3' is not x,y,z,yaw" in left_out[1]
    assert left_out[3] == "auto: detector 'auto' has no table of its own"  # not merely a table missing
    text = "\n".join(target_views_md(*target_views(runs), "six runs", left_out))
    assert "Left out (4 runs):" in text and "- nan: target 'nan,nan,nan,nan' is not x,y,z,yaw" in text


def test_a_look_off_the_optical_axis_gets_the_tables_rate_for_that_angle():
    askew = target_view(TRUTH, _look(3.0, 0.5, 90.0, pan_deg=27.5), TABLE)  # 3.4 m away, near the image's edge
    head_on = target_view(TRUTH, _look(3.0, 0.5, 90.0), TABLE)
    assert 25.0 < askew.off_axis_deg < 30.0 and askew.off_normal_deg < 2.0
    assert askew.rate == TABLE.lookup([askew.distance_m], [27.5], [0.0])[0] < head_on.rate


def test_the_angle_off_the_normal_counts_the_cameras_height_above_the_picture():
    view = target_view(TABLE_TOP, _look(3.0, 3.0, 90.0, tilt_deg=-20.0), TABLE)  # 0.9 m in front, 0.35 m above
    assert view.off_normal_deg == pytest.approx(21.3, abs=1.0)  # straight ahead, but seen from above
    assert view.rate < TABLE.lookup([view.distance_m], [view.off_axis_deg], [0.0])[0]


@pytest.mark.parametrize("tilt_deg, in_view", [(-14.0, True), (14.0, False)])
def test_a_head_tilted_down_sees_a_target_on_a_table_and_one_tilted_up_does_not(tilt_deg, in_view):
    view = target_view(TABLE_TOP, _look(3.0, 2.0, 90.0, tilt_deg=tilt_deg), TABLE)  # 10° below, 1.9 m away
    assert (view is not None and view.rate > 0.8) == in_view


@pytest.mark.parametrize("pan_deg, in_view", [(29.5, True), (31.5, False)])
def test_a_picture_whose_centre_is_in_the_image_but_a_side_is_not_is_out_of_view(pan_deg, in_view):
    # at 31.5° the centre projects at u = 632 of 640, the corners on its right at 653
    assert (target_view(TRUTH, _look(3.0, 0.5, 90.0, pan_deg=pan_deg), TABLE) is not None) == in_view


def test_an_obstacle_hiding_one_corner_of_the_picture_puts_it_out_of_view():
    post = Obstacle((3.04, 3.5, 1.25), (3.2, 3.6, 1.4))  # crosses the line to one corner only, not the centre's
    assert target_view(replace(TRUTH, obstacles=(post,)), _look(3.0, 2.0, 90.0), TABLE) is None
    assert target_view(TRUTH, _look(3.0, 2.0, 90.0), TABLE) is not None


def test_a_four_sided_target_is_seen_by_its_best_face():
    side = _look(5.0, 4.0, 180.0)  # 2 m along +x, looking at the target from its side
    assert target_view(TRUTH, side, TABLE).rate == 0.0  # one picture, seen edge-on
    four = target_view(replace(TRUTH, target_sides=4), side, TABLE)
    assert four.rate > 0.8 and four.off_normal_deg < 2.0  # the picture facing +x, head-on


def test_a_back_view_is_logged_but_not_counted_in_view():
    back = _look(3.0, 4.8, -90.0)  # behind the picture: its table rate is 0
    assert target_views([(TRUTH, [back], TABLE)]) == ([], 1, 0)


@pytest.mark.parametrize("look", [_look(3.0, 2.0, -90.0), _look(3.0, 4.8, -90.0)], ids=["away", "back"])
def test_a_look_out_of_view_taken_again_is_not_a_repeated_view(look):
    assert target_views([(TRUTH, [look, replace(look, action=2)], TABLE)]) == ([], 2, 0)


def test_every_look_after_a_runs_first_miss_in_view_counts_as_after_a_miss():
    looks = [_look(3.0, y, 90.0, detected=hit) for y, hit in ((0.5, False), (1.0, True), (1.5, False), (2.0, True))]
    viewed, _, _ = target_views([(TRUTH, looks, TABLE)])
    assert [v.after_miss for v in viewed] == [False, True, True, True]  # the last hit too, after a hit


def test_a_runs_table_is_rescaled_to_its_targets_face(tmp_path):
    world = tmp_path / "big-target.toml"  # the office with a 0.3 m target in place of its 0.23 m one
    world.write_text((WORLDS_DIR / "office.toml").read_text().replace("size = [0.23, 0.23, 0.23]",
                                                                      "size = [0.3, 0.3, 0.3]"))
    row = {"key": "big", "world": str(world), "target": "4.3,2.6,0.74,-90", "detector": "sift"}
    [(_, _, table)], _ = viewed_runs([row], [[_look(3.0, 2.0, 90.0)]])
    shipped = detector_table("sift")  # measured with a 0.23 m face: a 0.3 m one is seen as well 0.3 / 0.23 as far
    assert shipped.face_size_m == 0.23
    assert table.distance_edges_m == pytest.approx(shipped.distance_edges_m * 0.3 / 0.23)

"""The detectability tables shipped for the default target: measured by ``calibrate-detector`` on
rendered views, and what the search loads when no table is given."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from offboard.perception.detectability import DetectabilityTable, bin_index, face_size_m
from offboard.perception.detection.detector import shipped_table
from offboard.perception.detection.target_model import TargetModel
from offboard.search.run import SearchRequest, build_detectors, detectability_table
from shared.geometry import Intrinsics


def shipped(name: str) -> DetectabilityTable:
    table = shipped_table(name)
    assert table is not None, f"no table shipped for {name}"
    return table


def _cells(table: DetectabilityTable, near_m: float, far_m: float, max_facing_deg: float) -> tuple[np.ndarray, ...]:
    d = (table.distance_edges_m[:-1] >= near_m) & (table.distance_edges_m[1:] <= far_m)
    f = table.facing_edges_deg[1:] <= max_facing_deg
    return table.rate[d][:, :, f], table.samples[d][:, :, f]


@pytest.mark.parametrize("name", ["sift", "ncc"])
def test_each_detector_ships_a_measured_table_without_false_detections(name):
    table = shipped(name)
    assert table.detector == name and table.false_positive_rate == 0.0
    assert table.samples.sum() >= 800  # every cell measured, not a nominal stand-in
    assert 0.0 < table.cost_ms < 1000.0


def test_sift_finds_the_target_within_2_5_m_and_45_degrees():
    # rates pooled over neighbouring cells with a uniform prior: 0.97 where every view found it
    rate, views = _cells(shipped("sift"), 0.5, 2.5, 40.0)  # facing bins up to 40°: the "under 45°"
    assert views.sum() >= 100 and rate.min() >= 0.9


def test_detection_fades_with_distance_and_grazing_views():
    table = shipped("sift")
    near, _ = _cells(table, 0.5, 2.0, 30.0)
    far, _ = _cells(table, 5.0, 6.0, 30.0)
    assert near.mean() > 0.9 > 0.2 > far.mean()
    assert table.rate[:, :, -1].mean() < 0.05  # 80-90° off the face's normal: (almost) never


class _NoDetector:
    range_m, cost_ms = (0.3, 3.0), 40.0


def test_the_search_loads_the_shipped_table_unless_given_one(tmp_path):
    on_disk = shipped_table.__wrapped__("sift")  # uncached: read from the file again
    assert np.array_equal(detectability_table("sift", _NoDetector(), {}).rate, on_disk.rate)
    nominal = DetectabilityTable.nominal("sift")
    nominal.save(tmp_path / "mine.json")
    given = detectability_table("sift", _NoDetector(), {"sift": tmp_path / "mine.json"})
    assert np.array_equal(given.rate, nominal.rate)


def test_a_table_holds_for_its_face_size_and_a_face_half_as_large_is_found_from_half_as_far():
    table = shipped("sift")
    assert table.face_size_m == 0.23  # calibrate-detector's default target
    half = table.for_face(0.115)
    distances = np.array([0.6, 1.3, 2.7, 3.9, 4.6])
    off_axis, facing = np.full(5, 10.0), np.full(5, 25.0)
    assert np.array_equal(half.lookup(distances / 2, off_axis, facing), table.lookup(distances, off_axis, facing))
    assert half.lookup(np.array([4.0]), off_axis[:1], facing[:1])[0] < 0.05 < table.lookup(np.array([4.0]), off_axis[:1], facing[:1])[0]
    assert half.range_m == pytest.approx(tuple(d / 2 for d in table.range_m))
    assert table.for_face(0.23) is table
    nominal = DetectabilityTable.nominal()  # of no particular size: it holds for any
    assert nominal.for_face(0.1) is nominal
    with pytest.raises(ValueError, match="positive"):
        table.for_face(0.0)


def test_a_table_keeps_its_face_size_on_disk_and_an_older_file_holds_for_any(tmp_path):
    shipped("sift").for_face(0.3).save(tmp_path / "t.json")
    assert DetectabilityTable.load(tmp_path / "t.json").face_size_m == 0.3
    data = json.loads((tmp_path / "t.json").read_text())
    del data["face_size_m"]
    (tmp_path / "old.json").write_text(json.dumps(data))
    assert DetectabilityTable.load(tmp_path / "old.json").face_size_m is None


def test_the_search_rescales_the_table_to_its_target():
    picture = np.random.default_rng(0).integers(0, 255, (120, 120, 3), np.uint8)
    small = TargetModel((picture,), (0.3, 0.1, 0.16))  # 0.3 m deep, its face 0.1 m wide and 0.16 m high
    request = SearchRequest(pictures=(), target_size_m=small.size_m)
    (_, table), = build_detectors("sift", request, small, Intrinsics.from_fov(640, 480, 66.0)).values()
    assert table.face_size_m == face_size_m(0.1, 0.16) == pytest.approx(0.1265, abs=1e-4)
    assert np.allclose(table.distance_edges_m, shipped("sift").distance_edges_m * table.face_size_m / 0.23)


@pytest.mark.parametrize("edges_deg", [np.arange(0.0, 91.0, 10.0), np.linspace(0.0, 45.0, 10), np.arange(20.0, 61.0, 5.0)])
def test_binning_an_angle_by_its_cosine_gives_its_bin(edges_deg):
    from offboard.perception.detectability import bin_index, cosine_bin

    angles = np.concatenate([np.linspace(0.0, 180.0, 3601), edges_deg[1:-1] + 1e-6, edges_deg[1:-1] - 1e-6])
    cos_edges = np.cos(np.radians(edges_deg))
    got = [cosine_bin(cos_edges, float(np.cos(np.radians(a)))) for a in angles]
    want = [bin_index(edges_deg, float(a)) for a in angles]
    assert got == want
    assert cosine_bin(cos_edges, 1.0) == (0 if edges_deg[0] == 0 else -1)  # head-on: the first bin, if it has 0°


@pytest.mark.parametrize("face_m", [0.17, 0.3])
def test_the_table_and_the_planners_kernel_put_a_bin_edge_in_the_same_bin(face_m):
    """A table rescaled for another face has edges that are not exact multiples of its step; the
    planner (``bin_index``) and the yardsticks (``lookup``) must still read the same cell there."""
    table = shipped("sift").for_face(face_m)
    edges = table.distance_edges_m
    distances = np.concatenate([edges, np.nextafter(edges, np.inf), np.nextafter(edges, -np.inf)])
    off_axis = np.full_like(distances, 2.0)
    facing = np.full_like(distances, 5.0)
    planner = np.array([table.rate[i, 0, 0] if (i := bin_index(edges, d)) >= 0 else 0.0 for d in distances])
    assert np.array_equal(table.lookup(distances, off_axis, facing), planner)


@pytest.mark.parametrize(("field", "value"), [("false_positive_rate", float("nan")), ("false_positive_rate", 1.5),
                                              ("cost_ms", -5.0), ("cost_ms", float("inf"))])
def test_a_table_with_an_impossible_rate_or_cost_is_refused_by_name(field, value):
    with pytest.raises(ValueError, match=field):
        dataclasses.replace(shipped("sift"), **{field: value})



def _step_table(max_facing_deg: float, axis_deg: float = 90.0) -> DetectabilityTable:
    """Found for sure at 1-2 m up to ``max_facing_deg`` off the normal, never beyond (nor past the
    facing axis, ``axis_deg``)."""
    facing = np.arange(0.0, axis_deg + 1.0, 10.0)
    rate = np.zeros((1, 1, len(facing) - 1))
    rate[..., facing[1:] <= max_facing_deg] = 1.0
    return DetectabilityTable("step", np.array([1.0, 2.0]), np.array([0.0, 35.0]), facing, rate,
                              np.ones(rate.shape, int), 0.0, 10.0)


def test_a_sector_is_found_as_often_as_the_facings_in_it_on_average():
    table = _step_table(90.0).for_sectors(8)  # 45° sectors; found from any facing the axis measures
    rate = table.rate[0, 0]
    centre = (table.facing_edges_deg[:-1] + table.facing_edges_deg[1:]) / 2
    share = np.clip((90.0 - (centre - 22.5)) / 45.0, 0.0, 1.0)  # of the sector within 90° of the view
    assert table.facing_edges_deg[-1] == 110.0  # a look 100-110° off a sector's centre sees its near edge
    assert np.allclose(rate, share, atol=0.02)  # and past the measured 90°, nothing is found
    assert rate[centre < 67.5].min() == 1.0 and 0.1 < rate[-1] < 0.2


def test_a_facing_past_half_a_turn_is_the_same_angle_the_other_way():
    table = _step_table(180.0, axis_deg=180.0).for_sectors(2)  # found from every side, 180° sectors
    assert table.facing_edges_deg[-1] == 180.0 and np.all(table.rate == 1.0)


def test_facings_a_sector_is_never_found_from_are_left_off_the_axis():
    table = _step_table(60.0).for_sectors(8)
    assert table.facing_edges_deg[-1] == 80.0  # 80° off its centre, a sector is 60° off or more everywhere
    assert table.rate[0, 0, -1] > 0.0


def test_a_target_that_faces_the_camera_keeps_the_table_as_measured():
    table = _step_table(60.0)
    assert table.for_sectors(1) is table
    with pytest.raises(ValueError, match="at least one facing sector"):
        table.for_sectors(0)

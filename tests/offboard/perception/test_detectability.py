"""The detectability tables shipped for the default target: measured by ``calibrate-detector`` on
rendered views, and what the search loads when no table is given."""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from offboard.perception.detectability import DetectabilityTable
from offboard.search.run import detectability_table


def shipped(name: str) -> DetectabilityTable:
    return DetectabilityTable.load(Path(str(resources.files("offboard.perception.detection") / "tables" / f"{name}.json")))


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
    assert np.array_equal(detectability_table("sift", _NoDetector(), {}).rate, shipped("sift").rate)
    nominal = DetectabilityTable.nominal("sift")
    nominal.save(tmp_path / "mine.json")
    given = detectability_table("sift", _NoDetector(), {"sift": tmp_path / "mine.json"})
    assert np.array_equal(given.rate, nominal.rate)


@pytest.mark.parametrize("edges_deg", [np.arange(0.0, 91.0, 10.0), np.linspace(0.0, 45.0, 10), np.arange(20.0, 61.0, 5.0)])
def test_binning_an_angle_by_its_cosine_gives_its_bin(edges_deg):
    from offboard.perception.detectability import bin_index, cosine_bin

    angles = np.concatenate([np.linspace(0.0, 180.0, 3601), edges_deg[1:-1] + 1e-6, edges_deg[1:-1] - 1e-6])
    cos_edges = np.cos(np.radians(edges_deg))
    got = [cosine_bin(cos_edges, float(np.cos(np.radians(a)))) for a in angles]
    want = [bin_index(edges_deg, float(a)) for a in angles]
    assert got == want
    assert cosine_bin(cos_edges, 1.0) == (0 if edges_deg[0] == 0 else -1)  # head-on: the first bin, if it has 0°

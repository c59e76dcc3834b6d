"""The SYT planner on small hand-built maps whose right answers are known."""

from __future__ import annotations

import math
import re
from dataclasses import replace

import numpy as np
import pytest

from offboard.planning.belief import TargetBelief
from offboard.perception.detectability import DetectabilityTable
from offboard.planning.detection_function import look_footprint, visible_depth
from offboard.perception.occupancy import OccupancyGrid
from offboard.planning.planner import PlannerConfig, SearchPlanner
from offboard.planning.viewpoints import grid_vertices
from offboard.planning.priors import HintBox, hints
from offboard.planning.time_model import TimeModel
from offboard.perception.voxel_grid import VoxelGrid
from shared.geometry import HeadMount, Intrinsics, Pose2D
from shared.limits import BaseLimits, CameraTiming, PanTiltLimits

K = Intrinsics.from_fov(640, 480, 66.0)
MOUNT = HeadMount()
ROOM = VoxelGrid((6.0, 4.0, 2.5), 0.05)
TIME = TimeModel(BaseLimits(), PanTiltLimits(), CameraTiming())
# Each box sits at head height in the middle of a grid square: the four candidates around it see it
# from 0.7 m, no other candidate is within the detector's 1.5 m.
A_BOX = HintBox((4.4, 2.4, 1.1), (4.6, 2.6, 1.3), 0.6)  # far from the start: nearest viewpoint 3.8 m
B_BOX = HintBox((2.4, 1.4, 1.1), (2.6, 1.6, 1.3), 0.3)  # nearer: 1.6 m


def _planner(cost: int, boxes=(A_BOX, B_BOX), table=None, **config) -> SearchPlanner:
    belief = TargetBelief(ROOM, facing_sectors=1, prob_outside=0.0)
    belief.set_prior(hints(ROOM, boxes), prob_outside=0.0)
    return SearchPlanner(belief, PlannerConfig(cost_function=cost, **config),
                         table or DetectabilityTable.nominal(near_m=0.3, far_m=1.5, max_facing_deg=90), TIME, K, MOUNT)


def _paths(planner: SearchPlanner, pose: Pose2D) -> np.ndarray:
    return np.hypot(planner.positions[:, 0] - pose.x_m, planner.positions[:, 1] - pose.y_m)


START = Pose2D(0.5, 0.5, 0.0)  # nothing within reach of the start: the robot must move


@pytest.mark.parametrize("cost,near", [(1, A_BOX), (2, A_BOX), (3, B_BOX), (4, A_BOX)])
def test_each_cost_function_picks_what_its_equation_says(cost, near):
    # eq. 10: 0.6 > 0.3; eq. 11: 0.3 / 1.6 > 0.6 / 3.8; eq. 12: 0.6 (1 + 1/3.8) > 0.3 (1 + 1/1.6);
    # eq. 9: the single best action sees A's larger mass.
    planner = _planner(cost)
    d = planner.decide(START, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), _paths(planner, START))
    assert d.kind == "move"
    box_center = (np.array(near.min[:2]) + np.array(near.max[:2])) / 2
    assert np.hypot(*(np.array(d.position_m) - box_center)) < 1.0, d.reason
    assert d.find_prob > 0.1


@pytest.mark.parametrize("cost,near", [(2, A_BOX), (3, B_BOX), (4, B_BOX)])
def test_eq12_bonus_for_nearness_can_outweigh_a_larger_covering_far_away(cost, near):
    """Eq. 12 read as eq. 10 (covering alone) or as covering × (1 + distance) passed."""
    # A 0.5 at 3.8 m, B 0.4 at 1.6 m: eq. 10 takes A; eq. 12: 0.5 (1 + 1/3.8) < 0.4 (1 + 1/1.6)
    planner = _planner(cost, boxes=(replace(A_BOX, weight=0.5), replace(B_BOX, weight=0.4)))
    d = planner.decide(START, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), _paths(planner, START))
    box_center = (np.array(near.min[:2]) + np.array(near.max[:2])) / 2
    assert d.kind == "move" and np.hypot(*(np.array(d.position_m) - box_center)) < 1.0, d.reason


def test_a_one_sided_target_is_worth_a_look_from_in_front_of_its_face_only():
    """A facing cosine of the wrong sign (faces seen from behind) passed: every decision had one sector."""
    belief = TargetBelief(ROOM, facing_sectors=8, prob_outside=0.0)
    belief.set_prior(hints(ROOM, (replace(B_BOX, weight=1.0),)), prob_outside=0.0)
    box = np.flatnonzero(belief.target_prob.reshape(-1) > 0)
    facing_x = np.zeros((len(box), 8))
    facing_x[:, 0] = 1.0  # sector 0: the face's normal points along +x
    belief.observe(box, facing_x)
    planner = SearchPlanner(belief, PlannerConfig(), DetectabilityTable.nominal(near_m=0.3, far_m=1.5, max_facing_deg=90),
                            TIME, K, MOUNT)
    planner.positions = np.array([[3.2, 1.5], [1.8, 1.5]])  # 0.7 m in front of the box's face, 0.7 m behind it
    d = planner.decide(START, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), _paths(planner, START))
    front, back = d.values.find_prob[:2].max(axis=1)
    assert front > 0.5 and back < 0.01
    assert d.kind == "move" and d.position_m == (3.2, 1.5), d.reason
    assert abs(np.angle(np.exp(1j * (d.azimuth_rad - math.pi)))) <= math.radians(25.0)  # looking back along -x


@pytest.mark.parametrize("lengths", [np.zeros(1), np.zeros((15, 1)), np.zeros(16)])
def test_path_lengths_of_another_shape_than_one_per_candidate_are_refused(lengths):
    """A length-1 array was broadcast over every candidate."""
    planner = _planner(3)
    assert len(planner.positions) == 15
    with pytest.raises(ValueError, match=r"path_lengths_m must have one length per candidate position, shape \(15,\)"):
        planner.decide(START, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), lengths)


def test_the_paper_lab_has_544_actions():
    belief = TargetBelief(VoxelGrid((9.0, 5.0, 2.5), 0.05))
    planner = SearchPlanner(belief, PlannerConfig(), DetectabilityTable.nominal(), TIME, K, MOUNT)
    assert len(grid_vertices((9.0, 5.0, 2.5), 1.0)) == 32 and len(planner.settings) == 17
    assert planner.action_count == 544


@pytest.mark.parametrize("cost", [1, 3])
def test_a_room_with_no_other_position_to_go_to_is_searched_from_where_the_robot_stands(cost):
    """A 6 × 2 m room on a 2 m grid has no interior vertex; with no viewpoint either, the planner
    crashed on the empty candidate set."""
    grid = VoxelGrid((6.0, 2.0, 2.5), 0.1)
    assert grid_vertices(grid.size_m, 2.0).shape == (0, 2)
    belief = TargetBelief(grid, facing_sectors=1)
    planner = SearchPlanner(belief, PlannerConfig(cost_function=cost, grid_spacing_m=2.0, viewpoints=0),
                            DetectabilityTable.nominal(), TIME, K, MOUNT)
    occupancy = OccupancyGrid(grid)
    pose = Pose2D(3.0, 1.0, 0.0)
    planner.plan_positions(pose, occupancy.floor_map(0.3, 1.35), 0.3)
    decision = planner.decide(pose, 0.0, 0.0, 0.0, occupancy, np.zeros(0))
    assert decision.kind == "look" and decision.find_prob > 0 and "no other position" in decision.reason


def test_a_hinted_region_is_looked_at_first():
    planner = _planner(3, boxes=(HintBox((1.8, 2.6, 0.9), (2.2, 3.0, 1.2), 0.9),))
    pose = Pose2D(2.0, 1.5, 0.0)  # the hint is 1.3 m to the robot's left (+y)
    d = planner.decide(pose, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), _paths(planner, pose))
    assert d.kind == "look" and abs(math.degrees(d.azimuth_rad) - 90.0) <= 25.0


def _wall_between(occ: OccupancyGrid) -> None:
    """Observe a wall at x = 1.5 m across the room, seen from x = 0.5."""
    cam = MOUNT.camera_in_world(Pose2D(0.5, 2.0, 0.0), 0.0, 0.0)
    occ.integrate_disparity(np.full((480, 640), K.fx_px * MOUNT.baseline_m / 1.0, np.float32), K, MOUNT.baseline_m, cam)


def test_cubes_behind_a_wall_are_worth_nothing():
    box = (HintBox((2.0, 1.9, 1.0), (2.2, 2.1, 1.2), 0.95),)
    open_room, walled = OccupancyGrid(ROOM), OccupancyGrid(ROOM)
    for _ in range(3):
        _wall_between(walled)
    pose = Pose2D(0.8, 2.0, 0.0)
    planner = _planner(3, boxes=box)
    seen = planner.decide(pose, 0.0, 0.0, 0.0, open_room, _paths(planner, pose))
    hidden = planner.decide(pose, 0.0, 0.0, 0.0, walled, _paths(planner, pose))
    assert seen.values.find_prob[-1].max() > 0.3
    assert hidden.values.find_prob[-1].max() < 0.02 and hidden.values.covering_prob[-1] < 0.05


def test_a_place_nothing_has_looked_at_keeps_its_probability():
    planner = _planner(3, boxes=(), table=DetectabilityTable.nominal())
    belief = planner.belief
    occ = OccupancyGrid(ROOM)
    corner = ROOM.index_of(np.array([[5.8, 3.8, 0.2]]))[0]
    middle = ROOM.index_of(np.array([[3.0, 2.0, 1.2]]))[0]
    before_corner = belief.target_prob[tuple(corner)]
    for azimuth in (0.0, 1.5, 3.0):  # three looks from the west side, none reaching the far corner
        cam = MOUNT.camera_in_world(Pose2D(1.0, 2.0, azimuth), 0.0, 0.0)
        depth = visible_depth(None, occ, cam, K, MOUNT.baseline_m, 16, 3.5)
        fp = look_footprint(ROOM, cam, K, depth, 16, planner.table, belief.facing_azimuths_rad, 0.1)
        assert corner @ [ROOM.shape[1] * ROOM.shape[2], ROOM.shape[2], 1] not in set(fp.cube_index)
        belief.update_after_miss(fp.cube_index, fp.detection_prob)
    assert belief.target_prob[tuple(corner)] > before_corner  # it keeps (and gains) probability
    assert belief.target_prob[tuple(middle)] < before_corner  # what was seen lost


def test_the_threshold_rule_moves_once_the_covering_probability_drops_below_theta_move():
    planner = _planner(3, boxes=(HintBox((1.8, 2.6, 0.9), (2.2, 3.0, 1.2), 0.5),), move_threshold=0.3,
                       move_rule="threshold")
    pose = Pose2D(2.0, 1.5, 0.0)
    d = planner.decide(pose, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), _paths(planner, pose))
    assert d.kind == "look" and d.covering_here >= 0.3
    higher = _planner(3, boxes=(HintBox((1.8, 2.6, 0.9), (2.2, 3.0, 1.2), 0.5),), move_threshold=0.95,
                      move_rule="threshold")
    d2 = higher.decide(pose, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), _paths(higher, pose))
    assert d2.kind == "move" and "Θ_move" in d2.reason


def test_stops_when_the_budget_is_spent_or_nothing_is_left():
    planner = _planner(3, budget_s=10.0)
    assert planner.decide(START, 0.0, 0.0, 9.9, OccupancyGrid(ROOM), _paths(planner, START)).status == "budget"
    empty = _planner(3)
    empty.belief.set_prior(np.zeros(ROOM.shape), prob_outside=0.0)  # all the mass outside the room
    d = empty.decide(START, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), _paths(empty, START))
    assert d.kind == "stop" and d.status == "exhausted" and "reachable on the map" not in d.reason
    boxed_in = _planner(3)  # the mass is far away and the map shows no way there
    d = boxed_in.decide(START, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), np.full(len(boxed_in.positions), np.inf))
    others = int(np.sum(np.hypot(*(boxed_in.positions - (START.x_m, START.y_m)).T) > 0.5))
    assert d.status == "exhausted" and f"; 0 of {others} positions are reachable on the map, and an unreachable one " \
        "would find the target with probability 0." in d.reason, d.reason


def test_a_search_boxed_in_by_its_map_says_so_where_positions_near_it_are_reachable():
    # all the mass is at A; the map lets the robot reach only the positions within 1.2 m of it,
    # which cannot see A: the search stops, and says that it is the map, not the room, that ran out
    planner = _planner(3, boxes=(replace(A_BOX, weight=1.0),))
    paths = _paths(planner, START)
    near = paths < 1.2
    paths[~near] = np.inf
    d = planner.decide(START, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), paths)
    reachable = int(np.sum(near & (paths > 0.5)))
    assert d.kind == "stop" and d.status == "exhausted"
    found = re.search(rf"; {reachable} of \d+ positions are reachable on the map, and an unreachable one would "
                      r"find the target with probability (0\.\d+)$", d.reason)
    assert found and float(found.group(1)) > 0.1, d.reason


def test_a_search_with_nothing_left_at_its_tilts_widens_to_the_fallback_tilts_once():
    # all the mass on the floor 1 m ahead, 48° below the head: no level or raised view has it, and the
    # robot is boxed in, so only a look down from here can find it
    low = HintBox((3.9, 1.9, 0.0), (4.1, 2.1, 0.2), 1.0)
    pose = Pose2D(3.0, 2.0, 0.0)
    planner = _planner(3, boxes=(low,), table=DetectabilityTable.nominal())
    boxed_in = np.full(len(planner.positions), np.inf)
    usual = planner.settings
    assert planner.decide(pose, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), boxed_in).status == "exhausted"
    assert planner.widen() and not planner.widen()
    n = len(usual)
    assert len(planner.settings) == n + 8  # 9 level, 8 raised, now 8 lowered
    np.testing.assert_array_equal(planner.settings.azimuth_rad[:n], usual.azimuth_rad)  # taken stays taken
    np.testing.assert_array_equal(planner.settings.tilt_rad[:n], usual.tilt_rad)
    d = planner.decide(pose, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), boxed_in)
    assert d.kind == "look" and d.setting >= n and d.tilt_rad == pytest.approx(math.radians(-30.0)), d.reason
    assert d.find_prob > 0.5
    without = _planner(3, boxes=(low,), table=DetectabilityTable.nominal(), fallback_tilts_deg=())
    assert not without.widen() and len(without.settings) == n
    with pytest.raises(ValueError, match=r"tilt_deg=-60 is outside the tilt limit \[-47, 31\]°"):
        _planner(3, fallback_tilts_deg=(-60.0,))


def test_unreachable_positions_are_never_chosen():
    planner = _planner(2)
    paths = _paths(planner, START)
    a_center = np.array([4.5, 2.5])
    near_a = np.hypot(*(planner.positions - a_center).T) < 1.5
    paths[near_a] = np.inf
    d = planner.decide(START, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), paths)
    assert d.kind == "move" and np.hypot(*(np.array(d.position_m) - a_center)) >= 1.5


def test_the_rate_rule_looks_here_while_a_look_here_beats_any_visit_elsewhere():
    box = HintBox((1.8, 2.6, 0.9), (2.2, 3.0, 1.2), 0.5)  # 1.3 m in front of the pose: one look finds it
    planner = _planner(3, boxes=(box,))
    pose = Pose2D(2.0, 1.5, math.pi / 2)
    d = planner.decide(pose, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), _paths(planner, pose))
    assert d.kind == "look" and d.find_prob > 0.3, d.reason
    # the same mass far away (4.5, 2.5) is worth the drive: nothing here can see it
    far = _planner(3, boxes=(A_BOX,))
    d2 = far.decide(pose, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), _paths(far, pose))
    assert d2.kind == "move" and "a visit to" in d2.reason and d2.position_m[0] > 3.5


def test_a_look_here_is_left_for_a_visit_that_finds_more_per_second_travel_included():
    # a little mass here, a lot 1 m away: the visit's rate (travel included) wins over the look here
    planner = _planner(3, boxes=(HintBox((1.9, 2.4, 1.1), (2.1, 2.6, 1.3), 0.02), HintBox((3.4, 2.4, 1.1), (3.6, 2.6, 1.3), 0.98)))
    pose = Pose2D(2.0, 1.5, math.pi / 2)
    d = planner.decide(pose, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), _paths(planner, pose))
    assert d.kind == "move", d.reason


def test_the_leave_margin_keeps_the_robot_looking_until_a_visit_is_that_many_times_better():
    boxes = (HintBox((1.9, 2.4, 1.1), (2.1, 2.6, 1.3), 0.1), HintBox((3.4, 2.4, 1.1), (3.6, 2.6, 1.3), 0.9))
    pose = Pose2D(2.0, 1.5, math.pi / 2)
    eager = _planner(3, boxes=boxes, leave_margin=1.0)
    d = eager.decide(pose, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), _paths(eager, pose))
    visit, here = (float(v) for v in re.findall(r"(\d+\.\d+)/s", d.reason))
    assert d.kind == "move" and 1.0 < visit / here < 10.0, d.reason
    for margin, kind in ((0.9 * visit / here, "move"), (1.1 * visit / here, "look")):
        planner = _planner(3, boxes=boxes, leave_margin=max(1.0, margin))
        assert planner.decide(pose, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), _paths(planner, pose)).kind == kind


def test_a_view_taken_on_an_earlier_stay_is_not_taken_again_from_that_place_here_or_as_a_candidate():
    box = HintBox((1.8, 2.6, 0.9), (2.2, 3.0, 1.2), 0.5)
    planner = _planner(3, boxes=(box,))
    pose = Pose2D(2.0, 1.5, math.pi / 2)
    first = planner.decide(pose, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), _paths(planner, pose))
    assert first.kind == "look"
    elsewhere = planner.decide(pose, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), _paths(planner, pose),
                               views=((4.5, 0.5, first.setting),))
    assert elsewhere.setting == first.setting  # taken 2.5 m away: a different view
    came_back = planner.decide(pose, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), _paths(planner, pose),
                               views=((2.2, 1.3, first.setting),))  # taken 0.28 m from here
    assert came_back.setting != first.setting
    assert came_back.values.find_prob[-1, first.setting] == 0.0
    near = np.hypot(planner.positions[:, 0] - 2.2, planner.positions[:, 1] - 1.3) <= planner.config.same_position_m
    assert near.any() and not came_back.values.find_prob[:-1][near, first.setting].any()
    assert came_back.values.find_prob[:-1][~near, first.setting].any()


def test_cost_1_moves_carry_their_setting_and_never_to_where_the_robot_stands():
    """A move to a candidate within same_position_m passed: no case had one that sees better than here."""
    planner = _planner(1)
    d = planner.decide(START, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), _paths(planner, START))
    assert d.kind == "move" and 0 <= d.setting < len(planner.settings)
    j = np.flatnonzero(np.all(planner.positions == d.position_m, axis=1))[0]
    assert d.find_prob == pytest.approx(d.values.find_prob[:-1].max()) == d.values.find_prob[j, d.setting]
    assert d.azimuth_rad == planner.settings.azimuth_rad[d.setting]
    assert d.tilt_rad == planner.settings.tilt_rad[d.setting]
    # B is seen better from the candidate (2, 1), 0.3 m away, than from here: that one is "here", not a move
    planner = _planner(1, boxes=(replace(B_BOX, weight=1.0),))
    near_vertex = Pose2D(1.7, 1.0, 0.0)
    d2 = planner.decide(near_vertex, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), _paths(planner, near_vertex))
    beside = np.flatnonzero(np.all(planner.positions == (2.0, 1.0), axis=1))[0]
    assert d2.values.find_prob[beside].max() > d2.values.find_prob[-1].max()
    assert d2.kind == "move" and np.hypot(d2.position_m[0] - 1.7, d2.position_m[1] - 1.0) > 0.5, d2.reason


@pytest.mark.parametrize("cost", [1, 3])
def test_with_every_view_here_taken_and_only_here_reachable_the_search_stops_rather_than_look_again(cost):
    """Cost 1 used to take a look worth 0 (a view taken already) for ever: the candidate 0.3 m away
    is "here" to a move, yet counted as reachable elsewhere, so "exhausted" and its fallbacks never came."""
    planner = _planner(cost, boxes=(replace(B_BOX, weight=1.0),))
    pose = Pose2D(1.7, 1.0, 0.0)
    paths = _paths(planner, pose)
    beside = np.all(planner.positions == (2.0, 1.0), axis=1)
    paths[~beside] = np.inf
    d = planner.decide(pose, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), paths, taken=frozenset(range(len(planner.settings))))
    assert d.values.find_prob[:-1][beside].max() > 0.5  # worth a look, had it been elsewhere
    assert d.kind == "stop" and d.status == "exhausted", d.reason


def test_a_baseline_decides_on_every_vertex_of_a_room_with_more_than_256():
    """Baselines keep the report's whole grid (they never plan positions): 19 x 14 vertices here."""
    room = VoxelGrid((20.0, 15.0, 2.5), 0.1)
    belief = TargetBelief(room, facing_sectors=1, coarse_factor=4)
    planner = SearchPlanner(belief, PlannerConfig(), DetectabilityTable.nominal(), TIME, K, MOUNT)
    assert len(planner.positions) == 266
    d = planner.decide(START, 0.0, 0.0, 0.0, OccupancyGrid(room), _paths(planner, START))
    assert d.kind == "look" and d.find_prob > 0.0


def test_viewpoints_are_aimed_at_the_unseen_facing_of_a_mass():
    from offboard.planning.viewpoints import AimedViewpoints

    blocks = np.array([[4.0, 2.0, 1.0], [1.0, 1.0, 1.0]])
    mass = np.zeros((2, 8))
    mass[0, 2] = 0.9  # the first block's mass faces +y (sector 2 of 8 is 90°)
    mass[1, 0] = 0.1
    facings = np.arange(8) * (2 * math.pi / 8)
    points = AimedViewpoints(blocks, facings, 1.2, 1.2, (6.0, 4.0, 2.5), 0.3, 0.25).propose(mass, 2)
    assert points.shape == (2, 2)
    np.testing.assert_allclose(points[0], (4.0, 3.25), atol=0.13)  # straight in front of its face, 1.2 m
    np.testing.assert_allclose(points[1], (2.25, 1.0), atol=0.13)


def test_planned_positions_add_viewpoints_the_base_can_stand_on():
    planner = _planner(3, boxes=(B_BOX,))
    floor = OccupancyGrid(ROOM).floor_map(0.26, 1.35)
    positions = planner.plan_positions(START, floor, 0.3)
    assert len(positions) > len(planner.vertices) and len(planner.positions) == len(positions)
    aimed = positions[len(planner.vertices):]
    box_center = np.array([2.5, 1.5])
    assert np.hypot(*(aimed[0] - box_center)) < 1.0  # the strongest faces the box
    d = planner.decide(START, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), _paths(planner, START))
    assert d.kind == "move" and np.hypot(*(np.array(d.position_m) - box_center)) < 1.6


def test_where_the_belief_has_gathered_occlusion_is_judged_along_the_ray_to_it():
    """A thin post stands on the axis of the sphere bin that holds a heavily weighted place, but off
    the straight line to it: the look at it is worth what it finds, not nothing."""
    target = HintBox((3.45, 1.9, 1.15), (3.55, 2.0, 1.25), 0.9)
    occ = OccupancyGrid(ROOM)
    post = ROOM.box_slices(np.array([2.45, 1.8, 0.8]), np.array([2.55, 1.9, 1.6]))  # just beside the line
    with occ.edit() as (log_odds, observed):
        log_odds[post] = 5.0
        observed[:] = True
    pose = Pose2D(1.0, 1.95, 0.0)
    planner = _planner(3, boxes=(target,), table=DetectabilityTable.nominal())
    best = planner.decide(pose, 0.0, 0.0, 0.0, occ, _paths(planner, pose)).values.find_prob[-1].max()
    assert best > 0.6


def test_travel_is_costed_at_the_navigators_measured_rate():
    # some mass in view here, more 1 m away: a straight drive makes the visit worth it, the rate the
    # navigator really drives at (steps from rest, a look before each) does not
    boxes = (HintBox((1.9, 2.4, 1.1), (2.1, 2.6, 1.3), 0.1), HintBox((3.4, 2.4, 1.1), (3.6, 2.6, 1.3), 0.9))
    pose = Pose2D(2.0, 1.5, math.pi / 2)
    decisions = {}
    for rate in (0.0, 15.0):
        planner = _planner(3, boxes=boxes, leave_margin=1.0)  # the rate alone decides
        planner.set_drive_s_per_m(rate)
        decisions[rate] = planner.decide(pose, 0.0, 0.0, 0.0, OccupancyGrid(ROOM), _paths(planner, pose))
    assert decisions[0.0].kind == "move", decisions[0.0].reason
    assert decisions[15.0].kind == "look", decisions[15.0].reason
    assert TIME.travel_s(2.0, 0.0) < replace(TIME, drive_s_per_m=15.0).travel_s(2.0, 0.0) == pytest.approx(30.0)


def test_the_geometry_cache_holds_each_candidate_as_computed_afresh_as_candidates_come_and_go():
    from offboard.planning.action_values import ActionGeometry, CameraSettings, GeometryCache
    from offboard.planning.sensed_sphere import SphereBins

    belief = TargetBelief(ROOM, coarse_factor=4)
    parts = (CameraSettings.from_fov(K), HeadMount(), K, DetectabilityTable.nominal(), SphereBins())
    cache = GeometryCache(belief, *parts, capacity=5)
    a, b, c, d, e, f, g = (np.array([x, 1.0]) for x in (0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5))
    # more positions over the calls than the cache holds; some kept from the call before, one twice in a
    # call, and two a lattice of 0.25 m would put on one node
    for positions in ([a, b, c, d], [e, a], [f, g, b, f], [a, c, e, g], [d, b], [a, a + 0.1, b]):
        positions = np.array(positions)
        rows = cache.rows(positions)
        fresh = ActionGeometry(belief, positions, *parts)
        for name in ("distance_m", "sphere_bin", "distance_bin", "facing_bin", "off_axis_bin"):
            assert np.array_equal(getattr(cache.geometry, name)[rows], getattr(fresh, name)), name
    with pytest.raises(ValueError, match="do not fit"):
        cache.rows(np.arange(12).reshape(6, 2) * 0.25)


def test_the_looks_here_are_valued_as_from_a_candidate_there_as_the_robot_stays_and_moves():
    occupancy = OccupancyGrid(ROOM)
    planner = _planner(3)
    away, near_b = Pose2D(1.0, 1.0, 0.0), Pose2D(2.0, 1.0, 0.0)  # vertices out of the detector's reach of B, and in it
    for pose in (away, away, near_b, near_b, away, near_b):  # the geometry here is reused, then replaced
        planner.plan_positions(pose, occupancy.floor_map(0.2, 1.2), 0.25)
        values = planner.decide(pose, 0.0, 0.0, 0.0, occupancy, _paths(planner, pose)).values
        there = np.flatnonzero(np.all(planner.positions == (pose.x_m, pose.y_m), axis=1))[0]
        assert np.array_equal(values.find_prob[-1], values.find_prob[there])
        assert (values.find_prob[-1].max() > 0.1) == (pose == near_b)


def test_a_block_below_the_lowest_elevation_any_tilt_sees_has_no_sphere_bin():
    """int() rounded an elevation up to half a bin below the lowest one into that bin."""
    from offboard.planning.action_values import ActionGeometry, CameraSettings, block_centers
    from offboard.planning.sensed_sphere import SphereBins

    belief = TargetBelief(VoxelGrid((4.0, 4.0, 2.5), 0.05), coarse_factor=2)
    bins = SphereBins()
    geometry = ActionGeometry(belief, np.array([[2.0, 2.0]]), CameraSettings.from_fov(K), MOUNT, K,
                              DetectabilityTable.nominal(near_m=0.1), bins)
    offset = block_centers(belief) - geometry.cameras_m(np.zeros(1, np.int64))[0]
    elevation = np.arcsin(offset[:, 2] / np.linalg.norm(offset, axis=1))
    in_reach = (geometry.distance_m[0] > 0) & (geometry.sphere_bin[0] >= 0)
    assert in_reach.any() and (elevation[in_reach] >= bins.el_min_rad).all()


def test_a_measured_time_that_is_negative_or_nan_is_refused_and_the_model_kept():
    planner = _planner(3)
    with pytest.raises(ValueError, match="processing_s"):
        planner.set_processing_s(-0.2)
    with pytest.raises(ValueError, match="drive_s_per_m"):
        planner.set_drive_s_per_m(float("nan"))
    assert planner.time_model == TIME


def test_a_viewpoint_stands_midway_through_the_detectors_good_distances():
    from offboard.planning.viewpoints import best_distance_m

    # head-on within 5 % of the best rate from 0.5 to 1.5 m (bins of 0.25 m)
    assert best_distance_m(DetectabilityTable.nominal()) == 1.0


def _aimed(blocks, facings, mass, count, distance_m=1.0, margin_m=0.3, lattice_m=0.25) -> np.ndarray:
    from offboard.planning.viewpoints import AimedViewpoints

    return AimedViewpoints(np.array(blocks, float), np.array(facings, float), distance_m, MOUNT.height_m,
                           (6.0, 4.0, 2.5), margin_m, lattice_m).propose(np.array(mass, float), count)


def test_a_viewpoint_on_a_block_above_the_head_stands_nearer_by_the_rise():
    # 1.5 m to a block 1 m above the head: 1.12 m along the floor, on the lattice 1 m (1.5 m without the rise)
    points = _aimed([(2.0, 2.0, MOUNT.height_m + 1.0)], [0.0], [[1.0]], 1, distance_m=1.5)
    np.testing.assert_allclose(points, [(3.0, 2.0)])


def test_no_viewpoint_is_proposed_within_the_margin_of_a_wall():
    # the votes land 0.2 m from the west and the east wall
    blocks = [(1.2, 2.0, MOUNT.height_m), (4.8, 2.0, MOUNT.height_m)]
    mass = [[1.0, 0.0], [0.0, 1.0]]  # the first faces west, the second east
    assert _aimed(blocks, [math.pi, 0.0], mass, 2, margin_m=0.3, lattice_m=0.1).shape == (0, 2)
    near_walls = _aimed(blocks, [math.pi, 0.0], mass, 2, margin_m=0.15, lattice_m=0.1)
    np.testing.assert_allclose(sorted(near_walls[:, 0]), [0.2, 5.8])


def test_viewpoints_on_neighbouring_lattice_nodes_are_not_both_proposed():
    # votes on three nodes in a row, 0.25 m apart: the middle one neighbours the strongest
    blocks = [(2.0, 2.0, MOUNT.height_m), (2.0, 2.25, MOUNT.height_m), (2.0, 2.5, MOUNT.height_m)]
    np.testing.assert_allclose(_aimed(blocks, [0.0], [[0.5], [0.3], [0.2]], 3), [(3.0, 2.0), (3.0, 2.5)])

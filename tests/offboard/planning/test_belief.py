"""The target belief (eq. 1, 2, 4) and the detection function of a look taken."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from offboard.planning import belief as belief_module
from offboard.planning.belief import TargetBelief
from offboard.perception.detectability import DetectabilityTable, facing_angle_deg
from offboard.planning.detection_function import look_footprint, visible_depth
from offboard.perception.occupancy import OccupancyGrid
from offboard.perception.voxel_grid import VoxelGrid
from shared.geometry import HeadMount, Intrinsics, Pose2D

GRID = VoxelGrid((2.0, 1.0, 0.5), 0.1)  # 20 × 10 × 5 cubes: small enough for property tests
K = Intrinsics.from_fov(640, 480, 66.0)


def _random_look(rng, belief):
    n = belief.grid.num_cubes
    idx = rng.choice(n, size=rng.integers(0, n), replace=False)
    return idx, rng.uniform(0, 1, (idx.size, belief.facing_sectors))


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), sectors=st.sampled_from([1, 4, 8]), looks=st.integers(1, 6),
       outside=st.floats(0.0, 0.5))
def test_total_mass_stays_one_after_any_sequence_of_updates(seed, sectors, looks, outside):
    rng = np.random.default_rng(seed)
    belief = TargetBelief(GRID, facing_sectors=sectors, prob_outside=outside, coarse_factor=3)
    for _ in range(looks):
        belief.update_after_miss(*_random_look(rng, belief))
        assert belief.target_prob.sum() + belief.prob_outside == pytest.approx(1.0, abs=1e-5)
        assert belief.coarse_mass().sum() == pytest.approx(belief.prob_inside, abs=1e-5)
        assert 0.0 <= belief.success_prob <= 1.0


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_a_look_that_can_see_nothing_changes_nothing(seed):
    rng = np.random.default_rng(seed)
    belief = TargetBelief(GRID, facing_sectors=4)
    belief.update_after_miss(*_random_look(rng, belief))
    before = belief.target_prob.copy()
    idx = rng.choice(GRID.num_cubes, 30, replace=False)
    assert belief.update_after_miss(idx, np.zeros((30, 4))) == 0.0
    np.testing.assert_allclose(belief.target_prob, before, rtol=1e-6)


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 10_000), b=st.floats(0.05, 0.99))
def test_eq4_seen_cubes_lose_and_unseen_cubes_and_outside_gain(seed, b):
    rng = np.random.default_rng(seed)
    belief = TargetBelief(GRID, facing_sectors=1, prob_outside=0.1)
    before, outside = belief.target_prob.copy(), belief.prob_outside
    idx = rng.choice(GRID.num_cubes, 50, replace=False)
    found = belief.update_after_miss(idx, np.full((50, 1), b))
    after = belief.target_prob.reshape(-1)
    seen = np.zeros(GRID.num_cubes, bool)
    seen[idx] = True
    assert (after[seen] < before.reshape(-1)[seen]).all() and (after[~seen] > before.reshape(-1)[~seen]).all()
    assert belief.prob_outside > outside
    # eq. 4 exactly: p' = p (1 - b) / (p_out + Σ p (1 - b)); eq. 1: found = Σ p b
    assert found == pytest.approx(before.reshape(-1)[seen].sum() * b, rel=1e-5)
    expected = before.reshape(-1)[seen] * (1 - b) / (1 - found)
    np.testing.assert_allclose(after[seen], expected, rtol=1e-4)


def test_eq2_success_probability_accumulates():
    belief = TargetBelief(GRID, facing_sectors=1, prob_outside=0.0)
    idx = np.arange(GRID.num_cubes // 2)
    p1 = belief.update_after_miss(idx, np.full((idx.size, 1), 0.5))
    p2 = belief.update_after_miss(idx, np.full((idx.size, 1), 0.5))
    assert p1 == pytest.approx(0.25) and belief.success_prob == pytest.approx(p1 + (1 - p1) * p2)
    assert p2 == pytest.approx(0.125 / 0.75)  # of the probability after the first miss, not of the stored mass


def test_a_second_look_from_the_same_side_is_worth_less_than_one_from_a_new_side():
    belief = TargetBelief(GRID, facing_sectors=8, prob_outside=0.0)
    cube = np.array([GRID.num_cubes // 2])
    table = DetectabilityTable.nominal()
    az = belief.facing_azimuths_rad

    def b_from(view_az):
        return table.lookup(np.full(8, 1.0), np.zeros(8), facing_angle_deg(view_az, az))[None, :]
    first = belief.update_after_miss(cube, b_from(0.0))
    same = TargetBelief(GRID, facing_sectors=8, prob_outside=0.0)
    same.update_after_miss(cube, b_from(0.0))
    again_same = same.update_after_miss(cube, b_from(0.0))
    new_side = belief.update_after_miss(cube, b_from(math.pi))
    assert first > 0 and new_side > again_same


def test_observe_is_bayes_with_a_likelihood_per_listed_cube():
    belief = TargetBelief(GRID, facing_sectors=2, prob_outside=0.2)
    cubes = np.arange(10)
    before = belief.mass_by_facing().reshape(-1, 2)[cubes].sum()
    likelihood = np.full((10, 2), 3.0)
    belief.observe(cubes, likelihood)
    after = belief.mass_by_facing().reshape(-1, 2)[cubes].sum()
    rest = 1.0 - before  # every other cube and c_out keep their relative weight (factor 1)
    assert after == pytest.approx(3 * before / (3 * before + rest))
    assert belief.prob_outside == pytest.approx(0.2 / (3 * before + rest))
    with pytest.raises(ValueError, match="non-negative"):
        belief.observe(cubes, -likelihood)


def test_an_observation_that_would_leave_nothing_is_refused_and_changes_nothing():
    belief = TargetBelief(GRID, facing_sectors=2, prob_outside=0.0)
    before = belief.mass_by_facing()
    everything = np.arange(GRID.num_cubes)
    with pytest.raises(ValueError, match="no probability anywhere"):
        belief.observe(everything, np.zeros((GRID.num_cubes, 2)))
    assert np.array_equal(belief.mass_by_facing(), before)  # not scaled to zero on the way
    assert belief.coarse_mass().sum() == pytest.approx(1.0)


def test_a_prior_arriving_mid_search_moves_mass_inside_the_room_only():
    """A support-surface or saliency factor says where in the room the target is likelier, not
    whether it is in the room: p(c_out) stays."""
    belief = TargetBelief(GRID, facing_sectors=2, prob_outside=0.05)
    factors = np.ones(GRID.shape)
    factors[:, :, 2:4] = 5.0
    belief.reweight(factors)
    assert belief.prob_outside == pytest.approx(0.05)
    layers = belief.target_prob.sum(axis=(0, 1))
    assert layers[2] == pytest.approx(5 * layers[0])
    assert belief.target_prob.sum() + belief.prob_outside == pytest.approx(1.0)


@pytest.mark.parametrize("factors", [np.full(GRID.shape, np.nan), np.full(GRID.shape, -1.0), np.ones(GRID.shape[2])])
def test_reweighting_by_a_nan_negative_or_misshapen_factor_is_refused(factors):
    belief = TargetBelief(GRID)
    with pytest.raises(ValueError, match="reweighting factors"):
        belief.reweight(factors)
    assert belief.prob_outside == pytest.approx(0.05)


def test_a_fresh_prior_forgets_what_was_seen():
    belief = TargetBelief(GRID, facing_sectors=2)
    empty = np.zeros(GRID.shape, bool)
    empty[:5] = True
    belief.update_after_miss(np.arange(50), np.full((50, 2), 0.9))
    belief.rule_out_empty(empty, 0.1)
    belief.set_prior(np.ones(GRID.shape), 0.05)
    assert belief.success_prob == 0.0
    assert belief.rule_out_empty(empty, 0.1) > 0  # the same cubes are ruled out again
    with pytest.raises(ValueError, match="c_out"):
        belief.set_prior(np.ones(GRID.shape), 1.5)


def test_mass_near_counts_the_ball_around_a_point():
    belief = TargetBelief(GRID, facing_sectors=1, prob_outside=0.0)
    whole = belief.mass_near(np.array([1.0, 0.5, 0.25]), 10.0)
    assert whole == pytest.approx(1.0)
    small = belief.mass_near(np.array([1.0, 0.5, 0.25]), 0.1)
    assert 0 < small < 0.05


def _whole_grid_renormalise(belief):
    """The renormalisation as one float64 copy of the whole belief: what the chunked one must equal."""
    mass = belief._mass.astype(np.float64) * belief._scale
    outside = belief._outside * belief._scale
    total = mass.sum() + outside
    f, (cx, cy, cz) = belief.coarse_factor, belief.coarse_shape
    padded = np.zeros((cx * f, cy * f, cz * f, belief.facing_sectors))
    nx, ny, nz = belief.grid.shape
    padded[:nx, :ny, :nz] = (mass / total).astype(np.float32)
    return (mass / total).astype(np.float32), outside / total, \
        padded.reshape(cx, f, cy, f, cz, f, belief.facing_sectors).sum(axis=(1, 3, 5))


@pytest.mark.parametrize("chunk", [4096, 1 << 20])
def test_renormalising_a_chunk_at_a_time_is_the_whole_grid_renormalisation_to_the_bit(monkeypatch, chunk):
    monkeypatch.setattr(belief_module, "_CHUNK", chunk)  # small chunks: the pairwise split and many slabs
    rng = np.random.default_rng(1)  # masses over many orders of magnitude: a sum split elsewhere rounds otherwise
    belief = TargetBelief(VoxelGrid((2.05, 1.55, 1.15), 0.05), facing_sectors=8, coarse_factor=3)
    belief.set_prior(rng.lognormal(0.0, 3.0, belief.grid.shape), prob_outside=0.05)
    cubes = rng.choice(belief.grid.num_cubes, 5000, replace=False)
    belief.observe(cubes, rng.uniform(0, 3, (5000, 8)))  # stored masses now scaled
    flat = belief._mass.reshape(-1)
    total = belief_module._scaled_total(flat, belief._scale, 0, flat.size)
    assert total == (flat.astype(np.float64) * belief._scale).sum()  # a division would hide a last bit
    mass, outside, coarse = _whole_grid_renormalise(belief)
    belief._renormalise()
    assert np.array_equal(belief._mass, mass) and belief._outside == outside and belief._scale == 1.0
    assert np.array_equal(belief._coarse, coarse)


def test_mass_near_and_walls_read_the_cube_centres_as_the_whole_grid_of_centres_does():
    grid = VoxelGrid((2.05, 1.55, 1.15), 0.05)
    belief = TargetBelief(grid, facing_sectors=8, prob_outside=0.0)
    belief.set_prior(np.random.default_rng(4).random(grid.shape), prob_outside=0.0)
    point = np.array([0.33, 1.21, 0.52])
    centers = grid.centers()
    inside = np.sum((centers - point) ** 2, axis=-1) <= 0.4**2
    assert belief.mass_near(point, 0.4) == float(belief.target_prob[inside].sum())
    belief.exclude_facings_into_walls(0.3)
    for s, azimuth in enumerate(belief.facing_azimuths_rad):
        face = centers[..., :2] + 0.3 * np.array([math.cos(azimuth), math.sin(azimuth)])
        into_wall = np.any((face < 0.0) | (face > grid.size_m[:2]), axis=-1)
        assert (belief.mass_by_facing()[into_wall, s] == 0).all() and (belief.mass_by_facing()[~into_wall, s] > 0).all()


ROOM = VoxelGrid((4.0, 3.0, 2.5), 0.05)
MOUNT = HeadMount()


def test_footprint_is_the_visible_part_of_the_view_inside_the_detector_range():
    occ = OccupancyGrid(ROOM)
    cam = MOUNT.camera_in_world(Pose2D(0.5, 1.5, 0.0), 0.0, 0.0)
    wall = np.full((480, 640), K.fx_px * 0.12 / 1.5, np.float32)  # something 1.5 m ahead, everywhere
    occ.integrate_disparity(wall, K, 0.12, cam)
    table = DetectabilityTable.nominal(near_m=0.4, far_m=3.0)
    depth = visible_depth(wall, occ, cam, K, 0.12, 16, 3.5)
    toward_camera = np.array([math.pi])  # the face's normal points back along -x, at the camera
    fp = look_footprint(ROOM, cam, K, depth, 16, table, toward_camera, behind_surface_m=0.1)
    centers = ROOM.centers().reshape(-1, 3)[fp.cube_index]
    dx, dy = (centers[:, :2] - cam.translation[:2]).T
    assert fp.cube_index.size > 1000 and (fp.detection_prob > 0).mean() > 0.8
    assert dx.min() >= 0.4 - 0.05 and dx.max() <= 1.5 + 0.1 + 0.05  # in range, nothing behind the surface
    assert np.abs(np.arctan2(dy, dx)).max() <= math.radians(33.1)  # centres inside the image
    open_depth = visible_depth(None, OccupancyGrid(ROOM), cam, K, 0.12, 16, 3.5)
    far_fp = look_footprint(ROOM, cam, K, open_depth, 16, table, toward_camera, 0.1)
    assert far_fp.cube_index.size > 2 * fp.cube_index.size  # with nothing in the way it sees farther
    # facing: a face pointing away from the camera (azimuth 0 = +x, the camera looks along +x) is never seen
    back = look_footprint(ROOM, cam, K, depth, 16, table, np.array([0.0, math.pi]), 0.1)
    assert (back.detection_prob[:, 0] == 0).all() and (back.detection_prob[:, 1] > 0).mean() > 0.8


@pytest.mark.parametrize("block_px, depth_shape", [(16, (1, 1)), (8, (30, 40))])
def test_a_depth_image_of_another_block_size_is_refused_not_read_past(block_px, depth_shape):
    """The kernel reads depth_z by pixel block: a 1×1 map "saw" 41,967 cubes, one made for 16-pixel
    blocks read as 8 (one quarter of it) gave 40,252 cubes where 68,386 were in view."""
    cam = MOUNT.camera_in_world(Pose2D(0.5, 1.5, 0.0), 0.0, 0.0)
    with pytest.raises(ValueError, match=f"depth_z must hold one depth per {block_px}-pixel block"):
        look_footprint(ROOM, cam, K, np.ones(depth_shape, np.float32), block_px,
                       DetectabilityTable.nominal(near_m=0.4, far_m=3.0), np.array([math.pi]), 0.1)


def test_footprint_reaches_the_detector_range_straight_ahead():
    """A camera looking along a room axis sees the middle of its view out to the detector's far
    range, though the image's corners reach only 0.78 of it that far ahead (66° × 52° field)."""
    hall = VoxelGrid((8.0, 3.0, 2.5), 0.1)
    cam = MOUNT.camera_in_world(Pose2D(0.5, 1.5, 0.0), 0.0, 0.0)
    table = DetectabilityTable.nominal(near_m=0.4, far_m=6.0)
    depth = visible_depth(None, OccupancyGrid(hall), cam, K, 0.12, 16, 7.0)
    fp = look_footprint(hall, cam, K, depth, 16, table, np.array([math.pi]), behind_surface_m=0.1)
    ahead = hall.centers().reshape(-1, 3)[fp.cube_index, 0] - cam.translation[0]
    assert ahead.max() == pytest.approx(6.0, abs=0.1)


def test_space_seen_empty_loses_its_mass_once_whatever_the_facing():
    belief = TargetBelief(GRID, facing_sectors=4, prob_outside=0.0)
    empty = np.zeros(GRID.shape, bool)
    empty[:10] = True  # half the room seen through
    left = belief.rule_out_empty(empty, 0.05)
    assert left == pytest.approx(0.5 * 0.95, abs=1e-6)  # of the probability before the update
    assert belief.target_prob[:10].sum() == pytest.approx(0.025 / 0.525, rel=1e-5)
    again = belief.rule_out_empty(empty, 0.05)  # the map still says empty: nothing new is learnt
    assert again == 0.0 and belief.target_prob[:10].sum() == pytest.approx(0.025 / 0.525, rel=1e-5)


def test_no_picture_faces_a_wall_it_almost_touches():
    belief = TargetBelief(GRID, facing_sectors=4, prob_outside=0.1)  # facings +x, +y, -x, -y
    belief.exclude_facings_into_walls(0.15)
    mass = belief.mass_by_facing()
    assert mass[-1, :, :, 0].sum() == 0 and mass[-1, :, :, 2].sum() > 0  # the east wall: nothing faces it
    assert mass[0, :, :, 2].sum() == 0 and mass[0, :, :, 0].sum() > 0  # the west wall likewise
    assert mass[10, 5, 2].min() > 0  # the middle of the room faces anywhere
    assert mass.sum() == pytest.approx(0.9, rel=1e-5) and belief.prob_outside == pytest.approx(0.1)


def test_walls_are_where_the_grid_is_and_a_room_no_facing_fits_holds_no_target():
    moved = TargetBelief(VoxelGrid(GRID.size_m, GRID.resolution_m, (10.0, -3.0, 0.0)), facing_sectors=4)
    moved.exclude_facings_into_walls(0.15)
    assert moved.mass_by_facing()[10, 5, 2].min() > 0  # the room's middle, wherever the room is
    cramped = TargetBelief(GRID, facing_sectors=4)
    cramped.exclude_facings_into_walls(3.0)  # 3 m out, every face point is beyond a wall
    assert cramped.target_prob.sum() == 0 and cramped.prob_outside == pytest.approx(1.0)


def test_a_facing_with_a_surface_just_in_front_keeps_a_share_once():
    belief = TargetBelief(GRID, facing_sectors=4, prob_outside=0.1)  # facings +x, +y, -x, -y; 0.1 m cubes
    solid = np.zeros(GRID.shape, bool)
    solid[10] = True  # a surface across the room at x = 1.0-1.1 m
    left = belief.rule_out_blocked_facings(solid, 0.2, 0.3, 0.1)
    mass = belief.mass_by_facing()
    before = mass[0, 0, 0, 0]  # far from the surface: every facing as it was, relatively
    assert np.allclose(mass[:6], before) and np.allclose(mass[14:], before)
    assert np.allclose(mass[7:9, :, :, 0], 0.1 * before) and np.allclose(mass[7:9, :, :, 1:], before)  # facing it
    assert np.allclose(mass[12:14, :, :, 2], 0.1 * before)  # beyond it, facing back
    assert np.allclose(mass[10, :, :, 0], before)  # the surface's own cubes: nothing solid 0.2 m out along x
    assert left > 0 and belief.prob_outside + mass.sum() == pytest.approx(1.0, rel=1e-5)
    assert belief.rule_out_blocked_facings(solid, 0.2, 0.3, 0.1) == 0.0  # the map says it again: nothing new


def test_the_coarse_copy_kept_through_many_misses_is_the_one_summed_afresh():
    """A miss that took a cube's mass from the wrong coarse block (its height ignored) passed."""
    rng = np.random.default_rng(7)
    belief = TargetBelief(GRID, facing_sectors=4, prob_outside=0.1, coarse_factor=2)  # blocks 2 cubes high
    for _ in range(20):
        belief.update_after_miss(*_random_look(rng, belief))
    rebuilt = TargetBelief(GRID, facing_sectors=4, coarse_factor=2)
    rebuilt.restore(belief.state())
    rebuilt.reweight(np.ones(GRID.shape))  # renormalised: its coarse copy summed afresh from the cubes
    np.testing.assert_allclose(belief.coarse_mass(), rebuilt.coarse_mass(), rtol=1e-5, atol=1e-9)


def test_where_stereo_has_depth_the_look_sees_up_to_it_though_the_map_is_empty():
    """Ignoring the look's own disparity passed: the footprint test's wall was in the map as well."""
    cam = MOUNT.camera_in_world(Pose2D(0.5, 1.5, 0.0), 0.0, 0.0)
    disparity = np.full((480, 640), K.fx_px * 0.12 / 1.5, np.float32)  # a wall 1.5 m ahead, in stereo only
    disparity[:, 320:] = np.nan  # the image's right half has no disparity: the map's depth there
    depth = visible_depth(disparity, OccupancyGrid(ROOM), cam, K, 0.12, 16, 3.5)
    np.testing.assert_allclose(depth[:, :20], 1.5, rtol=1e-5)  # 16 px blocks: 20 of 40 columns
    assert depth[:, 20:].min() > 2.0  # the open room, out to its walls


def test_the_maps_depth_is_the_depth_along_the_optical_axis_not_along_the_ray():
    """The along-ray distance to a mapped wall passed for the depth: every wall was straight ahead."""
    occ = OccupancyGrid(ROOM)
    with occ.edit() as (log_odds, observed):
        log_odds[ROOM.box_slices(np.array([1.5, 0.0, 0.0]), np.array([1.55, 3.0, 2.5]))] = 5.0  # a wall across x = 1.5
        observed[:] = True
    cam = MOUNT.camera_in_world(Pose2D(0.5, 1.5, 0.0), 0.0, 0.0)
    depth = visible_depth(None, occ, cam, K, 0.12, 16, 3.5)
    np.testing.assert_allclose(depth, 1.5 - cam.translation[0], atol=0.03)  # corners too, 35° off the axis


@pytest.mark.parametrize("index", [-1, GRID.num_cubes, GRID.num_cubes + 5])
def test_a_cube_index_outside_the_grid_is_refused_and_changes_nothing(index):
    """An index past the grid (read and written out of bounds) or below 0 (wrapped round) passed."""
    belief = TargetBelief(GRID, facing_sectors=2)
    before = belief.mass_by_facing()
    cubes = np.array([0, index])
    with pytest.raises(ValueError, match=rf"cube_index must lie in \[0, {GRID.num_cubes}\)"):
        belief.update_after_miss(cubes, np.full((2, 2), 0.5))
    with pytest.raises(ValueError, match="cube_index"):
        belief.observe(cubes, np.ones((2, 2)))
    assert np.array_equal(belief.mass_by_facing(), before) and belief.success_prob == 0.0


@pytest.mark.parametrize("b", [-0.1, 1.1, np.nan])
def test_a_detection_probability_outside_0_to_1_is_refused_by_name(b):
    """b < 0 passed (a negative P_Ψ); b > 1 was refused as a bad "likelihood"."""
    belief = TargetBelief(GRID, facing_sectors=2)
    with pytest.raises(ValueError, match=r"detection_prob must lie in \[0, 1\]"):
        belief.update_after_miss(np.arange(3), np.full((3, 2), b))
    assert belief.success_prob == 0.0 and belief.prob_outside == pytest.approx(0.05)


@pytest.mark.parametrize("seed", range(8))
def test_an_observation_leaving_nothing_is_refused_though_the_running_total_drifts(seed):
    """The guard read the running total, which float32 rounding leaves ~1e-9 above 0: about half of
    such observations passed and turned the whole belief into NaN."""
    rng = np.random.default_rng(seed)
    belief = TargetBelief(GRID, facing_sectors=4, prob_outside=0.0)
    for _ in range(5):
        belief.update_after_miss(*_random_look(rng, belief))
    with pytest.raises(ValueError, match="no probability anywhere"):
        belief.observe(np.arange(GRID.num_cubes), np.zeros((GRID.num_cubes, 4)))
    with pytest.raises(ValueError, match="no probability anywhere"):
        belief.rule_out_empty(np.ones(GRID.shape, bool), 0.0)
    with pytest.raises(ValueError, match="no probability anywhere"):  # kept in float64, 0 as stored in float32
        belief.observe(np.arange(GRID.num_cubes), np.full((GRID.num_cubes, 4), 1e-44))
    assert belief.target_prob.sum() == pytest.approx(1.0, abs=1e-5)


@pytest.mark.parametrize("factors, match", [(np.full(GRID.shape, 1e39), "overflow"),
                                            (np.zeros(GRID.shape), "zero .in float32. on every cube"),
                                            (np.full(GRID.shape, 1e-50), "zero .in float32. on every cube")])
def test_reweighting_that_would_overflow_or_empty_the_room_is_refused(factors, match):
    """A finite factor past float32's range made every mass NaN; all-zero factors moved p(c_out) to 1."""
    belief = TargetBelief(GRID, facing_sectors=2)
    with pytest.raises(ValueError, match=match):
        belief.reweight(factors)
    assert belief.prob_outside == pytest.approx(0.05) and np.isfinite(belief.target_prob).all()


def test_reweighting_only_cubes_already_ruled_out_is_refused_and_changes_nothing():
    """Factors non-zero only where no mass is left passed the all-zero check and moved p(c_out) to 1."""
    belief = TargetBelief(GRID, facing_sectors=2)
    empty = np.zeros(GRID.shape, bool)
    empty[:10] = True
    belief.reweight((~empty).astype(float))  # the first ten slabs ruled out
    before = belief.target_prob.copy()
    with pytest.raises(ValueError, match="every cube that holds mass"):
        belief.reweight(empty * 2.0)
    np.testing.assert_array_equal(belief.target_prob, before)
    assert belief.prob_outside == pytest.approx(0.05)


def test_a_factor_of_zero_on_some_cubes_rules_them_out():
    belief = TargetBelief(GRID, facing_sectors=2)
    factors = np.ones(GRID.shape)
    factors[:10] = 0.0
    belief.reweight(factors)
    assert belief.target_prob[:10].sum() == 0 and belief.prob_outside == pytest.approx(0.05)
    belief.set_prior(factors, 0.05)
    assert belief.target_prob[:10].sum() == 0 and belief.target_prob.sum() == pytest.approx(0.95)


@pytest.mark.parametrize("method", ["update_after_miss", "expected_detection", "observe"])
@pytest.mark.parametrize("cubes, values, match", [
    (np.arange(3), np.full((2, 3), 0.5), r"must be of shape \(3, 2\)"),  # transposed
    (np.arange(3), np.full(6, 0.5), r"must be of shape \(3, 2\)"),  # flat
    (np.arange(4).reshape(2, 2), np.full((4, 2), 0.5), "cube_index must be 1-D"),
    (np.array([7, 3, 7]), np.full((3, 2), 0.5), "lists cube 7 more than once"),
    (np.array([3, 3]), np.full((2, 2), 0.5), "lists cube 3 more than once")])
def test_a_look_of_the_wrong_layout_or_with_a_cube_twice_is_refused(method, cubes, values, match):
    """These were reshaped and accepted; a cube listed twice kept (1 − b)² and counted twice in eq. 1."""
    belief = TargetBelief(GRID, facing_sectors=2)
    before = belief.mass_by_facing()
    with pytest.raises(ValueError, match=match):
        getattr(belief, method)(cubes, values)
    assert np.array_equal(belief.mass_by_facing(), before) and belief.success_prob == 0.0


@pytest.mark.parametrize("method", ["rule_out_empty", "rule_out_blocked_facings"])
def test_a_mask_not_of_the_grids_shape_is_refused(method):
    """An (nz,) mask broadcast over the grid."""
    belief = TargetBelief(GRID, facing_sectors=4)
    args = (0.15, 0.3, 0.1) if method == "rule_out_blocked_facings" else (0.05,)
    with pytest.raises(ValueError, match=r"must be a mask of shape \(20, 10, 5\), not \(5,\)"):
        getattr(belief, method)(np.ones(GRID.shape[2], bool), *args)


@pytest.mark.parametrize("b, index, match", [(np.nan, 0, r"detection_prob must lie in \[0, 1\]"),
                                             (-0.5, 0, r"detection_prob must lie in \[0, 1\]"),
                                             (0.5, -1, r"cube_index must lie in \[0, 1000\)")])
def test_the_expected_detection_refuses_what_a_miss_refuses(b, index, match):
    """It validated nothing: index −1 wrapped round, b NaN or negative gave a NaN or negative P_Ψ."""
    belief = TargetBelief(GRID, facing_sectors=2)
    with pytest.raises(ValueError, match=match):
        belief.expected_detection(np.array([5, index]), np.full((2, 2), b))


def test_the_expected_detection_is_eq1_on_the_current_belief():
    """It once dropped the stored masses' scale: right only before the first update."""
    belief = TargetBelief(GRID, facing_sectors=2, prob_outside=0.1)
    belief.update_after_miss(np.arange(300), np.full((300, 2), 0.8))
    cubes, b = np.arange(200, 500), np.full((300, 2), 0.5)
    assert belief.expected_detection(cubes, b) == pytest.approx(0.5 * belief.target_prob.reshape(-1)[cubes].sum())


@pytest.mark.parametrize("factor", [1.5, -0.1, np.nan])
def test_a_share_kept_outside_0_to_1_is_refused(factor):
    """An empty_factor above 1 added mass to cubes seen empty."""
    belief = TargetBelief(GRID, facing_sectors=4)
    with pytest.raises(ValueError, match="empty_factor must lie in"):
        belief.rule_out_empty(np.ones(GRID.shape, bool), factor)
    with pytest.raises(ValueError, match="factor must lie in"):
        belief.rule_out_blocked_facings(np.ones(GRID.shape, bool), 0.15, 0.3, factor)


def test_evidence_refused_is_applied_when_it_comes_again():
    """The cubes and facings were marked done before the update, which then refused: never applied."""
    belief = TargetBelief(GRID, facing_sectors=4, prob_outside=0.0)
    with pytest.raises(ValueError, match="no probability anywhere"):
        belief.rule_out_empty(np.ones(GRID.shape, bool), 0.0)
    assert belief.rule_out_empty(np.ones(GRID.shape, bool), 0.5) == pytest.approx(0.5)
    belief.set_prior(np.ones(GRID.shape), 0.0)
    just_west = np.zeros((*GRID.shape, 4))
    just_west[7:9, :, :, 0] = 1.0  # all the mass just west of a surface at x = 1.0-1.1 m, facing it (+x)
    belief.observe(np.arange(GRID.num_cubes), just_west.reshape(-1, 4))
    solid = np.zeros(GRID.shape, bool)
    solid[10] = True
    with pytest.raises(ValueError, match="no probability anywhere"):
        belief.rule_out_blocked_facings(solid, 0.2, 0.3, 0.0)
    assert belief.rule_out_blocked_facings(solid, 0.2, 0.3, 0.5) == pytest.approx(0.5)


def test_mass_gained_again_and_again_is_renormalised_before_float32_overflows():
    belief = TargetBelief(GRID, facing_sectors=1, prob_outside=0.05)
    for _ in range(12):
        belief.observe(np.array([0]), np.array([[1e5]]))
    assert np.isfinite(belief.mass_by_facing()).all() and belief.target_prob.flat[0] == pytest.approx(1.0)


def test_a_detection_probability_of_one_is_accepted_and_empties_the_cube():
    belief = TargetBelief(GRID, facing_sectors=2)
    assert belief.update_after_miss(np.arange(3), np.ones((3, 2))) == pytest.approx(0.95 * 3 / GRID.num_cubes)
    assert belief.target_prob.flat[:3].sum() == 0


def test_no_facing_sectors_is_refused():
    with pytest.raises(ValueError, match="facing_sectors ≥ 1"):
        TargetBelief(GRID, facing_sectors=0)


def test_a_surface_across_y_blocks_the_facings_toward_it():
    belief = TargetBelief(GRID, facing_sectors=4, prob_outside=0.1)  # facings +x, +y, -x, -y
    solid = np.zeros(GRID.shape, bool)
    solid[:, 6] = True  # a surface along x at y = 0.6-0.7 m
    belief.rule_out_blocked_facings(solid, 0.2, 0.3, 0.1)
    mass = belief.mass_by_facing()
    before = mass[0, 0, 0, 1]
    assert np.allclose(mass[:, 3:5, :, 1], 0.1 * before) and np.allclose(mass[:, 3:5, :, 3], before)  # south, facing it
    assert np.allclose(mass[:, 8:10, :, 3], 0.1 * before) and np.allclose(mass[:, 8:10, :, 1], before)  # north, facing back


def test_a_fresh_prior_or_a_restored_state_forgets_the_surfaces_folded_in():
    """set_prior left the blocked facings and the solid cubes done; restore left the solid cubes done:
    the same surface was then never folded in again."""
    solid = np.zeros(GRID.shape, bool)
    solid[10] = True
    belief = TargetBelief(GRID, facing_sectors=4)
    fresh_state = TargetBelief(GRID, facing_sectors=4).state()
    belief.rule_out_blocked_facings(solid, 0.2, 0.3, 0.1)
    belief.set_prior(np.ones(GRID.shape), 0.05)
    assert belief.rule_out_blocked_facings(solid, 0.2, 0.3, 0.1) > 0
    belief.restore(fresh_state)
    assert belief.rule_out_blocked_facings(solid, 0.2, 0.3, 0.1) > 0


def test_a_state_of_another_dtype_is_refused():
    belief = TargetBelief(GRID, facing_sectors=2)
    state = dict(belief.state(), mass=belief.state()["mass"].astype(np.float64))
    with pytest.raises(ValueError, match="belief mass: expected float32"):
        belief.restore(state)

"""The occupancy grid (eq. 5-8) on frames whose answer is known."""

import dataclasses
import math

import numpy as np
import pytest

from offboard.perception.occupancy import FREE, OCCUPIED, UNKNOWN, OccupancyConfig, OccupancyGrid
from offboard.perception.voxel_grid import VoxelGrid
from shared.geometry import HeadMount, Intrinsics, Pose2D

K = Intrinsics.from_fov(640, 480, 66.0)
MOUNT = HeadMount(1.2, 0.0, 0.12)
ROOM = VoxelGrid((6.0, 4.0, 2.5), 0.05)


def _wall_disparity(depth_m: float) -> np.ndarray:
    """A fronto-parallel wall ``depth_m`` ahead fills the image."""
    return np.full((K.height_px, K.width_px), K.fx_px * MOUNT.baseline_m / depth_m, np.float32)


def _facing_east(x=1.0, y=2.0):
    return MOUNT.camera_in_world(Pose2D(x, y, 0.0), 0.0, 0.0)


def test_a_wall_is_occupied_the_space_before_it_free_and_behind_it_unknown():
    occ = OccupancyGrid(ROOM)
    cam = _facing_east()
    occ.integrate_disparity(_wall_disparity(3.0), K, MOUNT.baseline_m, cam)
    wall_x = cam.translation[0] + 3.0  # 4.0 m
    j, k = int(2.0 / 0.05), int(1.2 / 0.05)
    state = occ.state()
    column = state[:, j, k]
    i_wall = int(wall_x / 0.05)
    assert OCCUPIED in column[i_wall - 2:i_wall + 2]
    assert (column[int(1.3 / 0.05):i_wall - 4] == FREE).all()
    assert (column[i_wall + 4:] == UNKNOWN).all()
    assert state[:, :, :].max() == OCCUPIED


def test_eq7_a_far_point_weighs_less_per_cube_than_a_near_one():
    near, far = OccupancyGrid(ROOM), OccupancyGrid(ROOM)
    for occ, depth in ((near, 1.0), (far, 4.0)):
        one_point = np.full((K.height_px, K.width_px), np.nan, np.float32)
        one_point[242, 322] = K.fx_px * MOUNT.baseline_m / depth
        occ.integrate_disparity(one_point, K, MOUNT.baseline_m, _facing_east())
    assert near.log_odds.max() > far.log_odds.max() > 0
    assert (far.log_odds > 0).sum() > (near.log_odds > 0).sum()  # |C| grows with distance
    assert far.log_odds[far.log_odds > 0].sum() == pytest.approx(1.0, abs=1e-5)  # 1/|C| over C


def test_eq6_a_point_covers_its_whole_pixel():
    """With coarse pixels a pixel is wider than a cube: the region spans its footprint, z/f wide."""
    coarse = Intrinsics.from_fov(16, 12, 66.0)
    occ, depth_m, baseline_m = OccupancyGrid(ROOM), 2.0, 1.0
    occ.integrate(np.array([8.0]), np.array([6.0]), np.array([coarse.fx_px * baseline_m / depth_m]), coarse,
                  baseline_m, _facing_east())
    cubes = np.argwhere(occ.log_odds > 0)
    width_m = (cubes.max(axis=0) - cubes.min(axis=0) + 1) * ROOM.resolution_m
    assert width_m[1] >= depth_m / coarse.fx_px and width_m[2] >= depth_m / coarse.fy_px  # across, up


def test_a_strided_pixel_lands_where_its_ray_points():
    """Each sampled pixel is at (u, v) = (s·a + s/2, s·b + s/2): without the s/2 it landed 13 cm off."""
    occ = OccupancyGrid(ROOM, OccupancyConfig(point_stride_px=32))
    cam, depth_m = _facing_east(), 4.0
    one_point = np.full((K.height_px, K.width_px), np.nan, np.float32)
    one_point[240, 336] = K.fx_px * MOUNT.baseline_m / depth_m  # sampled: 240 = 32·7 + 16, 336 = 32·10 + 16
    occ.integrate_disparity(one_point, K, MOUNT.baseline_m, cam)
    truth = ROOM.index_of(cam.apply(K.back_project(336.0, 240.0, depth_m)))
    cubes = np.argwhere(occ.log_odds > 0)
    assert occ.log_odds[tuple(truth)] > 0 and (np.abs(cubes[:, 1:] - truth[1:]) <= 1).all()


def test_stereo_beyond_max_range_is_dropped():
    occ = OccupancyGrid(ROOM, OccupancyConfig(max_range_m=4.0))
    assert occ.integrate_disparity(_wall_disparity(4.5), K, MOUNT.baseline_m, _facing_east()) == 0
    assert not occ.observed.any()
    assert occ.integrate_disparity(_wall_disparity(3.5), K, MOUNT.baseline_m, _facing_east()) > 0


CLEARING = OccupancyConfig(max_range_m=4.0, clear_beyond_range=True)


def test_told_to_stereo_beyond_max_range_clears_its_ray_out_to_the_range_and_hits_nothing():
    """OctoMap's maxrange: the wall 4.5 m off is too far to place, but nothing stands before it."""
    occ, cam = OccupancyGrid(ROOM, CLEARING), _facing_east()
    assert occ.integrate_disparity(_wall_disparity(4.5), K, MOUNT.baseline_m, cam) > 0
    column = occ.state()[:, int(2.0 / 0.05), int(1.2 / 0.05)]
    assert OCCUPIED not in occ.state()
    assert (column[int(1.3 / 0.05):int(4.9 / 0.05)] == FREE).all()  # the camera is at x = 1, the range ends at 5
    assert (column[int(5.1 / 0.05):] == UNKNOWN).all()


def test_told_to_a_ghost_that_only_far_rays_cross_is_cleared():
    """One frame's wrong disparity left an obstacle where only rays to points beyond max range pass:
    with those dropped, nothing ever cleared it (a start pocket sealed by ghosts)."""
    occ, cam = OccupancyGrid(ROOM, CLEARING), _facing_east()
    ghost = tuple(ROOM.index_of(cam.translation + np.array([2.0, 0.0, 0.0])))
    with occ.edit() as (log_odds, observed):
        log_odds[ghost], observed[ghost] = 1.0, True
    assert occ.state()[ghost] == OCCUPIED
    for _ in range(4):  # four misses of 0.4 outweigh one hit
        occ.integrate_disparity(_wall_disparity(4.5), K, MOUNT.baseline_m, cam)
    assert occ.state()[ghost] == FREE


def test_an_infinite_disparity_is_dropped_not_put_on_the_camera():
    """Depth f·B/d is 0 at d = inf: the camera's own cube came out occupied."""
    occ, cam = OccupancyGrid(ROOM), _facing_east()
    occ.integrate(np.array([320.0, 320.0]), np.array([240.0, 240.0]), np.array([np.inf, 20.0]), K,
                  MOUNT.baseline_m, cam)
    assert occ.log_odds[tuple(ROOM.index_of(cam.translation))] < 0  # free: the finite point's ray starts there
    assert (occ.log_odds > 0).any()


@pytest.mark.parametrize("part", ["rotation", "translation"])
def test_a_frame_from_a_non_finite_pose_is_refused(part):
    """A NaN rotation updated a stray cube; a NaN translation dropped the frame; neither said so."""
    cam = _facing_east()
    lost = dataclasses.replace(cam, **{part: getattr(cam, part) * np.nan})
    with pytest.raises(ValueError, match=f"finite camera pose, not {part}"):
        OccupancyGrid(ROOM).integrate_disparity(_wall_disparity(3.0), K, MOUNT.baseline_m, lost)


@pytest.mark.parametrize("field", ["cx_px", "cy_px"])
def test_a_frame_from_a_camera_with_no_principal_point_is_refused(field):
    """A NaN principal point dropped every point of the frame and marked only the camera's cube free."""
    lost = dataclasses.replace(K, **{field: float("nan")})
    with pytest.raises(ValueError, match="finite principal point"):
        OccupancyGrid(ROOM).integrate_disparity(_wall_disparity(3.0), lost, MOUNT.baseline_m, _facing_east())


@pytest.mark.parametrize("u, v, d, says", [
    (np.zeros(3), np.zeros(2), np.ones(3), "one length each"),  # once a bare IndexError in the kernel
    (np.zeros((2, 2)), np.zeros((2, 2)), np.ones((2, 2)), "one length each"),
])
def test_stereo_points_that_do_not_pair_up_are_refused(u, v, d, says):
    with pytest.raises(ValueError, match=says):
        OccupancyGrid(ROOM).integrate(u, v, d, K, MOUNT.baseline_m, _facing_east())


def test_a_disparity_image_that_is_not_2d_is_refused():
    with pytest.raises(ValueError, match="disparity image is 2-D"):
        OccupancyGrid(ROOM).integrate_disparity(np.ones(640, np.float32), K, MOUNT.baseline_m, _facing_east())


def test_log_odds_stop_at_the_clamps():
    occ = OccupancyGrid(ROOM)
    for _ in range(6):  # +1 a frame on the wall, -0.4 before it: past both clamps (a changed world is re-learnt)
        occ.integrate_disparity(_wall_disparity(3.0), K, MOUNT.baseline_m, _facing_east())
    assert occ.log_odds.max() == occ.config.clamp_max and occ.log_odds.min() == occ.config.clamp_min


def test_each_cube_is_updated_once_per_frame():
    occ = OccupancyGrid(ROOM, OccupancyConfig(point_stride_px=1))
    occ.integrate_disparity(_wall_disparity(2.0), K, MOUNT.baseline_m, _facing_east())
    assert occ.log_odds.min() >= -0.4 - 1e-6  # one miss at most, though many rays cross each cube
    assert occ.log_odds.max() <= 1.0 + 1e-6


def test_a_ghost_fades_when_later_frames_see_through_it():
    occ = OccupancyGrid(ROOM)
    cam = _facing_east()
    ghost = np.full((K.height_px, K.width_px), np.nan, np.float32)
    ghost[200:280, 280:360] = K.fx_px * MOUNT.baseline_m / 1.5  # one noisy frame: something 1.5 m ahead
    occ.integrate_disparity(ghost, K, MOUNT.baseline_m, cam)
    probe = np.array([[cam.translation[0] + 1.5, 2.0, 1.2]])
    assert occ.state()[tuple(ROOM.index_of(probe)[0])] == OCCUPIED
    for _ in range(4):
        occ.integrate_disparity(_wall_disparity(3.0), K, MOUNT.baseline_m, cam)
    assert occ.state()[tuple(ROOM.index_of(probe)[0])] == FREE


def test_ray_casting_stops_at_the_first_occupied_cube_and_passes_unknown_space():
    occ = OccupancyGrid(ROOM)
    cam = _facing_east()
    occ.integrate_disparity(_wall_disparity(3.0), K, MOUNT.baseline_m, cam)
    rays = occ.cast_rays(cam.translation, np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 0, 1.0]]), 10.0)
    assert rays.distance_m[0] == pytest.approx(3.0, abs=0.1) and rays.hit[0]
    # never observed behind or above: the rays cross that space to the room's west wall and ceiling
    assert rays.distance_m[1] == pytest.approx(1.0, abs=0.05) and rays.hit[1]
    assert rays.distance_m[2] == pytest.approx(ROOM.size_m[2] - cam.translation[2], abs=0.05) and rays.hit[2]
    short = occ.cast_rays(cam.translation, np.array([[1.0, 0, 0]]), 1.0)
    assert not short.hit[0] and short.distance_m[0] == pytest.approx(1.0)


def test_rays_from_many_origins_each_follow_their_own_direction_or_are_refused():
    occ = OccupancyGrid(ROOM)
    occ.integrate_disparity(_wall_disparity(3.0), K, MOUNT.baseline_m, _facing_east())  # a wall at x = 4 m
    origins = np.array([[1.0, 2.0, 1.2], [2.0, 2.0, 1.2], [3.0, 2.0, 1.2]])
    rays = occ.cast_rays(origins, np.array([1.0, 0.0, 0.0]), 10.0)  # one direction for all three
    assert rays.distance_m == pytest.approx([3.0, 2.0, 1.0], abs=0.1) and rays.hit.all()
    with pytest.raises(ValueError, match="one origin or one per direction"):  # the kernel read past the end
        occ.cast_rays(origins, np.array([[1.0, 0, 0], [0, 1.0, 0]]), 10.0)
    with pytest.raises(ValueError, match="zero vector"):  # it walked NaN to max range, unsaid
        occ.cast_rays(origins[0], np.zeros(3), 10.0)


@pytest.mark.parametrize("origin, direction, max_range_m, bad", [
    ((np.nan, 2.0, 1.2), (1.0, 0.0, 0.0), 5.0, "finite origins"),  # was a hit at 0 m
    ((1.0, 2.0, 1.2), (np.inf, 0.0, 0.0), 5.0, "finite directions"),  # ran to max range, no hit
    ((1.0, 2.0, 1.2), (np.nan, 0.0, 0.0), 5.0, "finite directions"),  # was called the zero vector
    ((1.0, 2.0, 1.2), (1.0, 0.0, 0.0), -1.0, "finite, positive max range"),  # distance -1 m
    ((1.0, 2.0, 1.2), (1.0, 0.0, 0.0), 0.0, "finite, positive max range"),
    ((1.0, 2.0, 1.2), (1.0, 0.0, 0.0), np.nan, "finite, positive max range"),  # distance NaN
    ((1.0, 2.0, 1.2), (1.0, 0.0, 0.0), np.inf, "finite, positive max range"),
])
def test_rays_with_non_finite_input_are_refused(origin, direction, max_range_m, bad):
    with pytest.raises(ValueError, match=bad):
        OccupancyGrid(ROOM).cast_rays(np.array(origin), np.array(direction), max_range_m)


@pytest.mark.parametrize("baseline_m", [0.0, -0.12])
def test_a_frame_without_a_positive_baseline_is_refused(baseline_m):
    """At 0 every point fell on the camera's own cube; negative, stereo carved free space behind it."""
    with pytest.raises(ValueError, match="positive baseline"):
        OccupancyGrid(ROOM).integrate_disparity(_wall_disparity(3.0), K, baseline_m, _facing_east())


@pytest.mark.parametrize("changes", [{"clamp_max": 0.3}, {"free_log_odds": -0.1, "occupied_log_odds": -0.2},
                                     {"clamp_min": -0.2}])
def test_thresholds_the_clamps_make_unreachable_are_refused(changes):
    """A clamp under the occupied threshold left a wall seen twenty times unoccupied."""
    with pytest.raises(ValueError, match="clamp_min <= free_log_odds < occupied_log_odds <= clamp_max"):
        OccupancyConfig(**changes)


@pytest.mark.parametrize("changes", [{"occupied_log_odds": 0.0}, {"free_log_odds": 0.0}])
def test_thresholds_that_do_not_straddle_no_evidence_are_refused(changes):
    """Occupied at 0, every unobserved cube was: each ray stopped at 0 m, the floor map was all blocked."""
    with pytest.raises(ValueError, match="free_log_odds < 0 < occupied_log_odds"):
        OccupancyConfig(**changes)


def _scene(*occupied_cubes) -> OccupancyGrid:
    """Every cube observed and free but ``occupied_cubes``, each an (i, j, k)."""
    occ = OccupancyGrid(ROOM)
    with occ.edit() as (log_odds, observed):
        observed[:] = True
        log_odds[:] = -1.0
        for cube in occupied_cubes:
            log_odds[cube] = 2.0
    return occ


def test_floor_map_ignores_noise_under_the_clearance_and_overhangs_over_the_robot():
    low, high = (60, 20, 2), (60, 60, 26)  # the band's ends: 10-15 cm and 1.30-1.35 m
    noise, overhang = (30, 40, 1), (90, 40, 27)  # 5-10 cm, 1.35-1.40 m
    fm = _scene(low, high, noise, overhang).floor_map(robot_radius_m=0.1, robot_height_m=1.35,
                                                      floor_clearance_m=0.1)
    assert fm.blocked[60, 20] and fm.blocked[60, 60]
    assert not fm.blocked[30, 40] and not fm.blocked[90, 40]


def test_floor_map_rounds_the_robot_radius_up():
    """0.12 m is 2.4 cubes: the base keeps 3 cubes off an obstacle, never less than its radius."""
    fm = _scene((60, 40, 10)).floor_map(robot_radius_m=0.12, robot_height_m=1.35)
    assert fm.blocked[63, 40] and fm.blocked[60, 37] and not fm.blocked[64, 40]


def test_a_robot_of_no_radius_blocks_what_is_occupied_and_the_walls_add_nothing():
    occ = OccupancyGrid(ROOM)
    occ.integrate_disparity(_wall_disparity(2.0), K, MOUNT.baseline_m, _facing_east())
    fm = occ.floor_map(robot_radius_m=0.0, robot_height_m=1.35)
    assert fm.blocked.shape == fm.occupied.shape and np.array_equal(fm.blocked, fm.occupied)


def test_floor_map_blocks_obstacles_in_the_robot_band_inflated_by_its_radius():
    occ = OccupancyGrid(ROOM)
    occ.integrate_disparity(_wall_disparity(2.0), K, MOUNT.baseline_m, _facing_east())
    fm = occ.floor_map(robot_radius_m=0.26, robot_height_m=1.35)
    i_wall, j = int(3.0 / 0.05), int(2.0 / 0.05)
    assert fm.occupied[i_wall - 1:i_wall + 2, j].any()
    assert fm.blocked[i_wall - 5, j] and not fm.blocked[i_wall - 8, j]  # 0.26 m = 5.2 cells
    assert fm.blocked[0, j] and fm.blocked[:, 0].all()  # near the room's walls
    assert not fm.unknown[int(2.0 / 0.05), j] and fm.unknown[-1, j]


def test_tilted_views_place_points_in_the_right_world_cubes():
    occ = OccupancyGrid(ROOM)
    cam = MOUNT.camera_in_world(Pose2D(1.0, 2.0, 0.0), 0.0, math.radians(-30))
    # the floor: a ray through pixel (u, v) hits z = 0 at depth z_cam; give each pixel that disparity
    rays = cam.rotation @ K.pixel_rays().reshape(-1, 3).T
    t = -cam.translation[2] / rays[2]
    disparity = np.where(t > 0, K.fx_px * MOUNT.baseline_m / np.where(t > 0, t, 1), np.nan).reshape(480, 640)
    occ.integrate_disparity(disparity.astype(np.float32), K, MOUNT.baseline_m, cam)
    occupied_z = ROOM.centers()[occ.occupied()][:, 2]
    assert occupied_z.size > 0 and np.percentile(occupied_z, 95) < 0.15


def test_a_coarsened_map_keeps_obstacles_and_what_was_observed():
    occ = OccupancyGrid(ROOM)
    occ.integrate_disparity(_wall_disparity(2.0), K, MOUNT.baseline_m, _facing_east())
    coarse = occ.coarsened(4)
    assert coarse.grid.resolution_m == pytest.approx(0.2) and coarse.grid.shape == (30, 20, 13)
    occupied_fine = ROOM.centers()[occ.occupied()]
    assert coarse.occupied()[tuple(coarse.grid.index_of(occupied_fine).T)].all()
    assert coarse.observed.sum() < occ.observed.sum() and (coarse.state() == FREE).any()
    rays = coarse.cast_rays(_facing_east().translation, np.array([[1.0, 0, 0]]), 10.0)
    assert rays.distance_m[0] == pytest.approx(2.0, abs=0.25)


def _pooled(occ: OccupancyGrid, factor: int) -> tuple[np.ndarray, np.ndarray]:
    """coarsened() from its definition, in numpy: per block, the largest observed log-odds (0 where
    no cube is observed) and whether any cube is observed."""
    pad = [(0, -n % factor) for n in occ.grid.shape]
    values = np.pad(np.where(occ.observed, occ.log_odds, -np.inf), pad, constant_values=-np.inf)
    blocks = [n // factor for n in values.shape]
    shape = (blocks[0], factor, blocks[1], factor, blocks[2], factor)
    observed = np.pad(occ.observed, pad).reshape(shape).any(axis=(1, 3, 5))
    return np.where(observed, values.reshape(shape).max(axis=(1, 3, 5)), 0).astype(np.float32), observed


def test_a_coarsened_map_follows_frames_and_direct_writes_between_calls():
    rng = np.random.default_rng(7)
    occ = OccupancyGrid(ROOM)
    rows, cols = np.mgrid[0:K.height_px, 0:K.width_px]
    for step in range(12):
        if step % 4 == 3:  # written directly, as the navigator marks a contact: in the last frame's view
            ahead = cam.translation + cam.rotation[:, 2]
            region = ROOM.box_slices(ahead - 0.2, ahead + 0.2)
            with occ.edit() as (log_odds, observed):
                if step % 8 == 3:
                    log_odds[region] = rng.uniform(-2.0, 3.5)
                else:
                    observed[region] = ~observed[region]
        else:  # a frame of a wavy surface 1-4 m ahead, from anywhere in the room
            pose = Pose2D(*rng.uniform((0.5, 0.5, -math.pi), (5.5, 3.5, math.pi)))
            cam = MOUNT.camera_in_world(pose, rng.uniform(-0.6, 0.6), rng.uniform(-0.5, 0.2))
            waves = np.sin(cols / rng.uniform(20, 150)) * np.cos(rows / rng.uniform(20, 150))
            depth = rng.uniform(1.0, 4.0) + 0.5 * waves
            occ.integrate_disparity((K.fx_px * MOUNT.baseline_m / depth).astype(np.float32), K, MOUNT.baseline_m, cam)
        for factor in (2, 3):
            coarse = occ.coarsened(factor)
            log_odds, observed = _pooled(occ, factor)
            assert np.array_equal(coarse.log_odds, log_odds) and np.array_equal(coarse.observed, observed)
    with pytest.raises(ValueError, match="read-only"):  # written through edit() only: coarsened() must know
        occ.log_odds[0, 0, 0] = 1.0


def test_seen_empty_keeps_a_margin_around_surfaces_unknown_space_and_the_room():
    occ = OccupancyGrid(ROOM)
    cam = _facing_east()
    occ.integrate_disparity(_wall_disparity(3.0), K, MOUNT.baseline_m, cam)
    occ.integrate_disparity(_wall_disparity(3.0), K, MOUNT.baseline_m, cam)  # twice: log-odds -0.8 before the wall
    j, k = int(2.0 / 0.05), int(1.2 / 0.05)
    i_wall = int(np.argmax(occ.occupied()[:, j, k]))
    plain = occ.seen_empty(-0.8)
    kept = occ.seen_empty(-0.8, margin_cubes=3)
    assert plain[i_wall - 3, j, k] and not kept[i_wall - 3, j, k]  # next to the wall: kept
    assert kept[i_wall - 10, j, k]  # open air in front of it: empty
    assert not kept[:, :, :3].any() and not kept[:3].any()  # the floor, the room's boundary
    assert kept[i_wall - 4, j, k]  # the margin is three cubes: the fourth out is empty
    with occ.edit() as (_, observed):
        observed[i_wall - 10, j + 2, k] = False  # unknown space two cubes beside it: kept
    assert not occ.seen_empty(-0.8, margin_cubes=3)[i_wall - 10, j, k]

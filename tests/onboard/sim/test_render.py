"""The stereo renderer: true depth, occlusion, the target's picture, rectification, and that real
OpenCV block matching and SIFT work on what it draws."""

from __future__ import annotations

import math
from dataclasses import replace

import cv2
import numpy as np
import pytest

from onboard.sim.preview import write_preview
from onboard.sim.render import StereoRenderer
from onboard.sim.textures import load_picture
from onboard.sim.world import load_world
from shared.world import World, parse_world
from shared.geometry import HeadMount, Intrinsics, Pose2D, RigidTransform

K = Intrinsics.from_fov(640, 480, 66.0)
MOUNT = HeadMount()
BEHIND = (0.3, 3.7)  # out of view of a robot at the bare room's start, which faces +x


def room_world(tmp_path, obstacles=(), target_at=(0.5, 3.5, 0.0, 0.0)) -> World:
    """A bare 6 x 4 x 2.5 m room; the target defaults to a corner behind a robot facing +x."""
    x, y, z, yaw = target_at
    data = {
        "name": "bare",
        "room": {"size": [6.0, 4.0, 2.5]},
        "obstacle": [{"name": f"box-{i}", "min": list(lo), "max": list(hi)} for i, (lo, hi) in enumerate(obstacles)],
        "target": {"size": [0.23, 0.23, 0.23], "position": [x, y, z], "yaw_deg": yaw},
        "robot": {"start": [1.0, 2.0], "heading_deg": 0.0},
    }
    return parse_world(data, tmp_path)


def analytic_depth(pose: Pose2D, tilt: float, u, v, axis: int = 2, plane: float = 0.0) -> np.ndarray:
    """z-depth of the plane ``world[axis] = plane`` (default: the floor) seen through pixels (u, v)
    of the left camera."""
    u, v = np.broadcast_arrays(np.asarray(u, float), np.asarray(v, float))
    cam = MOUNT.camera_in_world(pose, 0.0, tilt, "left")
    rays = np.stack([(u - K.cx_px) / K.fx_px, (v - K.cy_px) / K.fy_px, np.ones_like(u)], -1)
    dirs = rays @ cam.rotation.T
    return (plane - cam.translation[axis]) / dirs[..., axis]  # a ray with camera z = 1: t is depth


def target_shift(world: World, xy: tuple[float, float] | None = None) -> World:
    """The same world with the target moved out of the way: on the floor at ``xy``, by default in
    the far corner of the room."""
    x, y = xy or (world.room.size_m[0] - 0.3, world.room.size_m[1] - 0.3)
    return world.with_target(x, y, 0.0, 180.0)


@pytest.fixture(scope="module")
def lab() -> World:
    return load_world("paper-lab")


@pytest.fixture(scope="module")
def lab_renderer(lab) -> StereoRenderer:
    return StereoRenderer(lab, K, MOUNT)


def look_at_target(world: World, distance_m: float) -> tuple[World, float, np.ndarray]:
    """Robot ``distance_m`` in front of the target's picture, facing it, tilted to its centre.
    Returns the world with that start, the tilt and the picture centre in the world."""
    t = world.target
    face = t.center_m() + t.facing() * t.size_m[0] / 2
    xy = face[:2] + t.facing()[:2] * distance_m
    placed = world.with_start(xy[0], xy[1], math.atan2(-t.facing()[1], -t.facing()[0]))
    return placed, math.atan2(face[2] - MOUNT.height_m, distance_m), face


def project(pose: Pose2D, tilt: float, points: np.ndarray) -> np.ndarray:
    return K.project(MOUNT.camera_in_world(pose, 0.0, tilt, "left").inverse().apply(points))


def test_frame_format_and_determinism(lab, lab_renderer):
    frame = lab_renderer.render(lab.start, 0.0, 0.0)
    assert frame.left.shape == frame.right.shape == (480, 640, 3)
    assert frame.left.dtype == frame.right.dtype == np.uint8
    assert frame.depth_m.shape == (480, 640) and frame.depth_m.dtype == np.float32
    assert np.all(np.isfinite(frame.depth_m)) and frame.depth_m.min() > 0.0
    again = StereoRenderer(lab, K, MOUNT).render(lab.start, 0.0, 0.0)
    for a, b in ((frame.left, again.left), (frame.right, again.right), (frame.depth_m, again.depth_m)):
        np.testing.assert_array_equal(a, b)


def test_depth_of_a_facing_wall_and_the_floor_is_exact(tmp_path):
    world = room_world(tmp_path)
    renderer = StereoRenderer(world, K, MOUNT)
    _, depth = renderer.render_view(MOUNT.camera_in_world(world.start, 0.0, 0.0, "left"))
    np.testing.assert_allclose(depth[200:280, 280:360], 5.0, rtol=1e-5)  # east wall, 5 m ahead
    u = np.arange(0, 640, 7.0)
    np.testing.assert_allclose(depth[479, ::7], analytic_depth(world.start, 0.0, u, 479.0), rtol=1e-5)
    tilt = -0.5  # looking down: the floor fills the lower image, depth by ray-plane geometry
    frame = renderer.render(world.start, 0.0, tilt)
    v, u = np.mgrid[300:480:9, 0:640:11].astype(float)
    np.testing.assert_allclose(frame.depth_m[300:480:9, 0:640:11], analytic_depth(world.start, tilt, u, v),
                               rtol=1e-5)


def test_a_box_in_front_occludes_what_is_behind_it(tmp_path):
    target_at = (5.8, 2.0, 0.0, 180.0)  # on the floor against the east wall, facing the robot
    crate = ((3.0, 1.5, 0.0), (3.5, 2.5, 1.5))
    open_room = room_world(tmp_path, target_at=target_at)
    blocked = room_world(tmp_path, obstacles=[crate], target_at=target_at)
    pose = open_room.start
    seen = StereoRenderer(open_room, K, MOUNT).render(pose, 0.0, -0.2)
    hidden = StereoRenderer(blocked, K, MOUNT).render(pose, 0.0, -0.2)
    hidden_moved = StereoRenderer(target_shift(blocked, BEHIND), K, MOUNT).render(pose, 0.0, -0.2)
    v, u = np.mgrid[230:250, 300:340]
    np.testing.assert_allclose(hidden.depth_m[230:250, 300:340], analytic_depth(pose, -0.2, u, v, 0, 3.0),
                               rtol=1e-5)  # the crate's face at x = 3 m
    open_moved = StereoRenderer(target_shift(open_room, BEHIND), K, MOUNT).render(pose, 0.0, -0.2)
    assert np.any(seen.left != open_moved.left), "without the crate the target is in view"
    np.testing.assert_array_equal(hidden.left, hidden_moved.left)  # with it, nothing of the target shows


def test_the_target_picture_appears_where_geometry_puts_it(lab, lab_renderer):
    placed, tilt, _ = look_at_target(lab, 1.0)
    frame = lab_renderer.render(placed.start, 0.0, tilt)
    without = StereoRenderer(target_shift(placed), K, MOUNT).render(placed.start, 0.0, tilt)
    box = placed.target.box()
    corners3d = np.array([[x, y, z] for x in (box.min_m[0], box.max_m[0]) for y in (box.min_m[1], box.max_m[1])
                          for z in (box.min_m[2], box.max_m[2])])
    lo, hi = project(placed.start, tilt, corners3d).min(axis=0), project(placed.start, tilt, corners3d).max(axis=0)
    changed = np.argwhere(np.any(frame.left != without.left, axis=2))
    assert len(changed) > 2000
    assert np.all(changed[:, 1] >= lo[0] - 1) and np.all(changed[:, 1] <= hi[0] + 1)
    assert np.all(changed[:, 0] >= lo[1] - 1) and np.all(changed[:, 0] <= hi[1] + 1)
    # The picture, warped where its corners project, matches the render (upright, not mirrored).
    picture = load_picture(placed.target.picture, placed.base_dir)
    h, w = picture.shape[:2]
    quad = project(placed.start, tilt, placed.target.picture_corners_m()).astype(np.float32)
    src = np.float32([[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]])
    expected = cv2.warpPerspective(picture, cv2.getPerspectiveTransform(src, quad), (640, 480))
    inner = cv2.erode(cv2.fillConvexPoly(np.zeros((480, 640), np.uint8), quad.astype(np.int32), 1), np.ones((5, 5)))
    a, b = (cv2.cvtColor(img, cv2.COLOR_RGB2GRAY)[inner > 0].astype(float) for img in (frame.left, expected))
    assert np.corrcoef(a, b)[0, 1] > 0.9


def test_a_yawed_target_is_where_its_pose_says(tmp_path):
    post = ((2.95, 2.25, 0.0), (3.05, 2.35, 0.6))  # under the target, out of sight below it
    world = room_world(tmp_path, obstacles=[post], target_at=(3.0, 2.3, 0.6, 150.0))  # turned 30 deg off us
    tilt = -0.3
    frame = StereoRenderer(world, K, MOUNT).render(world.start, 0.0, tilt)
    corners = world.target.picture_corners_m()
    pixel = project(world.start, tilt, corners.mean(axis=0))
    u, v = np.round(pixel).astype(int)
    camera = MOUNT.camera_in_world(world.start, 0.0, tilt, "left")
    point = camera.apply(K.pixel_rays()[v, u] * frame.depth_m[v, u])
    # The pixel's surface point lies on the picture's plane, close to the face centre.
    normal = world.target.facing()
    assert (point - corners.mean(axis=0)) @ normal == pytest.approx(0.0, abs=1e-4)
    assert np.linalg.norm(point - corners.mean(axis=0)) < 0.01


def test_the_pair_is_rectified_with_true_disparities(lab, lab_renderer):
    frame = lab_renderer.render(Pose2D(4.5, 2.0, 0.0), 0.0, -0.3)
    sift = cv2.SIFT_create()
    kl, dl = sift.detectAndCompute(cv2.cvtColor(frame.left, cv2.COLOR_RGB2GRAY), None)
    kr, dr = sift.detectAndCompute(cv2.cvtColor(frame.right, cv2.COLOR_RGB2GRAY), None)
    good = [m for m, n in cv2.BFMatcher().knnMatch(dl, dr, k=2) if m.distance < 0.75 * n.distance]
    assert len(good) > 500
    pl = np.array([kl[m.queryIdx].pt for m in good])
    pr = np.array([kr[m.trainIdx].pt for m in good])
    dy = np.abs(pl[:, 1] - pr[:, 1])
    assert np.median(dy) < 0.1 and np.percentile(dy, 90) < 0.5
    rows = dy < 0.5
    disparity = (pl[:, 0] - pr[:, 0])[rows]
    truth = K.fx_px * MOUNT.baseline_m / frame.depth_m[np.round(pl[rows, 1]).astype(int),
                                                         np.round(pl[rows, 0]).astype(int)]
    assert np.mean(disparity > 0) > 0.9
    assert np.median(np.abs(disparity - truth)) < 0.5


def test_block_matching_recovers_the_true_disparity(lab, lab_renderer):
    frame = lab_renderer.render(lab.start, 0.0, 0.0)
    matcher = cv2.StereoBM_create(numDisparities=96, blockSize=15)
    grey = [cv2.cvtColor(img, cv2.COLOR_RGB2GRAY) for img in (frame.left, frame.right)]
    disparity = matcher.compute(*grey).astype(np.float32) / 16.0
    valid = disparity > 0
    truth = K.fx_px * MOUNT.baseline_m / frame.depth_m
    assert valid.mean() > 0.6  # every surface is textured (the left 96 columns cannot match)
    error = np.median(np.abs(disparity - truth)[valid])
    assert error < 1.0, f"median BM disparity error {error:.3f} px"


@pytest.mark.parametrize("distance_m", [0.5, 1.0, 2.0, 3.0])
def test_sift_finds_the_target_picture(lab, lab_renderer, distance_m):
    # At 3 m the 0.23 m picture spans ~38 px (18 inliers when written); at 0.5 m it fills half the view.
    placed, tilt, face = look_at_target(lab, distance_m)
    left = lab_renderer.render(placed.start, 0.0, tilt).left
    picture = load_picture(placed.target.picture, placed.base_dir)
    sift = cv2.SIFT_create()
    kp, dp = sift.detectAndCompute(cv2.cvtColor(picture, cv2.COLOR_RGB2GRAY), None)
    ki, di = sift.detectAndCompute(cv2.cvtColor(left, cv2.COLOR_RGB2GRAY), None)
    good = [m for m, n in cv2.BFMatcher().knnMatch(dp, di, k=2) if m.distance < 0.75 * n.distance]
    src = np.float32([kp[m.queryIdx].pt for m in good])
    dst = np.float32([ki[m.trainIdx].pt for m in good])
    homography, mask = cv2.findHomography(src, dst, cv2.RANSAC, 3.0)
    assert homography is not None and int(mask.sum()) >= 10
    h, w = picture.shape[:2]
    centre = cv2.perspectiveTransform(np.float32([[[(w - 1) / 2, (h - 1) / 2]]]), homography)[0, 0]
    expected = project(placed.start, tilt, face)
    assert np.linalg.norm(centre - expected) < 3.0


@pytest.mark.parametrize("sides", [1, 4])
def test_a_target_with_four_sides_is_recognised_from_every_direction(tmp_path, sides):
    from offboard.perception.detection import TargetModel, make_detector

    post = ((2.95, 1.95, 0.0), (3.05, 2.05, 0.8))  # under the target, out of sight below it
    world = room_world(tmp_path, obstacles=[post], target_at=(3.0, 2.0, 0.8, 30.0))
    world = replace(world, target=replace(world.target, sides=sides))
    renderer = StereoRenderer(world, K, MOUNT)
    picture = load_picture(world.target.picture, world.base_dir)
    sift = make_detector("sift", TargetModel((picture,), world.target.size_m), K)
    found = []
    for turn in (0.0, 90.0, 180.0, 270.0):  # the picture's own side first, then its other sides
        facing = np.array([math.cos(math.radians(30.0 + turn)), math.sin(math.radians(30.0 + turn))])
        xy = world.target.center_m()[:2] + 1.5 * facing
        pose = Pose2D(xy[0], xy[1], math.atan2(-facing[1], -facing[0]))
        detection = sift.detect(renderer.render(pose, 0.0, math.radians(-10.0)).left)
        found.append(detection is not None and abs(detection.center_px[0] - K.cx_px) < 40)  # left camera: ~20 px off
    assert found == ([True] * 4 if sides == 4 else [True, False, False, False])


def target_pixels(world: World, camera: RigidTransform, depth: np.ndarray) -> np.ndarray:
    """Mask of the pixels whose depth puts them on the target's surface."""
    t = world.target
    points = camera.apply(K.pixel_rays() * depth[..., None]) - t.center_m()
    forward, left = t.facing(), np.cross([0.0, 0.0, 1.0], t.facing())
    local = np.stack([points @ forward, points @ left, points[..., 2]], axis=-1)
    return np.all(np.abs(local) <= np.array(t.size_m) / 2 + 2e-3, axis=-1)


def test_the_high_shelf_target_needs_an_upward_tilt():
    world = load_world("high-shelf")
    renderer = StereoRenderer(world, K, MOUNT)

    def seen_px(x: float, y: float, tilt_deg: float) -> int:
        world.with_start(x, y, 0.0)  # a reachable position
        target = world.target.center_m()
        pose = Pose2D(x, y, math.atan2(target[1] - y, target[0] - x))  # aimed at the target
        camera = MOUNT.camera_in_world(pose, 0.0, math.radians(tilt_deg), "left")
        return int(target_pixels(world, camera, renderer.render_view(camera)[1]).sum())

    in_front = [(2.2, 4.0), (2.7, 4.0), (3.0, 4.0), (2.7, 4.3)]  # the open floor before the alcove
    for x, y in in_front:
        assert seen_px(x, y, 0.0) == 0, (x, y)  # above a level view
        assert seen_px(x, y, 30.0) > 500, (x, y)
    assert seen_px(6.0, 4.7, 0.0) == 0  # from the side the shelving hides it


def test_the_renderer_refuses_a_camera_outside_the_room(lab_renderer):
    with pytest.raises(ValueError, match="not inside the room"):
        lab_renderer.render(Pose2D(-1.0, 2.0, 0.0), 0.0, 0.0)


def test_write_preview(tmp_path, lab):
    paths = write_preview(lab, lab.start, 0.1, -0.1, tmp_path / "out", K, MOUNT)
    assert [p.name for p in paths] == ["left.png", "right.png", "depth.npy"]
    frame = StereoRenderer(lab, K, MOUNT).render(lab.start, 0.1, -0.1)
    np.testing.assert_array_equal(cv2.cvtColor(cv2.imread(str(paths[0])), cv2.COLOR_BGR2RGB), frame.left)
    np.testing.assert_array_equal(cv2.cvtColor(cv2.imread(str(paths[1])), cv2.COLOR_BGR2RGB), frame.right)
    depth = np.load(paths[2])
    assert depth.dtype == np.float32
    np.testing.assert_array_equal(depth, frame.depth_m)

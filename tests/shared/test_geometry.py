"""Frame conventions, checked with directions anyone can picture."""

import math

import numpy as np
import pytest

from shared.geometry import HeadMount, Intrinsics, Pose2D, RigidTransform, rot_z

MOUNT = HeadMount(height_m=1.2, forward_m=0.1, baseline_m=0.12)


def _axis(t: RigidTransform, column: int) -> np.ndarray:
    return t.rotation[:, column]


def test_optical_axis_follows_heading_pan_and_tilt():
    cam = MOUNT.camera_in_world(Pose2D(2.0, 1.0, 0.0), 0.0, 0.0)
    np.testing.assert_allclose(_axis(cam, 2), [1, 0, 0], atol=1e-12)  # looks along +x
    np.testing.assert_allclose(_axis(cam, 0), [0, -1, 0], atol=1e-12)  # image right is the robot's right
    np.testing.assert_allclose(_axis(cam, 1), [0, 0, -1], atol=1e-12)  # image down is down
    left = MOUNT.camera_in_world(Pose2D(2.0, 1.0, math.pi / 2), math.radians(90), 0.0)
    np.testing.assert_allclose(_axis(left, 2), [-1, 0, 0], atol=1e-12)  # heading +y, pan left → -x
    up = MOUNT.camera_in_world(Pose2D(0.0, 0.0, 0.0), 0.0, math.radians(30))
    np.testing.assert_allclose(_axis(up, 2), [math.cos(math.radians(30)), 0, math.sin(math.radians(30))], atol=1e-12)


def test_stereo_cameras_sit_a_baseline_apart_and_left_is_left():
    pose = Pose2D(3.0, 2.0, 0.3)
    left = MOUNT.camera_in_world(pose, 0.2, -0.1, "left")
    right = MOUNT.camera_in_world(pose, 0.2, -0.1, "right")
    right_in_left = left.inverse().compose(right)
    np.testing.assert_allclose(right_in_left.translation, [MOUNT.baseline_m, 0, 0], atol=1e-12)
    np.testing.assert_allclose(right_in_left.rotation, np.eye(3), atol=1e-12)
    head = pose.to_transform().apply(np.array([MOUNT.forward_m, 0, MOUNT.height_m]))
    np.testing.assert_allclose((left.translation + right.translation) / 2, head, atol=1e-12)


def test_transform_inverse_and_compose():
    a = RigidTransform(rot_z(0.7), np.array([1.0, 2.0, 3.0]))
    b = RigidTransform(rot_z(-0.2), np.array([0.5, 0.0, -1.0]))
    p = np.array([[0.3, -0.4, 2.0]])
    np.testing.assert_allclose(a.compose(b).apply(p), a.apply(b.apply(p)))
    np.testing.assert_allclose(a.inverse().apply(a.apply(p)), p)


def test_poses_compose_and_invert_as_their_transforms_do():
    a, b = Pose2D(1.0, 2.0, 3.0), Pose2D(-0.3, 0.5, -2.0)  # headings that sum past pi: wrapped
    for pose, transform in ((a.compose(b), a.to_transform().compose(b.to_transform())),
                            (a.inverse(), a.to_transform().inverse())):
        np.testing.assert_allclose(pose.to_transform().rotation, transform.rotation, atol=1e-12)
        np.testing.assert_allclose(pose.to_transform().translation, transform.translation, atol=1e-12)
    assert -math.pi <= a.compose(b).heading_rad < math.pi and a.compose(b).heading_rad == pytest.approx(1.0)


def test_projection_of_pixel_rays_lands_on_the_pixels():
    k = Intrinsics.from_fov(640, 480, 66.0)
    assert k.fx_px == pytest.approx(492.8, abs=0.5)  # a Bumblebee2 with 3.8 mm lenses: 66° across 640 px
    rays = k.pixel_rays()
    uv = k.project(rays * 3.0)
    np.testing.assert_allclose(uv[..., 0], np.broadcast_to(np.arange(640), (480, 640)), atol=1e-9)
    np.testing.assert_allclose(uv[..., 1], np.broadcast_to(np.arange(480)[:, None], (480, 640)), atol=1e-9)
    assert np.isnan(k.project(np.array([0.0, 0.0, -1.0]))).all()


def test_back_projection_undoes_projection_and_keeps_float32():
    k = Intrinsics.from_fov(640, 480, 66.0)
    points = np.array([[0.4, -0.3, 2.0], [-1.0, 0.2, 5.0]])
    pixels = k.project(points)
    assert k.back_project(pixels[:, 0], pixels[:, 1], points[:, 2]) == pytest.approx(points)
    single = k.back_project(np.float32(100.0), np.float32(50.0), np.float32(3.0))
    assert single.shape == (3,) and single.dtype == np.float32


def test_pose_motion_and_bearing():
    pose = Pose2D(1.0, 1.0, 0.0).moved(2.0, math.pi / 2)
    assert (pose.x_m, pose.y_m) == pytest.approx((1.0, 3.0))
    assert pose.bearing_to(1.0, 0.0) == pytest.approx(math.pi, abs=1e-9) or pose.bearing_to(1.0, 0.0) == pytest.approx(-math.pi)
    assert pose.distance_to(4.0, 7.0) == pytest.approx(5.0)

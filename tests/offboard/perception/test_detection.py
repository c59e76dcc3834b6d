"""Target detectors on synthetic views (no simulator needed).

A view is a 640x480 image (f ≈ 493 px, the simulator's camera) of a textured background (the
simulator's wall and floor textures, tiled at random scales and tints), 0-3 distractor pictures
(astronaut, coffee, rocket, Hubble) and, in positives, the simulator's built-in target picture on a
0.23 m face placed 0.5-3 m away (230 down to 38 px wide) and turned out of plane by up to 45°. Every
picture is first shrunk with area averaging, as the renderer's mip-mapping does, then warped with
the homography of its 3D pose; the true corners are the projected corners of the face.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import pytest

from offboard.perception.detection import (Detection, Detector, TargetModel, TargetModelError, detector_names,
                                locate_target, make_detector)
from onboard.sim.textures import load_picture, texture_image
from shared.geometry import HeadMount, Intrinsics, Pose2D, RigidTransform, rot_y

CAMERA = Intrinsics.from_fov(640, 480, 66.0)
FACE_M = 0.23
TARGET = load_picture("target", Path("."))
DISTRACTORS = [load_picture(name, Path(".")) for name in ("astronaut", "coffee", "rocket", "hubble")]
BACKGROUNDS = ["brick", "gravel", "grass", "plaster", "carpet", "wood", "metal", "fabric", "cardboard"]


def _rot_x(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def _face_points(distance_m: float, yaw_deg: float, pitch_deg: float, centre_px: np.ndarray,
                 width_m: float = FACE_M, height_m: float = FACE_M) -> np.ndarray:
    """Corners (4, 3) in the camera frame (TL, TR, BR, BL) of a face centred on the ray through
    ``centre_px`` at ``distance_m``, turned by yaw (about the camera's y) and pitch (about x)."""
    ray = np.array([(centre_px[0] - CAMERA.cx_px) / CAMERA.fx_px, (centre_px[1] - CAMERA.cy_px) / CAMERA.fy_px, 1.0])
    centre = distance_m * ray / np.linalg.norm(ray)
    turn = rot_y(math.radians(yaw_deg)) @ _rot_x(math.radians(pitch_deg))
    right, down = turn[:, 0] * width_m / 2, turn[:, 1] * height_m / 2
    return np.stack([centre - right - down, centre + right - down, centre + right + down, centre - right + down])


def _view_quad(rng: np.random.Generator, distance_m: float, max_turn_deg: float, width_m: float = FACE_M,
               height_m: float = FACE_M, margin_px: float = 4.0) -> np.ndarray:
    """Image corners (4, 2) of a face at a random place and out-of-plane turn inside the image."""
    for _ in range(200):
        turn, direction = rng.uniform(0, max_turn_deg), rng.uniform(0, 2 * math.pi)
        centre = rng.uniform([0, 0], [CAMERA.width_px, CAMERA.height_px])
        quad = CAMERA.project(_face_points(distance_m, turn * math.cos(direction), turn * math.sin(direction),
                                           centre, width_m, height_m))
        if quad.min() > margin_px and np.all(quad.max(axis=0) < [CAMERA.width_px - margin_px, CAMERA.height_px - margin_px]):
            return quad
    raise AssertionError("no view of the face fits in the image")


def _background(rng: np.random.Generator) -> np.ndarray:
    tile = texture_image(BACKGROUNDS[rng.integers(len(BACKGROUNDS))])
    n = round(512 * rng.uniform(0.35, 1.0))
    tile = cv2.resize(tile, (n, n), interpolation=cv2.INTER_AREA).astype(np.float32)
    big = np.tile(tile, (480 // n + 2, 640 // n + 2, 1))
    y0, x0 = rng.integers(0, n, 2)
    return big[y0:y0 + 480, x0:x0 + 640] * rng.uniform(0.5, 1.0, 3).astype(np.float32)


def _paste(image: np.ndarray, picture: np.ndarray, quad: np.ndarray) -> np.ndarray:
    """``picture`` stretched over the image quadrilateral ``quad`` (picture corners at its outer
    pixel edges, image corners in pixel-centre coordinates)."""
    h, w = picture.shape[:2]
    longest = np.linalg.norm(np.roll(quad, -1, axis=0) - quad, axis=1).max()
    shrink = min(1.0, 1.2 * longest / max(h, w))
    if shrink < 1.0:  # like mip-mapping: no aliasing when a picture is seen small
        picture = cv2.resize(picture, (max(2, round(w * shrink)), max(2, round(h * shrink))),
                             interpolation=cv2.INTER_AREA)
        h, w = picture.shape[:2]
    corners = np.array([[0, 0], [w, 0], [w, h], [0, h]], np.float32) - 0.5
    homography = cv2.getPerspectiveTransform(corners, quad.astype(np.float32))
    size = (image.shape[1], image.shape[0])
    colour = cv2.warpPerspective(picture.astype(np.float32), homography, size, flags=cv2.INTER_LINEAR)
    cover = cv2.warpPerspective(np.ones((h, w), np.float32), homography, size, flags=cv2.INTER_LINEAR)[:, :, None]
    return image * (1.0 - cover) + colour  # colour is already weighted by the edge coverage


def _finish(image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Camera-like softness and noise (OpenCV's generator, seeded from ``rng``: numpy's is slower)."""
    noise = np.empty(image.shape, np.float32)
    cv2.setRNGSeed(int(rng.integers(2**31)))
    cv2.randn(noise, 0.0, 2.0)
    return np.clip(cv2.GaussianBlur(image, (0, 0), 0.5) + noise, 0, 255).astype(np.uint8)


def _with_distractors(image: np.ndarray, rng: np.random.Generator, count: int) -> np.ndarray:
    for _ in range(count):
        picture = DISTRACTORS[rng.integers(len(DISTRACTORS))]
        width_m = rng.uniform(0.25, 0.8)
        quad = _view_quad(rng, rng.uniform(1.0, 4.0), 45.0, width_m, width_m * picture.shape[0] / picture.shape[1],
                          margin_px=-200.0)
        image = _paste(image, picture, quad)
    return image


def positive_view(rng: np.random.Generator, distance_m: float, max_turn_deg: float) -> tuple[np.ndarray, np.ndarray]:
    image = _with_distractors(_background(rng), rng, int(rng.integers(0, 3)))
    quad = _view_quad(rng, distance_m, max_turn_deg)
    return _finish(_paste(image, TARGET, quad), rng), quad


def negative_view(rng: np.random.Generator) -> np.ndarray:
    return _finish(_with_distractors(_background(rng), rng, int(rng.integers(1, 4))), rng)


# ----------------------------------------------------------------------------- fixtures

MODEL = TargetModel((TARGET,), (FACE_M, FACE_M, FACE_M))


@pytest.fixture(scope="module")
def detectors() -> dict[str, Detector]:
    return {name: make_detector(name, MODEL, CAMERA) for name in detector_names()}


@pytest.fixture(scope="module")
def negatives() -> list[np.ndarray]:
    rng = np.random.default_rng(2024)
    return [negative_view(rng) for _ in range(100)]


# ----------------------------------------------------------------------------- target model


def test_target_model_reads_pictures_as_rgb(tmp_path):
    path = tmp_path / "face.png"
    cv2.imwrite(str(path), cv2.cvtColor(np.ascontiguousarray(TARGET), cv2.COLOR_RGB2BGR))
    model = TargetModel.from_files([path], (0.1, 0.3, 0.2))
    assert np.array_equal(model.pictures[0], TARGET)
    assert (model.face_width_m, model.face_height_m) == (0.3, 0.2)


def test_target_model_names_the_unreadable_file(tmp_path):
    bad = tmp_path / "broken.png"
    bad.write_bytes(b"not an image at all")
    with pytest.raises(TargetModelError, match="broken.png"):
        TargetModel.from_files([bad], (0.23, 0.23, 0.23))
    with pytest.raises(TargetModelError, match="missing.jpg"):
        TargetModel.from_files([tmp_path / "missing.jpg"], (0.23, 0.23, 0.23))


@pytest.mark.parametrize("size", [(0.23, 0.0, 0.23), (0.23, 0.23), (0.23, math.nan, 0.23)])
def test_target_model_refuses_bad_sizes(size):
    with pytest.raises(TargetModelError, match="size_m"):
        TargetModel((TARGET,), size)


# ----------------------------------------------------------------------------- registry, range, cost


def test_registry_builds_every_detector_and_refuses_unknown_names(detectors):
    assert set(detectors) == {"sift", "ncc"}
    for name, detector in detectors.items():
        assert isinstance(detector, Detector) and detector.name == name
        assert 0.0 < detector.cost_ms < 1000.0
    with pytest.raises(ValueError, match="sift"):
        make_detector("surf", MODEL, CAMERA)


@pytest.mark.parametrize(("name", "options", "named"), [
    ("sift", {"scale_step": 1.0}, "got 1.0 and"), ("sift", {"scale_step": 0.9}, "got 0.9 and"),
    ("sift", {"tilt": 0.5}, "and 0.5"), ("ncc", {"scale_step": 1.0}, "got 1.0"), ("ncc", {"scale_step": 0.9}, "got 0.9"),
])
def test_a_scale_step_that_never_reaches_the_smallest_face_is_refused(name, options, named):
    """At 1 the model's views never shrink (SIFT looped for ever; NCC divided by zero), below it they grow."""
    with pytest.raises(ValueError, match=f"scale_step must be over 1.*{named}"):
        make_detector(name, MODEL, CAMERA, cost_repeats=0, **options)


def test_range_follows_from_face_size_and_focal_length(detectors):
    for detector in detectors.values():
        near, far = detector.range_m
        # Near: the 0.23 m face fills at most 90 % of the 480 px image height.
        assert near == pytest.approx(CAMERA.fy_px * FACE_M / (0.9 * CAMERA.height_px))
        assert 3.0 < far < 4.0
    small = TargetModel((TARGET,), (0.1, 0.1, 0.1))
    assert make_detector("ncc", small, CAMERA, cost_repeats=0).range_m[1] < detectors["ncc"].range_m[1] / 2


# ----------------------------------------------------------------------------- detection


@pytest.fixture(scope="module")
def sift_views(detectors) -> list[tuple[float, np.ndarray, Detection | None]]:
    rng = np.random.default_rng(7)
    views = []
    for i in range(40):
        distance = 0.5 + 2.5 * (i + 0.5) / 40  # face 230 px down to 38 px wide
        image, quad = positive_view(rng, distance, max_turn_deg=45.0)
        views.append((distance, quad, detectors["sift"].detect(image)))
    return views


def test_sift_finds_the_target_up_to_3_m_and_45_degrees(sift_views):
    found = [d is not None for _, _, d in sift_views]
    assert np.mean(found) >= 0.95, [round(dist, 2) for (dist, _, _), ok in zip(sift_views, found) if not ok]


def test_sift_corners_are_within_a_few_pixels(sift_views):
    errors = np.array([np.abs(d.corners_px - quad).max() for _, quad, d in sift_views if d is not None])
    assert np.median(errors) < 1.5 and errors.max() < 4.0
    near = [d for dist, _, d in sift_views if d is not None and dist < 1.0]
    assert len(near) >= 6 and all(d.confident and d.score >= 24 for d in near)  # 8 views under 1 m


def test_ncc_finds_fronto_parallel_targets_at_the_right_scale(detectors):
    rng = np.random.default_rng(11)
    for distance in np.linspace(0.5, 3.0, 16):
        image, quad = positive_view(rng, distance, max_turn_deg=0.0)
        detection = detectors["ncc"].detect(image)
        assert detection is not None, distance
        assert np.abs(detection.corners_px - quad).max() < 3.0, (distance, detection.corners_px, quad)
        width = detection.box_px[2] - detection.box_px[0]
        assert width == pytest.approx(quad[1, 0] - quad[0, 0], rel=0.03)


@pytest.mark.parametrize("name", ["sift", "ncc"])
def test_no_false_detections_among_distractor_pictures(detectors, negatives, name):
    false = [i for i, image in enumerate(negatives) if detectors[name].detect(image) is not None]
    assert false == []


# ----------------------------------------------------------------------------- geometry


def _looking_at_face() -> tuple[Detection, np.ndarray, RigidTransform, float]:
    """A face 1.6 m ahead of a camera on the robot's head, seen obliquely; its detection from
    the true corners; the world position of its centre; the camera pose; its depth."""
    mount = HeadMount()
    camera = mount.camera_in_world(Pose2D(2.0, 1.0, 0.3), math.radians(10), math.radians(-5))
    corners_cam = _face_points(1.6, 30.0, 10.0, np.array([400.0, 200.0]))
    detection = Detection.from_corners("sift", CAMERA.project(corners_cam), 40, True)
    centre_cam = corners_cam.mean(axis=0)
    return detection, camera.apply(centre_cam), camera, float(centre_cam[2])


def test_detection_centre_is_the_projected_face_centre():
    detection, _, _, _ = _looking_at_face()
    corners_cam = _face_points(1.6, 30.0, 10.0, np.array([400.0, 200.0]))
    assert np.allclose(detection.center_px, CAMERA.project(corners_cam.mean(axis=0)), atol=1e-6)
    assert detection.box_px == pytest.approx((*detection.corners_px.min(axis=0), *detection.corners_px.max(axis=0)))


def test_locate_target_recovers_the_face_centre_from_disparity():
    detection, centre_world, camera, depth = _looking_at_face()
    baseline = 0.12
    disparity = np.full((480, 640), np.nan, np.float32)
    face = np.zeros((480, 640), np.uint8)
    cv2.fillConvexPoly(face, np.round(detection.corners_px).astype(np.int32), 1)
    disparity[face > 0] = CAMERA.fx_px * baseline / depth
    # The face's rim carries the background's disparity (block matching fattens edges): ignored.
    rim = cv2.dilate(face, np.ones((9, 9), np.uint8)) - cv2.erode(face, np.ones((9, 9), np.uint8))
    disparity[rim > 0] = 5.0
    located = locate_target(detection, disparity, CAMERA, baseline, camera)
    assert located is not None
    assert np.allclose(located, centre_world, atol=1e-3)


def test_locate_target_needs_valid_disparity_on_the_face():
    detection, _, camera, _ = _looking_at_face()
    disparity = np.full((480, 640), np.nan, np.float32)
    disparity[:, :50] = 20.0  # valid, but nowhere near the face
    assert locate_target(detection, disparity, CAMERA, 0.12, camera) is None

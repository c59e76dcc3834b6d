"""SIFT target detector: model features matched into the image, verified by a homography (the
report's feature detector: the target is found when enough features agree on one planar view).

Model, computed once: SIFT features of simulated views of each picture, shrunk in steps of
``scale_step`` down to the smallest face to be found (a face 40 px wide is matched far better by a
60 px copy's features than by a 250 px original's fine detail), each also foreshortened ASIFT-style
by ``tilt`` along x and along y (a face turned by ~45°); keypoints are mapped back to the original.

Per image, two passes, because describing all ~4000 keypoints of a textured 640x480 room costs ~3x
the time budget, while keeping only the strongest loses the faint ones of a face seen from 3 m:

1. **Global**: the ``max_features`` strongest keypoints of the image shrunk by ``global_shrink``.
   OpenCV's SIFT doubles its input first, and that finest octave is most of its cost: shrinking
   by 1.5 halves the cost (~107 → ~49 ms a 640x480 image here) and loses the faintest detail of
   far faces: the reliable range drops from ~5 m to ~3.5 m for a 23 cm face (measured on rendered
   views; by 2, to ~2.5 m). Each descriptor's nearest
   model descriptor must pass Lowe's ratio test against the nearest one at a *different place* of
   the picture (the same place in another simulated view is no rival); one match per location.
   A near face gives enough matches for a confident homography right away.
2. **Focus**: otherwise even a far face leaves a match or a few, and they form the densest group of
   matches agreeing on the face's size (each match's keypoint scale predicts it). Around the
   ``max_regions`` best groups, a window two predicted faces wide is magnified so that the face is
   ~``focus_face_px`` wide (at most ``max_zoom``) and fully described with a lower contrast
   threshold: about twice the matches a full-image pass finds.

A detection needs ``min_inliers`` RANSAC inliers (``cv2.findHomography``) and a plausible homography
(see ``_plausible_view``). Matching is one float32 matrix product and two row minima (numpy's
argpartition and OpenCV's BFMatcher are several times slower).
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from dataclasses import dataclass

import cv2
import numpy as np

from offboard.perception.detection.detector import Detection, MeasuredDetector, operating_range, to_grey
from offboard.perception.detection.target_model import TargetModel, TargetModelError
from shared.geometry import Intrinsics

log = logging.getLogger("syt.offboard.perception.detection.sift")


@dataclass(frozen=True)
class _ModelFeatures:
    """All keypoints of the simulated views of one picture, positions in its original pixels."""

    corners: np.ndarray  # (4, 2) picture corners (outer pixel edges)
    width_px: int
    points: np.ndarray  # (n, 2) float32
    sizes: np.ndarray  # (n,) keypoint diameters in original pixels
    descriptors_x_minus2: np.ndarray  # (128, n) float32: -2 x the descriptors, transposed
    sq_norms: np.ndarray  # (n,) squared norms: squared distances come from one matrix product
    same_place: np.ndarray  # (n, n) bool: keypoints close enough to be one feature in two views


@dataclass(frozen=True)
class _Features:
    """Keypoints of (part of) an image, positions in full-image pixels."""

    points: np.ndarray  # (m, 2) float32
    sizes: np.ndarray  # (m,) diameters in full-image pixels
    descriptors: np.ndarray  # (m, 128) float32


@dataclass(frozen=True)
class _Matches:
    model_points: np.ndarray  # (k, 2) best match first
    image_points: np.ndarray  # (k, 2)
    face_px: np.ndarray  # (k,) face width in the image that each match's scale predicts


class SiftDetector(MeasuredDetector):
    """SIFT, ratio test, RANSAC homography, with a focused second look. See the module docstring."""

    name = "sift"

    def __init__(self, model: TargetModel, intrinsics: Intrinsics, *, ratio: float = 0.75,
                 min_inliers: int = 12, confident_inliers: int = 24, ransac_px: float = 3.0,
                 max_features: int = 600, contrast_threshold: float = 0.06, min_face_px: float = 36.0,
                 max_magnification: float = 4.0, max_regions: int = 1, focus_face_px: float = 80.0,
                 focus_max_face_px: float = 120.0, max_zoom: float = 2.0, focus_contrast_threshold: float = 0.02,
                 scale_step: float = 2**0.5, tilt: float = 2**0.5, features_per_view: int = 150,
                 max_aspect_change: float = 3.0, global_shrink: float = 1.5, cost_repeats: int = 3) -> None:
        self.model = model
        self.ratio, self.ransac_px = ratio, ransac_px
        self.min_inliers, self.confident_inliers = min_inliers, max(confident_inliers, min_inliers)
        self.min_face_px, self.max_aspect_change = min_face_px, max_aspect_change
        self.max_regions, self.focus_face_px, self.max_zoom = max_regions, focus_face_px, max_zoom
        self.focus_max_face_px = focus_max_face_px
        if global_shrink < 1.0:
            raise ValueError(f"global_shrink must be at least 1, got {global_shrink}")
        if not (scale_step > 1.0 and tilt >= 1.0):  # else the model's views never shrink to min_face_px
            raise ValueError(f"scale_step must be over 1 and tilt at least 1, got {scale_step} and {tilt}")
        self.global_zoom = 1.0 / global_shrink
        # A face magnified far beyond the picture's own pixels has no features as fine as the model's.
        super().__init__(operating_range(model, intrinsics, min_face_px=min_face_px, max_magnification=max_magnification))
        self._global = cv2.SIFT_create(nfeatures=max_features, contrastThreshold=contrast_threshold)
        self._focus = cv2.SIFT_create(contrastThreshold=focus_contrast_threshold)
        model_sift = cv2.SIFT_create(nfeatures=features_per_view, contrastThreshold=contrast_threshold)
        self._models = tuple(_model_features(to_grey(p), model_sift, min_face_px, scale_step, tilt)
                             for p in model.pictures)
        self._measure_cost(model, intrinsics, cost_repeats)
        log.info("sift: %s model keypoints, %.1f ms per image, range %.2f-%.2f m",
                 [len(m.points) for m in self._models], self.cost_ms, *self._range)

    def _detect(self, left_rgb: np.ndarray) -> Detection | None:
        grey = to_grey(left_rgb)
        overall = _features(self._global, grey, (0, 0), self.global_zoom)
        found = [self._detect_picture(model, grey, overall) for model in self._models]
        return max((d for d in found if d is not None), key=lambda d: d.score, default=None)

    def _detect_picture(self, model: _ModelFeatures, grey: np.ndarray, overall: _Features) -> Detection | None:
        """The global pass's detection if confident, else the best of it and the focused looks."""
        matches = self._matches(model, overall)
        best = self._verify(model, matches, grey.shape)
        if best is not None and best.confident:
            return best
        for centre, face_px in self._regions(matches):
            found = self._verify(model, self._matches(model, self._look_closer(grey, centre, face_px)), grey.shape)
            if found is not None and (best is None or found.score > best.score):
                best = found
        return best

    def _look_closer(self, grey: np.ndarray, centre: np.ndarray, face_px: float) -> _Features:
        """All features of a window two faces wide around ``centre``, magnified so that the face is
        about ``focus_face_px`` wide."""
        half = float(np.clip(face_px, self.min_face_px, self.focus_max_face_px))
        (x0, y0), (x1, y1) = np.maximum(np.floor(centre - half), 0), np.ceil(centre + half)
        window = grey[int(y0):int(y1), int(x0):int(x1)]
        zoom = float(np.clip(self.focus_face_px / face_px, 1.0, self.max_zoom))
        return _features(self._focus, window, (x0, y0), zoom)

    def _matches(self, model: _ModelFeatures, image: _Features) -> _Matches:
        """Image keypoints whose nearest model descriptor passes the ratio test, best first."""
        if len(image.points) == 0:
            return _Matches(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros(0))
        # Squared distances less the image descriptor's own squared norm (a per-row constant that
        # changes no ranking): one matrix product, added to in place.
        dist = image.descriptors @ model.descriptors_x_minus2
        dist += model.sq_norms
        nearest = np.argmin(dist, axis=1)
        own = np.einsum("ij,ij->i", image.descriptors, image.descriptors)
        first = dist[np.arange(len(dist)), nearest] + own
        np.putmask(dist, model.same_place[nearest], np.inf)
        rival = dist.min(axis=1) + own
        ratio = np.sqrt(np.maximum(first, 0.0) / np.maximum(rival, 1e-9))
        keep = np.nonzero(ratio < self.ratio)[0]
        keep = keep[np.argsort(ratio[keep], kind="stable")]
        # OpenCV returns a keypoint once per dominant orientation: count each location once.
        pixel = np.round(image.points[keep]).astype(np.int64)
        _, unique = np.unique(pixel[:, 0] * 100_003 + pixel[:, 1], return_index=True)
        chosen = keep[np.sort(unique)]
        model_idx = nearest[chosen]
        face_px = model.width_px * image.sizes[chosen] / model.sizes[model_idx]
        return _Matches(model.points[model_idx], image.points[chosen], face_px)

    def _regions(self, matches: _Matches) -> list[tuple[np.ndarray, float]]:
        """(centre, predicted face width) of up to ``max_regions`` places worth a closer look: the
        densest groups of matches agreeing on a face small enough to have been missed (a larger one
        gives the global pass matches enough), then single matches (best first) predicting a face
        no wider than ``focus_face_px`` (a far face may leave only one match)."""
        small = matches.face_px <= self.focus_max_face_px
        pts, face = matches.image_points[small], np.clip(matches.face_px[small], self.min_face_px, None)
        near = np.linalg.norm(pts[:, None] - pts[None, :], axis=2) < np.maximum(face[:, None], face[None, :])
        members = near & (np.abs(np.log(face[:, None] / face[None, :])) < np.log(2.0))
        taken = np.zeros(len(pts), dtype=bool)
        chosen: list[np.ndarray] = []
        for seed in np.argsort(-members.sum(axis=1), kind="stable"):
            group = members[seed] & ~taken
            if not taken[seed] and group.sum() >= 2:
                taken |= group
                chosen.append(group)
        chosen += [np.arange(len(pts)) == i for i in np.nonzero(~taken & (face <= self.focus_face_px))[0]]
        return [(pts[g].mean(axis=0), float(np.median(face[g]))) for g in chosen[: self.max_regions]]

    def _verify(self, model: _ModelFeatures, matches: _Matches, image_shape: tuple[int, ...]) -> Detection | None:
        if len(matches.image_points) < self.min_inliers:
            return None
        homography, mask = cv2.findHomography(matches.model_points, matches.image_points, cv2.RANSAC,
                                              self.ransac_px, maxIters=5000, confidence=0.999)
        if homography is None or np.count_nonzero(mask) < self.min_inliers:
            return None
        inliers = int(np.count_nonzero(mask))
        face_aspect = self.model.face_width_m / self.model.face_height_m
        corners = _plausible_view(homography, model.corners, face_aspect, self.max_aspect_change,
                                  (0.25 * self.min_face_px**2, float(image_shape[0] * image_shape[1])))
        if corners is None:
            return None
        return Detection.from_corners(self.name, corners, inliers, inliers >= self.confident_inliers)


def _features(sift: cv2.SIFT, grey: np.ndarray, offset: tuple[float, float], zoom: float) -> _Features:
    """SIFT of ``grey`` magnified by ``zoom``, mapped back to the pixels of the image ``grey`` was
    cut from at ``offset``."""
    h, w = grey.shape
    size = (max(1, round(w * zoom)), max(1, round(h * zoom)))
    interpolation = cv2.INTER_AREA if zoom < 1.0 else cv2.INTER_CUBIC  # area: no aliasing when shrinking
    view = grey if zoom == 1.0 else cv2.resize(grey, size, interpolation=interpolation)
    keypoints, descriptors = sift.detectAndCompute(view, None)
    if descriptors is None or not keypoints:
        return _Features(np.zeros((0, 2), np.float32), np.zeros(0, np.float32), np.zeros((0, 128), np.float32))
    scale = np.array([w / size[0], h / size[1]], dtype=np.float32)  # exact, whatever the rounding
    xy = np.array([k.pt for k in keypoints], dtype=np.float32)
    points = (xy + 0.5) * scale - 0.5 + np.asarray(offset, dtype=np.float32)
    sizes = np.array([k.size for k in keypoints], dtype=np.float32) * float(scale.mean())
    return _Features(points, sizes, descriptors.astype(np.float32))


# ----------------------------------------------------------------------------- model features


def _model_features(grey: np.ndarray, sift: cv2.SIFT, min_face_px: float, scale_step: float,
                    tilt: float) -> _ModelFeatures:
    points, sizes, descriptors = [], [], []
    for view, mask, to_original in _simulated_views(grey, min_face_px, scale_step, tilt):
        keypoints, desc = sift.detectAndCompute(view, mask)
        if desc is None or not keypoints:
            continue
        xy = np.array([k.pt for k in keypoints], dtype=np.float64)
        points.append(xy @ to_original[:2, :2].T + to_original[:2, 2])
        sizes.append(np.array([k.size for k in keypoints]) * np.sqrt(abs(np.linalg.det(to_original[:2, :2]))))
        descriptors.append(desc.astype(np.float32))
    if not points:
        raise TargetModelError("a target picture has no SIFT features: it is too plain to be detected")
    pts, desc = np.concatenate(points).astype(np.float32), np.concatenate(descriptors)
    h, w = grey.shape
    # Keypoints closer than this are one feature seen in two views: mapping back from a shrunk
    # copy is only good to a pixel or two of that copy.
    same = np.linalg.norm(pts[:, None] - pts[None, :], axis=2) <= 0.03 * max(h, w)
    corners = np.array([[0, 0], [w, 0], [w, h], [0, h]], dtype=np.float64) - 0.5  # pixel edges
    return _ModelFeatures(corners, w, pts, np.concatenate(sizes).astype(np.float32),
                          np.ascontiguousarray(-2.0 * desc.T), np.einsum("ij,ij->i", desc, desc), same)


def _simulated_views(grey: np.ndarray, min_face_px: float, scale_step: float,
                     tilt: float) -> Iterator[tuple[np.ndarray, np.ndarray | None, np.ndarray]]:
    """(view, mask or None, 3x3 affine from the view's to the original's pixels) for each scale
    down to ``min_face_px``, as is and, if ``tilt`` > 1, foreshortened along x and along y."""
    h, w = grey.shape
    factor = 1.0
    while True:
        size = (max(2, round(w * factor)), max(2, round(h * factor)))
        copy = grey if factor == 1.0 else cv2.resize(grey, size, interpolation=cv2.INTER_AREA)
        to_copy = _resize_affine(size[0] / w, size[1] / h)
        yield copy, None, np.linalg.inv(to_copy)
        if tilt > 1.0:
            for angle_deg in (0.0, 90.0):
                view, mask, to_view = _foreshortened(copy, tilt, angle_deg)
                yield view, mask, np.linalg.inv(to_view @ to_copy)
        if min(size) / scale_step < min_face_px:
            break
        factor /= scale_step


def _resize_affine(sx: float, sy: float) -> np.ndarray:
    """3x3 affine of cv2.resize between pixel-centre coordinates."""
    return np.array([[sx, 0.0, 0.5 * sx - 0.5], [0.0, sy, 0.5 * sy - 0.5], [0.0, 0.0, 1.0]])


def _foreshortened(image: np.ndarray, tilt: float, angle_deg: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """ASIFT's simulated tilt: rotate by ``angle_deg``, then shrink x by ``tilt`` (blurred first so
    as not to alias). Returns the view, the mask of the picture in it (rim eroded: keypoints there
    would describe the black border) and the 3x3 affine from the image's pixels to the view's."""
    h, w = image.shape
    rotation = np.vstack([cv2.getRotationMatrix2D(((w - 1) / 2, (h - 1) / 2), angle_deg, 1.0), [0, 0, 1]])
    corners = np.array([[0, 0, 1], [w - 1, 0, 1], [w - 1, h - 1, 1], [0, h - 1, 1]], float) @ rotation.T
    rotation[:2, 2] -= corners[:, :2].min(axis=0)
    span = corners[:, :2].max(axis=0) - corners[:, :2].min(axis=0)
    size = (int(np.ceil(span[0])) + 1, int(np.ceil(span[1])) + 1)
    rotated = cv2.warpAffine(image, rotation[:2], size, flags=cv2.INTER_LINEAR)
    mask = cv2.warpAffine(np.full_like(image, 255), rotation[:2], size, flags=cv2.INTER_NEAREST)
    rotated = cv2.GaussianBlur(rotated, (0, 0), sigmaX=0.8 * np.sqrt(tilt * tilt - 1.0), sigmaY=0.01)
    new_size = (max(2, round(size[0] / tilt)), size[1])
    view = cv2.resize(rotated, new_size, interpolation=cv2.INTER_LINEAR)
    mask = cv2.erode(cv2.resize(mask, new_size, interpolation=cv2.INTER_NEAREST), np.ones((5, 5), np.uint8))
    return view, mask, _resize_affine(new_size[0] / size[0], 1.0) @ rotation


def _plausible_view(homography: np.ndarray, corners: np.ndarray, face_aspect: float, max_change: float,
                    area_px: tuple[float, float]) -> np.ndarray | None:
    """The picture's corners in the image if the homography is a plausible view of the face: not
    mirrored, all corners in front of the camera, a convex quadrilateral whose area lies in
    ``area_px``, whose aspect ratio is within ``max_change`` of the face's and whose opposite sides
    are within that factor of each other (perspective, not a degenerate fit)."""
    if abs(homography[2, 2]) < 1e-12:
        return None
    h = homography / homography[2, 2]
    if _jacobian_det(h, corners.mean(axis=0)) <= 0:
        return None
    homogeneous = np.hstack([corners, np.ones((4, 1))]) @ h.T
    if np.any(homogeneous[:, 2] <= 1e-6):
        return None
    quad = homogeneous[:, :2] / homogeneous[:, 2:]
    edges = np.roll(quad, -1, axis=0) - quad  # top, right, bottom, left
    following = np.roll(edges, -1, axis=0)
    if not np.all(edges[:, 0] * following[:, 1] - edges[:, 1] * following[:, 0] > 0):  # convex, clockwise
        return None
    x, y = quad[:, 0], quad[:, 1]
    area = 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))
    sides = np.linalg.norm(edges, axis=1)
    if not area_px[0] <= area <= area_px[1] or sides.min() < 1e-3:
        return None
    aspect = (sides[0] + sides[2]) / (sides[1] + sides[3]) / face_aspect
    opposite = max(sides[0] / sides[2], sides[2] / sides[0], sides[1] / sides[3], sides[3] / sides[1])
    return quad if 1.0 / max_change <= aspect <= max_change and opposite <= max_change else None


def _jacobian_det(h: np.ndarray, point: np.ndarray) -> float:
    """Determinant of the homography's local linear map at ``point`` (negative: mirrored): its 2x2
    part once both planes are centred on ``point`` and its image. The raw 2x2 part says nothing
    when the perspective terms are large next to the scale, as for a small, slanted face."""
    u = h @ np.array([point[0], point[1], 1.0])
    return float(np.linalg.det(h[:2, :2] - np.outer(u[:2] / u[2], h[2, :2])))

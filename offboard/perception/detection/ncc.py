"""Normalised grey-level correlation detector (the report's second detector): the target's picture
as a template, correlated (``cv2.matchTemplate``, TM_CCOEFF_NORMED) over a range of sizes.

The sizes are those of the face between the detector's near and far distance, in steps of
``scale_step``; the template keeps the *face's* aspect ratio (the picture is stretched over the
face whatever its own). Coarse to fine, to stay within ~30 ms on 640x480:

1. **Coarse**: each size is searched in the level of an image pyramid (2x2 averaging, like the
   templates' own shrinking) where its template is about ``coarse_px`` wide, never finer than
   ``min_level`` (a full-resolution search costs ~20 ms per size). The ``candidates`` best peaks,
   at distinct places, go on.
2. **Refine**: around each candidate, at the level where the template is at most ``refine_px``
   wide (full resolution for all but near faces), three sizes about the candidate's are correlated
   in a small window; the peak is located to sub-pixel and the size interpolated.

The detection is the best refined peak if it reaches ``threshold``; it is ``confident`` from
``confident_threshold``. Correlation tolerates uniform changes of brightness and contrast, not
rotation or foreshortening: a face turned by more than ~20-30° drops below threshold.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass

import cv2
import numpy as np

from offboard.perception.detection.detector import Detection, MeasuredDetector, operating_range, to_grey
from offboard.perception.detection.target_model import TargetModel
from shared.geometry import Intrinsics

log = logging.getLogger("syt.offboard.perception.detection.ncc")


@dataclass(frozen=True)
class _Peak:
    score: float
    x: float  # left edge of the face, full-resolution pixel-edge coordinates (pixel i spans [i, i+1))
    y: float  # top edge
    width_px: float  # face width, full-resolution pixels

    def centre(self, aspect: float) -> tuple[float, float]:
        return self.x + self.width_px / 2, self.y + self.width_px * aspect / 2


class NccDetector(MeasuredDetector):
    """Multi-scale normalised correlation, coarse to fine. See the module docstring."""

    name = "ncc"

    def __init__(self, model: TargetModel, intrinsics: Intrinsics, *, threshold: float = 0.6,
                 confident_threshold: float = 0.8, min_face_px: float = 32.0, scale_step: float = 1.12,
                 coarse_px: float = 16.0, min_level: int = 1, max_level: int = 3, refine_px: float = 96.0,
                 candidates: int = 3, cost_repeats: int = 3) -> None:
        if not scale_step > 1.0:  # the template sizes grow by it from min_face_px
            raise ValueError(f"scale_step must be over 1, got {scale_step}")
        self.model = model
        self.threshold, self.confident_threshold = threshold, max(confident_threshold, threshold)
        self.scale_step, self.coarse_px, self.refine_px = scale_step, coarse_px, refine_px
        self.min_level, self.max_level, self.candidates = min_level, max(max_level, min_level), candidates
        super().__init__(operating_range(model, intrinsics, min_face_px=min_face_px))
        self._aspect = model.face_height_m / model.face_width_m  # template height per width
        near_px = intrinsics.fx_px * model.face_width_m / self._range[0]
        count = int(math.log(near_px / min_face_px) / math.log(scale_step)) + 1
        self._widths = min_face_px * scale_step ** np.arange(count)
        self._greys = tuple(to_grey(p) for p in model.pictures)
        self._coarse = tuple(tuple(self._coarse_template(grey, w) for w in self._widths) for grey in self._greys)
        self._measure_cost(model, intrinsics, cost_repeats)
        log.info("ncc: %d sizes %.0f-%.0f px, %.1f ms per image, range %.2f-%.2f m",
                 len(self._widths), self._widths[0], self._widths[-1], self.cost_ms, *self._range)

    def _detect(self, left_rgb: np.ndarray) -> Detection | None:
        pyramid = [to_grey(left_rgb)]
        for _ in range(self.max_level):
            h, w = pyramid[-1].shape
            pyramid.append(cv2.resize(pyramid[-1], (w // 2, h // 2), interpolation=cv2.INTER_AREA))
        best: _Peak | None = None
        for picture, coarse in zip(self._greys, self._coarse):
            for candidate in self._candidates(self._coarse_peaks(coarse, pyramid)):
                peak = self._refine(picture, pyramid, candidate)
                if peak is not None and (best is None or peak.score > best.score):
                    best = peak
        if best is None or best.score < self.threshold:
            return None
        w, h = best.width_px, best.width_px * self._aspect
        corners = np.array([[0, 0], [w, 0], [w, h], [0, h]]) + [best.x - 0.5, best.y - 0.5]  # to pixel centres
        return Detection.from_corners(self.name, corners, best.score, best.score >= self.confident_threshold)

    def _level(self, width_px: float, template_px: float, finest: int) -> int:
        """Pyramid level at which a face ``width_px`` wide is about ``template_px`` wide."""
        return int(np.clip(math.floor(math.log2(max(width_px / template_px, 1.0))), finest, self.max_level))

    def _template(self, picture: np.ndarray, width_px: float, level: int) -> np.ndarray:
        scale = 2.0**-level
        size = (max(4, round(width_px * scale)), max(4, round(width_px * self._aspect * scale)))
        return cv2.resize(picture, size, interpolation=cv2.INTER_AREA)

    def _coarse_template(self, picture: np.ndarray, width_px: float) -> tuple[int, np.ndarray]:
        """(pyramid level, template) of the coarse search for one face width."""
        level = self._level(width_px, self.coarse_px, self.min_level)
        return level, self._template(picture, width_px, level)

    def _coarse_peaks(self, coarse: tuple[tuple[int, np.ndarray], ...], pyramid: list[np.ndarray]) -> list[_Peak]:
        """The best place of every size."""
        peaks = []
        for level, template in coarse:
            image = pyramid[level]
            if template.shape[0] > image.shape[0] or template.shape[1] > image.shape[1]:
                continue
            _, score, _, (x, y) = cv2.minMaxLoc(cv2.matchTemplate(image, template, cv2.TM_CCOEFF_NORMED))
            peaks.append(_Peak(float(score), x * 2.0**level, y * 2.0**level, template.shape[1] * 2.0**level))
        return peaks

    def _candidates(self, peaks: list[_Peak]) -> list[_Peak]:
        """The best ``candidates`` peaks at distinct places (neighbouring sizes peak together)."""
        kept: list[_Peak] = []
        for peak in sorted(peaks, key=lambda p: -p.score):
            cx, cy = peak.centre(self._aspect)
            if all(math.hypot(cx - k.centre(self._aspect)[0], cy - k.centre(self._aspect)[1])
                   > 0.5 * min(peak.width_px, k.width_px) for k in kept):
                kept.append(peak)
            if len(kept) == self.candidates:
                break
        return kept

    def _refine(self, picture: np.ndarray, pyramid: list[np.ndarray], coarse: _Peak) -> _Peak | None:
        """The best of three sizes about the candidate's, searched around it at a finer level;
        while the best is the smallest or largest, once more about that one."""
        peak = coarse
        for _ in range(3):
            step = math.sqrt(self.scale_step)
            sizes = (peak.width_px / step, peak.width_px, peak.width_px * step)
            results = [r for r in (self._correlate(picture, pyramid, peak, w) for w in sizes) if r is not None]
            if not results:
                return None
            best = max(results, key=lambda p: p.score)
            if len(results) == 3 and best is results[1]:
                return self._interpolate_size(results)
            peak = best
        return peak

    def _correlate(self, picture: np.ndarray, pyramid: list[np.ndarray], around: _Peak, width: float) -> _Peak | None:
        """The best place of a template ``width`` wide near ``around``, to sub-pixel."""
        level = self._level(around.width_px, self.refine_px, 0)
        scale, image = 2.0**-level, pyramid[level]
        coarse_level = self._level(around.width_px, self.coarse_px, self.min_level)
        # The coarse peak's uncertainty: its level's pixel, and the corner's shift with size.
        margin = 2 * 2 ** max(coarse_level - level, 0) + math.ceil((self.scale_step - 1) * around.width_px * scale) + 1
        cx, cy = around.centre(self._aspect)
        template = self._template(picture, width, level)
        th, tw = template.shape
        x0 = max(round(cx * scale - tw / 2) - margin, 0)
        y0 = max(round(cy * scale - th / 2) - margin, 0)
        window = image[y0 : y0 + th + 2 * margin, x0 : x0 + tw + 2 * margin]
        if window.shape[0] < th + 2 or window.shape[1] < tw + 2:
            return None
        scores = cv2.matchTemplate(window, template, cv2.TM_CCOEFF_NORMED)
        _, score, _, (x, y) = cv2.minMaxLoc(scores)
        dx = _parabola_peak(scores[y, x - 1:x + 2]) if 0 < x < scores.shape[1] - 1 else 0.0
        dy = _parabola_peak(scores[y - 1:y + 2, x]) if 0 < y < scores.shape[0] - 1 else 0.0
        return _Peak(float(score), (x0 + x + dx) / scale, (y0 + y + dy) / scale, tw / scale)

    def _interpolate_size(self, peaks: list[_Peak]) -> _Peak:
        """The middle of three sizes, the best, moved to the summit of a parabola through the
        scores in log size, keeping the face's centre."""
        best = peaks[1]
        t = _parabola_peak(np.array([p.score for p in peaks]))
        width = best.width_px * (peaks[2].width_px / best.width_px if t > 0 else best.width_px / peaks[0].width_px) ** t
        cx, cy = best.centre(self._aspect)
        return _Peak(best.score, cx - width / 2, cy - width * self._aspect / 2, width)


def _parabola_peak(values: np.ndarray) -> float:
    """Offset (-0.5..0.5) of the summit of the parabola through three samples, the middle highest."""
    prev, centre, nxt = (float(v) for v in values)
    denom = prev - 2.0 * centre + nxt
    return float(np.clip(0.5 * (prev - nxt) / denom, -0.5, 0.5)) if denom < 0 else 0.0

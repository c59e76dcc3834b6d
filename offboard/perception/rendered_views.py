"""The stereo check on the rooms the robot searches: rendered views with true depth.

``syt-onboard worlds views`` writes the views (its ``views.json`` names each one's world, pose and
tilt). Each is scored against its true disparity ``f·B / depth``, with three figures:

- *bad2* and *density*, as for Middlebury (:mod:`offboard.perception.middlebury`). Pixels nearer
  than ``f·B / num_disparities`` (0.46 m with the defaults) count as known, though no matcher can
  answer them, so density is a little below what the matcher could reach;
- *phantom share*: the fraction of answered pixels whose disparity is too large by more than a
  third (and 2 px): a surface put much nearer than it is. Too far is harmless to the map (free space
  is carved a little too deep); too near puts an obstacle where there is none;
- *phantom views*: views where such pixels cover more than ``PHANTOM_VIEW_SHARE`` of the image. On
  a regular wall the wrong match takes whole regions, and that is a wall where there is none: it can
  close the robot in.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from offboard.perception.middlebury import BAD_THRESHOLD_PX, answered_errors, bad2_and_density
from offboard.perception.stereo import StereoConfig, StereoMatcher

PHANTOM_RATIO = 4.0 / 3.0  # a disparity this many times the truth: depth under 3/4 of the true depth
PHANTOM_VIEW_SHARE = 0.02


@dataclass(frozen=True)
class PixelCounts:
    """One view's pixels: with a true depth, answered (both), over 2 px off, too near."""

    known: int
    answered: int
    bad: int
    phantom: int
    pixels: int

    @property
    def phantom_view(self) -> bool:
        return self.phantom > PHANTOM_VIEW_SHARE * self.pixels


def count_pixels(disparity: np.ndarray, truth: np.ndarray) -> PixelCounts:
    """Compare a disparity map (NaN = no answer) with the true disparity (NaN or inf = unknown)."""
    known, ok, error = answered_errors(disparity, truth)
    too_near = (error > BAD_THRESHOLD_PX) & (disparity[ok] > PHANTOM_RATIO * truth[ok])
    return PixelCounts(known, int(ok.sum()), int((np.abs(error) > BAD_THRESHOLD_PX).sum()),
                       int(too_near.sum()), disparity.size)


@dataclass(frozen=True)
class ViewScores:
    bad2: float
    density: float
    phantom_share: float
    phantom_views: int
    views: int

    @classmethod
    def of(cls, counts: list[PixelCounts]) -> ViewScores:
        answered = sum(c.answered for c in counts)
        bad2, density = bad2_and_density(sum(c.bad for c in counts), answered, sum(c.known for c in counts))
        return cls(bad2, density, sum(c.phantom for c in counts) / max(answered, 1),
                   sum(c.phantom_view for c in counts), len(counts))

    def as_dict(self) -> dict:
        return {"bad2": round(self.bad2, 5), "density": round(self.density, 4),
                "phantom_share": round(self.phantom_share, 5), "phantom_views": self.phantom_views,
                "views": self.views}


def load_index(views_dir: Path) -> dict:
    """``views.json`` of a views directory; ``ValueError`` naming the file if it is missing or wrong."""
    index_path = Path(views_dir) / "views.json"
    try:
        index = json.loads(index_path.read_text())
        if not index["views"] or index["fx_px"] <= 0 or index["baseline_m"] <= 0:
            raise ValueError("no views, or a camera without focal length or baseline")
        for view in index["views"]:
            if not isinstance(view["folder"], str) or not isinstance(view["world"], str):
                raise ValueError(f"view {view!r} lacks its world or folder")
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"{index_path}: not a views index written by `syt-onboard worlds views` ({exc})") from exc
    return index


def _read_view(folder: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(left RGB, right RGB, depth): RGB as the robot's frames reach the matcher."""
    left, right = (cv2.imread(str(folder / name), cv2.IMREAD_COLOR) for name in ("left.png", "right.png"))
    try:
        depth = np.load(folder / "depth.npy").astype(np.float32)
    except (OSError, ValueError) as exc:
        raise ValueError(f"{folder}: depth.npy is missing or unreadable ({exc})") from exc
    if left is None or right is None or left.shape[:2] != depth.shape or right.shape[:2] != depth.shape:
        raise ValueError(f"{folder}: left.png, right.png and depth.npy must all be there, of one size")
    return cv2.cvtColor(left, cv2.COLOR_BGR2RGB), cv2.cvtColor(right, cv2.COLOR_BGR2RGB), depth


def score_views(views_dir: Path, configs: dict[str, StereoConfig]) -> dict[str, ViewScores]:
    """Score each named matcher on every view of ``views_dir`` (each view is read once)."""
    index = load_index(views_dir)
    matchers = {name: StereoMatcher(config) for name, config in configs.items()}
    counts: dict[str, list[PixelCounts]] = {name: [] for name in configs}
    for view in index["views"]:
        left, right, depth = _read_view(Path(views_dir) / view["folder"])
        with np.errstate(divide="ignore"):  # zero depth (no surface) is an unknown disparity
            truth = np.where(depth > 0, index["fx_px"] * index["baseline_m"] / depth, np.nan)
        for name, matcher in matchers.items():
            counts[name].append(count_pixels(matcher.disparity(left, right), truth))
    return {name: ViewScores.of(c) for name, c in counts.items()}

"""The stereo check on the rooms the robot searches: rendered views with true depth.

``syt-onboard worlds views`` writes the views (its ``views.json`` names each one's world, pose and
tilt). Each is scored against its true disparity ``f·B / depth``, with three figures:

- *bad2* and *density*, as for Middlebury (:mod:`offboard.perception.middlebury`);
- *phantom share*: the fraction of answered pixels whose disparity is too large by more than a
  third (and 2 px): a surface put much nearer than it is. Too far is harmless to the map (free space
  is carved a little too deep); too near puts an obstacle where there is none;
- *phantom views*: views where phantoms cover more than ``PHANTOM_VIEW_SHARE`` of the image. That
  many pixels in one place is a wall where there is none, and it can close the robot in.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from offboard.perception.middlebury import BAD_THRESHOLD_PX
from offboard.perception.stereo import StereoConfig, StereoMatcher

PHANTOM_RATIO = 4.0 / 3.0  # a disparity this many times the truth: depth under 3/4 of the true depth
PHANTOM_VIEW_SHARE = 0.02


@dataclass(frozen=True)
class ViewScores:
    bad2: float
    density: float
    phantom_share: float
    phantom_views: int
    views: int

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
    left, right = (cv2.imread(str(folder / name), cv2.IMREAD_GRAYSCALE) for name in ("left.png", "right.png"))
    try:
        depth = np.load(folder / "depth.npy")
    except (OSError, ValueError) as exc:
        raise ValueError(f"{folder}: depth.npy is missing or unreadable ({exc})") from exc
    if left is None or right is None or left.shape != depth.shape or right.shape != depth.shape:
        raise ValueError(f"{folder}: left.png, right.png and depth.npy must all be there, of one size")
    return left, right, depth


def score_views(views_dir: Path, config: StereoConfig) -> ViewScores:
    """Score one matcher on every view of ``views_dir``."""
    index = load_index(views_dir)
    matcher = StereoMatcher(config)
    known = answered = bad = phantom = phantom_views = 0
    for view in index["views"]:
        left, right, depth = _read_view(Path(views_dir) / view["folder"])
        truth = index["fx_px"] * index["baseline_m"] / depth
        disparity = matcher.disparity(left, right)
        ok = np.isfinite(disparity) & np.isfinite(truth)
        error = disparity[ok] - truth[ok]
        too_near = (error > BAD_THRESHOLD_PX) & (disparity[ok] > PHANTOM_RATIO * truth[ok])
        known += int(np.isfinite(truth).sum())
        answered += int(ok.sum())
        bad += int((np.abs(error) > BAD_THRESHOLD_PX).sum())
        phantom += int(too_near.sum())
        phantom_views += int(too_near.sum() > PHANTOM_VIEW_SHARE * disparity.size)
    return ViewScores(bad / max(answered, 1), answered / max(known, 1), phantom / max(answered, 1),
                      phantom_views, len(index["views"]))

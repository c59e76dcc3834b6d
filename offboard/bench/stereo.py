"""``syt-offboard bench stereo --views DIR --json``: both matchers on rendered views of rooms.

The views come from ``syt-onboard worlds views``; the figures are those of
:mod:`offboard.perception.rendered_views` for SAD (9 px window) and SGBM (5 px), with the worlds
and seed that made the views, so every figure says where it comes from, and which of the two the
search uses by default.
"""

from __future__ import annotations

import logging
from pathlib import Path

from offboard.perception.rendered_views import load_index, score_views
from offboard.perception.stereo import StereoConfig

log = logging.getLogger(__name__)

MATCHERS = {"sad": StereoConfig(method="sad", block_size=9), "sgbm": StereoConfig(method="sgbm", block_size=5)}


def run(views_dir: Path) -> dict:
    index = load_index(views_dir)
    log.info("scoring %s on %d views", " and ".join(MATCHERS), len(index["views"]))
    scores = score_views(views_dir, MATCHERS)
    default = next((name for name, config in MATCHERS.items() if config == StereoConfig()), "other")
    return {"views_dir": str(views_dir), "seed": index.get("seed"), "default": default,
            "worlds": sorted({view["world"] for view in index["views"]}),
            **{name: s.as_dict() for name, s in scores.items()}}

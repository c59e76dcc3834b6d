"""A top view of a search, like the report's Fig. 4: the room, the obstacles mapped, the robot's
path, each look's field of view out to its depth of field, and the detection."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from offboard.perception.occupancy import FloorMap
from shared.image_files import write_bgr

PX_PER_M = 80
MARGIN_PX = 40
HEADER_PX = 40
_TILT_COLOURS = {0: (230, 160, 60), 30: (90, 190, 90)}  # BGR: blue-ish for level looks, green raised


@dataclass(frozen=True)
class LookTrace:
    x_m: float
    y_m: float
    azimuth_rad: float
    tilt_deg: float
    depth_m: float  # how far the look could detect the target
    found: bool


def draw_top_view(path: Path, room_m: tuple[float, float, float], floor: FloorMap, trail: list[tuple[float, float]],
                  looks: list[LookTrace], hfov_rad: float, estimate_m: np.ndarray | None, title: str) -> None:
    """Write the picture as PNG."""
    w = int(room_m[0] * PX_PER_M) + 2 * MARGIN_PX
    h = int(room_m[1] * PX_PER_M) + 2 * MARGIN_PX + HEADER_PX
    image = np.full((h, w, 3), 255, np.uint8)

    def px(x: float, y: float) -> tuple[int, int]:
        return int(MARGIN_PX + x * PX_PER_M), int(HEADER_PX + MARGIN_PX + (room_m[1] - y) * PX_PER_M)

    _draw_obstacles(image, floor, px)
    overlay = image.copy()
    for look in looks:
        arc = [px(look.x_m + look.depth_m * math.cos(a), look.y_m + look.depth_m * math.sin(a))
               for a in np.linspace(look.azimuth_rad - hfov_rad / 2, look.azimuth_rad + hfov_rad / 2, 12)]
        colour = (60, 60, 230) if look.found else _TILT_COLOURS.get(int(round(look.tilt_deg)), (180, 120, 200))
        cv2.fillPoly(overlay, [np.array([px(look.x_m, look.y_m), *arc], np.int32)], colour)
    blended = cv2.addWeighted(overlay, 0.25, image, 0.75, 0)
    (x0, y0), (x1, y1) = px(0, room_m[1]), px(room_m[0], 0)
    image[y0:y1, x0:x1] = blended[y0:y1, x0:x1]  # a view ends at the room's walls
    cv2.rectangle(image, px(0, room_m[1]), px(room_m[0], 0), (40, 40, 200), 2)
    for a, b in zip(trail, trail[1:]):
        cv2.arrowedLine(image, px(*a), px(*b), (30, 80, 140), 3, tipLength=0.08)
    for look in looks:  # small arrows: the viewpoints inspected
        tip = (look.x_m + 0.35 * math.cos(look.azimuth_rad), look.y_m + 0.35 * math.sin(look.azimuth_rad))
        cv2.arrowedLine(image, px(look.x_m, look.y_m), px(*tip), (20, 20, 20), 1, tipLength=0.3)
    if trail:
        x, y = trail[0]
        cv2.rectangle(image, px(x - 0.2, y + 0.15), px(x + 0.2, y - 0.15), (40, 90, 160), -1)
    if estimate_m is not None:
        cv2.drawMarker(image, px(estimate_m[0], estimate_m[1]), (0, 0, 255), cv2.MARKER_TILTED_CROSS, 22, 3)
    cv2.putText(image, title, (MARGIN_PX, 28), cv2.FONT_HERSHEY_SIMPLEX, 0.6, (0, 0, 0), 1, cv2.LINE_AA)
    write_bgr(path, image)


def _draw_obstacles(image: np.ndarray, floor: FloorMap, px) -> None:
    res = floor.resolution_m
    for i, j in zip(*np.nonzero(floor.occupied)):
        cv2.rectangle(image, px(i * res, (j + 1) * res), px((i + 1) * res, j * res), (110, 110, 110), -1)

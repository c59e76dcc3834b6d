"""Texture and picture library of the simulator, and the atlas that packs them for the renderer.

*Textures* tile surfaces (walls, floor, furniture). Each has a physical tile size in metres and an
RGB tint; the images are 512 x 512 RGB and wrap seamlessly (the renderer repeats them). They are
photographs shipped offline by scikit-image (brick, grass, gravel) or procedural (wood, carpet,
plaster, metal, fabric, cardboard) from fixed seeds, so every run renders the same scene. Stereo
block matching needs texture on every surface, so even "plain" plaster carries visible mottling.

*Pictures* are stretched over one face (the target's front, a poster). Built-in names: ``target``
(the default target picture: a square, contrast-enhanced crop of scikit-image's cat "chelsea"
that SIFT matches well; the ``chelsea`` poster is therefore a hard distractor), ``astronaut``,
``chelsea``, ``coffee``, ``rocket``, ``hubble``, and ``chessboard`` (a calibration target: 10 x 7
black and white squares, so 9 x 6 inner corners, on a white border one square wide; 4:3, so a
1.2 x 0.9 m poster has 0.1 m squares). A name ending in .png/.jpg/.jpeg is read from disk relative to the world file; such a
name with no file behind it whose stem is a built-in name (``target.png``) falls back to that
built-in picture. ``load_picture`` renders nothing, so the detector side can use it cheaply.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import cv2
import numpy as np
import skimage.data

TEXTURE_SIZE_PX = 512
_PICTURE_SUFFIXES = (".png", ".jpg", ".jpeg")


class PictureError(ValueError):
    """A picture name that is neither built in nor a readable image file."""


@dataclass(frozen=True)
class TextureInfo:
    """How a texture is laid on a surface: one image tile covers ``tile_m`` metres (u, v)."""

    name: str
    tile_m: tuple[float, float]
    tint: tuple[float, float, float]  # multiplies the image colour, 0..1


def _unit_noise(rng: np.random.Generator, cells_x: int, cells_y: int | None = None) -> np.ndarray:
    """Smooth periodic random field, ``cells_x`` x ``cells_y`` blobs per tile, zero mean, unit std."""
    n = TEXTURE_SIZE_PX
    grid = rng.standard_normal((cells_y or cells_x, cells_x)).astype(np.float32)
    # Interpolating a 3 x 3 tiling and keeping the middle makes the field wrap without seams.
    big = cv2.resize(np.tile(grid, (3, 3)), (3 * n, 3 * n), interpolation=cv2.INTER_CUBIC)
    field = big[n : 2 * n, n : 2 * n]
    return (field - field.mean()) / (field.std() + 1e-6)


def _fractal(rng: np.random.Generator, octaves: list[tuple[int, float]]) -> np.ndarray:
    """Sum of noise octaves given as (cells across, weight)."""
    return sum(weight * _unit_noise(rng, cells) for cells, weight in octaves)


def _to_rgb(grey: np.ndarray, lo: float = 0.0, hi: float = 1.0) -> np.ndarray:
    """Float field → uint8 RGB, stretched so its 1st..99th percentiles span [lo, hi] of 255."""
    p1, p99 = np.percentile(grey, [1, 99])
    norm = np.clip((grey - p1) / (p99 - p1 + 1e-6), 0.0, 1.0) * (hi - lo) + lo
    g = (norm * 255.0).astype(np.uint8)
    return np.repeat(g[:, :, None], 3, axis=2)


def _photo(loader: Callable[[], np.ndarray], rotate: bool = False) -> np.ndarray:
    """A 512 x 512 grey photograph made tileable: towards its borders it fades into a copy of itself
    shifted by half a tile, whose borders wrap seamlessly."""
    grey = loader().astype(np.float32)
    if rotate:  # scikit-image's brick wall is photographed with its courses vertical
        grey = np.ascontiguousarray(np.rot90(grey))
    n = grey.shape[0]
    ramp = np.sin(np.pi * (np.arange(n) + 0.5) / n) ** 2
    weight = np.outer(ramp, ramp)
    shifted = np.roll(grey, (n // 2, n // 2), axis=(0, 1))
    blended = weight * grey + (1.0 - weight) * shifted
    # Restore the contrast lost where two uncorrelated images average.
    mean = blended.mean()
    blended = mean + (blended - mean) / np.sqrt(weight**2 + (1.0 - weight) ** 2)
    return _to_rgb(blended, 0.15, 1.0)


def _wood() -> np.ndarray:
    """Planks with growth rings bent by noise, fine grain along the plank and dark seams."""
    rng = np.random.default_rng(11)
    n = TEXTURE_SIZE_PX
    y, x = np.mgrid[0:n, 0:n].astype(np.float32) / n
    plank = np.floor(y * 4)  # four planks across the tile
    warp = 0.35 * _fractal(rng, [(3, 1.0), (8, 0.4)])
    rings = np.sin(2 * np.pi * (9 * (y * 4 - plank) + 3 * warp + 5 * plank + x))
    grain = 0.5 * _unit_noise(rng, 6, 128) + 0.35 * _unit_noise(rng, 12, 256)  # runs along x
    seams = (np.abs((y * 4) - np.round(y * 4)) < 0.012).astype(np.float32)
    field = 0.8 * rings + 0.7 * grain + 0.5 * _unit_noise(rng, 24) - 3.0 * seams + 0.3 * plank
    return _to_rgb(field, 0.2, 1.0)


def _carpet() -> np.ndarray:
    rng = np.random.default_rng(12)
    field = _fractal(rng, [(6, 0.6), (32, 0.6), (128, 0.8), (256, 0.7)])
    return _to_rgb(field, 0.2, 1.0)


def _plaster() -> np.ndarray:
    rng = np.random.default_rng(13)
    field = _fractal(rng, [(4, 0.5), (16, 0.7), (48, 0.8), (160, 0.5)])
    return _to_rgb(field, 0.45, 1.0)


def _metal() -> np.ndarray:
    """Brushed steel: noise stretched along x, a few scratches and broad reflection bands."""
    rng = np.random.default_rng(14)
    n = TEXTURE_SIZE_PX
    streaks = _unit_noise(rng, 4, 64) + 0.8 * _unit_noise(rng, 16, 256)
    field = streaks + 0.8 * _unit_noise(rng, 3) + 0.6 * _unit_noise(rng, 40)
    for _ in range(40):  # kept inside the tile so that it still wraps seamlessly
        x0, y0 = rng.integers(130, n - 130, 2)
        length, angle = rng.uniform(20, 120), rng.uniform(-0.4, 0.4)
        x1, y1 = int(x0 + length * np.cos(angle)), int(y0 + length * np.sin(angle))
        cv2.line(field, (int(x0), int(y0)), (x1, y1), float(rng.uniform(-3, 3)), 1)
    return _to_rgb(field, 0.3, 1.0)


def _fabric() -> np.ndarray:
    """Woven cloth: a fine over-under weave modulated by slubs and stains."""
    rng = np.random.default_rng(15)
    n = TEXTURE_SIZE_PX
    y, x = np.mgrid[0:n, 0:n].astype(np.float32)
    weave = np.sin(2 * np.pi * x / 8) * np.sin(2 * np.pi * y / 8)
    field = 0.7 * weave + _fractal(rng, [(5, 0.6), (24, 0.6), (128, 0.5)])
    return _to_rgb(field, 0.2, 1.0)


def _cardboard() -> np.ndarray:
    rng = np.random.default_rng(16)
    fibres = _unit_noise(rng, 32, 128)
    field = 0.6 * fibres + _fractal(rng, [(6, 0.6), (32, 0.6)])
    return _to_rgb(field, 0.35, 1.0)


_TEXTURES: dict[str, tuple[TextureInfo, Callable[[], np.ndarray]]] = {
    t.name: (t, make)
    for t, make in [
        (TextureInfo("brick", (1.2, 1.2), (0.95, 0.62, 0.5)),
         lambda: _photo(skimage.data.brick, rotate=True)),
        (TextureInfo("grass", (0.8, 0.8), (0.55, 0.85, 0.45)), lambda: _photo(skimage.data.grass)),
        (TextureInfo("gravel", (0.8, 0.8), (0.85, 0.85, 0.8)), lambda: _photo(skimage.data.gravel)),
        (TextureInfo("wood", (1.0, 1.0), (0.85, 0.6, 0.38)), _wood),
        (TextureInfo("carpet", (0.6, 0.6), (0.45, 0.5, 0.62)), _carpet),
        (TextureInfo("plaster", (1.5, 1.5), (0.95, 0.93, 0.88)), _plaster),
        (TextureInfo("metal", (0.8, 0.8), (0.75, 0.78, 0.82)), _metal),
        (TextureInfo("fabric", (0.3, 0.3), (0.35, 0.45, 0.6)), _fabric),
        (TextureInfo("cardboard", (0.5, 0.5), (0.8, 0.65, 0.45)), _cardboard),
    ]
}

# Default texture per surface when the world names none; obstacles by their ``kind`` label.
_SURFACE_DEFAULTS = {"wall": "plaster", "floor": "carpet", "ceiling": "plaster", "target": "cardboard",
                     "poster": "cardboard"}
_KIND_DEFAULTS = {"table": "wood", "desk": "wood", "shelf": "wood", "bookshelf": "wood",
                  "chair": "fabric", "sofa": "fabric", "partition": "fabric", "cabinet": "metal",
                  "locker": "metal", "box": "cardboard", "crate": "wood", "pillar": "brick"}
_OBSTACLE_FALLBACK = "metal"


def texture_names() -> list[str]:
    return sorted(_TEXTURES)


def texture_info(name: str) -> TextureInfo:
    """Tile size and tint of a named texture (KeyError for unknown names)."""
    return _TEXTURES[name][0]


@functools.lru_cache(maxsize=None)
def texture_image(name: str) -> np.ndarray:
    """The (512, 512, 3) uint8 image of a named texture, built once and read-only."""
    image = _TEXTURES[name][1]()
    image.setflags(write=False)
    return image


def default_texture(surface: str, kind: str | None = None) -> str:
    """Texture for a surface ("wall", "floor", "ceiling", "obstacle", "target", "poster")."""
    if surface == "obstacle":
        return _KIND_DEFAULTS.get((kind or "").lower(), _OBSTACLE_FALLBACK)
    return _SURFACE_DEFAULTS[surface]


class TextureAtlas:
    """Images with their mip levels (halved with area averaging down to 1 x 1), packed into flat
    arrays for the renderer's kernels: ``texels`` holds one uint32 per texel (r | g << 8 | b << 16,
    so a bilinear tap is 4 loads, not 12), ``levels`` rows are (offset, width, height) and
    ``images`` rows are (first level, level count)."""

    def __init__(self) -> None:
        self._chunks: list[np.ndarray] = []
        self._levels: list[tuple[int, int, int]] = []  # offset, width, height
        self._images: list[tuple[int, int]] = []  # first level, level count
        self._size = 0

    def add(self, image: np.ndarray) -> int:
        """Add an (H, W, 3) uint8 image; returns its index."""
        first = len(self._levels)
        level = np.ascontiguousarray(image[:, :, :3], dtype=np.uint8)
        while True:
            h, w = level.shape[:2]
            packed = level.astype(np.uint32)
            self._chunks.append((packed[:, :, 0] | packed[:, :, 1] << 8 | packed[:, :, 2] << 16).ravel())
            self._levels.append((self._size, w, h))
            self._size += w * h
            if w == 1 and h == 1:
                break
            level = cv2.resize(level, (max(1, w // 2), max(1, h // 2)), interpolation=cv2.INTER_AREA)
            level = level.reshape(level.shape[0], level.shape[1], 3)
        self._images.append((first, len(self._levels) - first))
        return len(self._images) - 1

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(texels, levels, images)."""
        return (np.concatenate(self._chunks), np.array(self._levels, dtype=np.int64),
                np.array(self._images, dtype=np.int64))


def _target_picture() -> np.ndarray:
    """A tight crop of the cat's face (eyes, nose, fur stripes) with local contrast raised (CLAHE on
    lightness): about 1.7 times as many SIFT matches survive its shrinking to ~38 px, the size of
    a 0.23 m target seen from 3 m."""
    lab = cv2.cvtColor(np.ascontiguousarray(skimage.data.chelsea()[20:270, 90:340]), cv2.COLOR_RGB2LAB)
    lab[:, :, 0] = cv2.createCLAHE(clipLimit=2.0, tileGridSize=(4, 4)).apply(lab[:, :, 0])
    return cv2.cvtColor(lab, cv2.COLOR_LAB2RGB)


CHESSBOARD_SQUARES = (10, 7)  # columns, rows of squares; inner corners are one fewer each way
CHESSBOARD_SQUARE_PX = 64


def _chessboard() -> np.ndarray:
    """Black and white squares inside a white border one square wide (detectors need the border)."""
    cols, rows = CHESSBOARD_SQUARES
    y, x = np.mgrid[0 : rows + 2, 0 : cols + 2]
    inside = (x >= 1) & (x <= cols) & (y >= 1) & (y <= rows)
    cells = np.where(inside & ((x + y) % 2 == 0), 0, 255).astype(np.uint8)
    grey = np.kron(cells, np.ones((CHESSBOARD_SQUARE_PX, CHESSBOARD_SQUARE_PX), dtype=np.uint8))
    return np.repeat(grey[:, :, None], 3, axis=2)


_BUILTIN_PICTURES: dict[str, Callable[[], np.ndarray]] = {
    "target": _target_picture,
    "astronaut": skimage.data.astronaut,
    "chelsea": skimage.data.chelsea,
    "coffee": skimage.data.coffee,
    "rocket": skimage.data.rocket,
    "hubble": skimage.data.hubble_deep_field,
    "chessboard": _chessboard,
}


def picture_names() -> list[str]:
    return sorted(_BUILTIN_PICTURES)


def load_picture(name: str, base_dir: Path | str | None = None) -> np.ndarray:
    """A picture as (H, W, 3) uint8 RGB, read-only (copy it to modify).

    ``name`` is a built-in picture name or an image file (.png/.jpg/.jpeg) relative to ``base_dir``
    (or absolute). Raises ``PictureError`` for unknown names and unreadable files.
    """
    if name.lower().endswith(_PICTURE_SUFFIXES):
        path = Path(name) if base_dir is None else Path(base_dir) / name
        if path.is_file():
            return _read_picture_file(str(path.resolve()), path.stat().st_mtime_ns)
        if Path(name).stem in _BUILTIN_PICTURES and Path(name).name == name:
            return _builtin_picture(Path(name).stem)
        raise PictureError(f"picture file {str(path)!r} does not exist")
    if name in _BUILTIN_PICTURES:
        return _builtin_picture(name)
    raise PictureError(
        f"unknown picture {name!r}: use a built-in name ({', '.join(picture_names())}) "
        "or an image file ending in .png/.jpg/.jpeg"
    )


@functools.lru_cache(maxsize=None)
def _builtin_picture(name: str) -> np.ndarray:
    image = np.ascontiguousarray(_BUILTIN_PICTURES[name]()[:, :, :3])
    image.setflags(write=False)
    return image


@functools.lru_cache(maxsize=32)
def _read_picture_file(path: str, mtime_ns: int) -> np.ndarray:
    """Cached by path and modification time, so an edited file is read again."""
    bgr = cv2.imread(path, cv2.IMREAD_COLOR)
    if bgr is None:
        raise PictureError(f"cannot read picture file {path!r} as an image")
    image = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
    image.setflags(write=False)
    return image

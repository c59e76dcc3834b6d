"""A priori search knowledge (report §3.4): the five types, combinable by weights.

- Type 1, no knowledge: :func:`uniform`.
- Type 3, hints: :func:`hints` — weighted boxes from a TOML file, the rest of the room sharing what
  is left (the report's "the target is on one of the tables").
- Type 2, indirect search: :class:`SupportSurfaces` — the space just above horizontal surfaces found
  in the occupancy map (tables, shelves) is raised, and re-raised as the map grows.
- Type 4, saliency: :class:`Saliency` — a bottom-up saliency map of each image (spectral residual)
  times the back-projection of the target's colour histogram, carried into the cubes that image saw.
- Type 5, predictive: :func:`last_seen` — a last-known location whose spread grows with time.

Static priors (1, 3, 5) are grid-shaped weights mixed by :func:`combine` and set once; dynamic ones
(2, 4) return factors that :meth:`TargetBelief.reweight` folds in as evidence arrives. Each dynamic
prior remembers the factor it has applied to each cube (:meth:`memory`), so the same evidence seen
again is not counted again, and a checkpoint can carry that memory (:meth:`restore`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from offboard.perception.occupancy import OccupancyGrid
from offboard.perception.voxel_grid import VoxelGrid
from shared.geometry import Intrinsics, RigidTransform
from shared.strict import bounds


@dataclass(frozen=True)
class HintBox:
    """A box (world frame) holding ``weight`` of the target probability."""

    min: tuple[float, float, float]
    max: tuple[float, float, float]
    weight: float = field(metadata=bounds(0.0, 1.0))
    name: str = ""

    def __post_init__(self) -> None:
        if any(a >= b for a, b in zip(self.min, self.max)):
            raise ValueError("max must exceed min on every axis")


@dataclass(frozen=True)
class HintsFile:
    """A hints file: ``[[hint]]`` tables with ``min``, ``max``, ``weight`` and an optional ``name``
    (read with ``shared.config.load_config``; this package does no I/O)."""

    hint: tuple[HintBox, ...]

    def __post_init__(self) -> None:
        if sum(h.weight for h in self.hint) > 1.0 + 1e-9:
            raise ValueError("the hints' weights add up to more than 1")


def uniform(grid: VoxelGrid) -> np.ndarray:
    return np.ones(grid.shape)


def hints(grid: VoxelGrid, boxes: tuple[HintBox, ...]) -> np.ndarray:
    """Each box's cubes share its weight; all other cubes share what is left."""
    weights = np.zeros(grid.shape)
    claimed = np.zeros(grid.shape, bool)
    for box in boxes:
        cubes = grid.box_slices(np.array(box.min), np.array(box.max))
        count = int(np.prod([s.stop - s.start for s in cubes]))
        if count == 0:  # its weight would vanish, unsaid
            raise ValueError(f"hint {box.name or box.min}: the box holds no cube centre of the room (a box "
                             f"thinner than a cube, {grid.resolution_m:g} m, or outside the room)")
        weights[cubes] += box.weight / count
        claimed[cubes] = True
    rest = max(0.0, 1.0 - sum(b.weight for b in boxes))
    if (~claimed).any():
        weights[~claimed] = rest / (~claimed).sum()
    return weights


def last_seen(grid: VoxelGrid, position_m: np.ndarray, elapsed_s: float, sigma0_m: float = 0.2,
              spread_m_per_s: float = 0.01) -> np.ndarray:
    """Type 5: a Gaussian around where the target was last known, wider the longer ago."""
    sigma = sigma0_m + spread_m_per_s * max(elapsed_s, 0.0)
    weights = np.exp(-0.5 * grid.squared_distances(position_m) / sigma**2)
    if not weights.any():  # a units slip, say: alone it would leave nothing inside the room, mixed it would vanish
        raise ValueError(f"last seen at {tuple(float(v) for v in position_m)}, so far outside the room (spread "
                         f"{sigma:.2g} m) that no cube holds any of it")
    return weights


def combine(grid: VoxelGrid, weighted: list[tuple[float, np.ndarray]]) -> np.ndarray:
    """A mixture: Σ w_i · prior_i / Σ prior_i."""
    total = np.zeros(grid.shape)
    for weight, prior in weighted:
        mass = prior.sum()
        if mass > 0:
            total += weight * prior / mass
    return total


@dataclass(frozen=True)
class SupportConfig:
    min_height_m: float = 0.3  # lower than this is the floor, not a surface to search on
    max_height_m: float = 2.2
    layer_m: float = 0.3  # the space above a surface where objects rest
    min_area_m2: float = 0.04  # ignore specks
    boost: float = 5.0  # how much more likely the target is above a surface than elsewhere


class _FactorMemory:
    """What a dynamic prior has applied to each cube so far: it applies only what is new, so the same
    evidence seen again is not counted again, and a checkpoint carries it (:meth:`memory`,
    :meth:`restore`)."""

    def __init__(self, grid: VoxelGrid):
        self.grid = grid
        self._applied = np.ones(grid.shape, np.float32)

    def _bring_to(self, wanted: np.ndarray, cubes: np.ndarray | slice = slice(None)) -> np.ndarray:
        """The grid-shaped factor that brings ``cubes`` (flat indices; all by default) from what they
        have had to ``wanted``; 1 elsewhere."""
        applied = self._applied.reshape(-1)
        factor = np.ones(self.grid.num_cubes, np.float32)
        factor[cubes] = wanted / applied[cubes]
        applied[cubes] = wanted
        return factor.reshape(self.grid.shape)

    def memory(self) -> np.ndarray:
        """The factor applied so far to each cube (grid-shaped)."""
        return self._applied

    def restore(self, memory: np.ndarray) -> None:
        """Take back a :meth:`memory` (a copy), refused unless it fits the grid."""
        memory = np.array(memory, np.float32)
        if memory.shape != self.grid.shape or not np.all(np.isfinite(memory)) or np.any(memory <= 0):
            raise ValueError(f"a dynamic prior's memory must be positive, finite and of shape {self.grid.shape}, "
                             f"not {memory.shape}")
        self._applied = memory


class SupportSurfaces(_FactorMemory):
    """Type 2: raise the probability just above horizontal support surfaces of the occupancy map."""

    def __init__(self, grid: VoxelGrid, config: SupportConfig = SupportConfig()):
        super().__init__(grid)
        self.config = config

    def surfaces(self, occupancy: OccupancyGrid) -> np.ndarray:
        """Occupied cubes, within the height band, with a free cube right above (grid-shaped bool)."""
        occ = occupancy.occupied()
        state_free = occupancy.observed & ~occ
        top = np.zeros_like(occ)
        top[:, :, :-1] = occ[:, :, :-1] & state_free[:, :, 1:]
        z = self.grid.axis_centers()[2]  # each layer's height
        top[:, :, (z < self.config.min_height_m) | (z > self.config.max_height_m)] = False
        area_cells = self.config.min_area_m2 / self.grid.resolution_m**2
        column = top.any(axis=2).astype(np.uint8)
        count, labels, stats, _ = cv2.connectedComponentsWithStats(column, connectivity=8)
        small = np.isin(labels, np.nonzero(stats[:, cv2.CC_STAT_AREA] < area_cells)[0])
        top[small] = False
        return top

    def update(self, occupancy: OccupancyGrid) -> np.ndarray:
        """The factor to reweight the belief by, given what the map shows now."""
        top = self.surfaces(occupancy)
        above = np.zeros_like(top)
        layers = max(1, int(round(self.config.layer_m / self.grid.resolution_m)))
        for k in range(1, layers + 1):
            above[:, :, k:] |= top[:, :, :-k]
        return self._bring_to(np.where(above, self.config.boost, 1.0).astype(np.float32).reshape(-1))


class Saliency(_FactorMemory):
    """Type 4: where in an image something looks like the target, carried into the cubes it saw."""

    def __init__(self, target_pictures: tuple[np.ndarray, ...], grid: VoxelGrid, gain: float = 2.0, bins: int = 16):
        hsv = [cv2.cvtColor(p, cv2.COLOR_RGB2HSV) for p in target_pictures]
        # one picture at a time: calcHist numbers the channels across its list of images
        hist = sum(cv2.calcHist([picture], [0, 1], None, [bins, bins], [0, 180, 0, 256]) for picture in hsv)
        self._hist = cv2.normalize(hist, None, 0, 255, cv2.NORM_MINMAX)
        super().__init__(grid)  # the strongest factor each cube has had
        self.gain = gain

    def score(self, image_rgb: np.ndarray) -> np.ndarray:
        """Per-pixel score in [0, 1]: spectral-residual saliency × target-colour back-projection."""
        return self.spectral_residual(image_rgb) * self.colour_match(image_rgb)

    @staticmethod
    def spectral_residual(image_rgb: np.ndarray, size: int = 64) -> np.ndarray:
        """Hou & Zhang (2007): the log spectrum minus its local average, back to the image."""
        grey = cv2.resize(cv2.cvtColor(image_rgb, cv2.COLOR_RGB2GRAY), (size, size)).astype(np.float64)
        spectrum = np.fft.fft2(grey)
        log_amplitude = np.log(np.abs(spectrum) + 1e-9)
        residual = log_amplitude - cv2.blur(log_amplitude, (3, 3))
        saliency = np.abs(np.fft.ifft2(np.exp(residual + 1j * np.angle(spectrum)))) ** 2
        saliency = cv2.GaussianBlur(saliency, (0, 0), 2.5)
        saliency = cv2.resize(saliency, (image_rgb.shape[1], image_rgb.shape[0]))
        return saliency / max(saliency.max(), 1e-12)

    def colour_match(self, image_rgb: np.ndarray) -> np.ndarray:
        hsv = cv2.cvtColor(image_rgb, cv2.COLOR_RGB2HSV)
        back = cv2.calcBackProject([hsv], [0, 1], self._hist, [0, 180, 0, 256], 1).astype(np.float64)
        return cv2.GaussianBlur(back, (0, 0), 5) / 255.0

    def factor(self, image_rgb: np.ndarray, cube_index: np.ndarray, camera_in_world: RigidTransform,
               intrinsics: Intrinsics) -> np.ndarray:
        """Grid-shaped factor that brings each seen cube to 1 + gain × score at its pixel, if that is
        more than it has had; 1 elsewhere. The same sight seen again is the same evidence: multiplied
        in with every look, it once grew without bound where a salient thing was seen from afar, too
        far for the detector, and piled the belief there (a `test` search stopped "exhausted")."""
        score = self.score(image_rgb)
        centers = self.grid.center_of(np.stack(np.unravel_index(cube_index, self.grid.shape), axis=-1))
        uv = intrinsics.project(camera_in_world.inverse().apply(centers))
        u = np.clip(np.nan_to_num(uv[:, 0]).round().astype(int), 0, intrinsics.width_px - 1)
        v = np.clip(np.nan_to_num(uv[:, 1]).round().astype(int), 0, intrinsics.height_px - 1)
        wanted = np.maximum(self._applied.reshape(-1)[cube_index], 1.0 + self.gain * score[v, u])
        return self._bring_to(wanted.astype(np.float32), cube_index)

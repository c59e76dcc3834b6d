"""Where the target may be: the target probability p(c_i, τ) over the cubes, plus c_out (report §3).

Paper symbols, named once:

- ``p(c_i, τ)`` → :attr:`TargetBelief.target_prob`; ``p(c_out, τ)`` → :attr:`TargetBelief.prob_outside`;
- ``b(c_i, f)`` → ``detection_prob`` (computed per look in :mod:`offboard.planning.detection_function`);
- ``P[F]`` (§3.2, the success probability of the looks so far; the report's eq. 2 is their time,
  T[F]) → :attr:`TargetBelief.success_prob`.

Beyond the report (its §6.2, "future work"): the target's facing is unknown, so each cube's mass is
split over ``facing_sectors`` directions its pictured face could point to. A look that misses
removes mass only from the facings it could have seen, so a second look from the same side is
worth less than a look from a new side, and a cube is ruled out only once seen from enough sides.
With one sector this is exactly eq. 4.

Stereo sees more than the detector does: a cube it has seen empty (space in front of a visible
surface) cannot hold the target's centre, whichever way the target faces. :meth:`rule_out_empty`
folds that in once per cube, with a likelihood ``empty_factor`` > 0 for stereo's mistakes; which
cubes count as empty is the occupancy map's :meth:`~offboard.perception.occupancy.OccupancyGrid.seen_empty`.

The map also says which way a picture can face: not into a surface just in front of it.
:meth:`exclude_facings_into_walls` applies this to the room's walls at the start, and
:meth:`rule_out_blocked_facings` to each surface as the map finds it, once per cube and facing.

Masses are stored scaled (``stored × scale`` is the probability) so that the normalisation of eq. 4
costs one scalar instead of a pass over every cube. The planner also reads a coarse copy (cubes
summed into ``coarse_factor``³ blocks) kept up to date by the same update.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from offboard.perception.voxel_grid import VoxelGrid


class TargetBelief:
    def __init__(self, grid: VoxelGrid, facing_sectors: int = 8, prob_outside: float = 0.05,
                 coarse_factor: int = 4):
        if facing_sectors < 1 or not 0.0 <= prob_outside < 1.0 or coarse_factor < 1:
            raise ValueError("need facing_sectors ≥ 1, 0 ≤ prob_outside < 1 and coarse_factor ≥ 1")
        self.grid = grid
        self.facing_sectors = facing_sectors
        self.coarse_factor = coarse_factor
        self.coarse_shape = tuple(-(-n // coarse_factor) for n in grid.shape)
        self._mass = np.zeros((*grid.shape, facing_sectors), np.float32)
        self._seen_empty = np.zeros(grid.shape, np.bool_)
        self._facing_blocked = np.zeros((*grid.shape, facing_sectors), np.bool_)
        self._solid_done = np.zeros(grid.shape, np.bool_)  # a cache: the solid cubes already folded in
        self._coarse = np.zeros((*self.coarse_shape, facing_sectors), np.float64)
        self.success_prob = 0.0  # P[F], §3.2
        self.set_prior(np.ones(grid.shape), prob_outside)

    @property
    def facing_azimuths_rad(self) -> np.ndarray:
        """World azimuth of the face's normal in each facing sector; with a single sector, NaN: the
        report's assumption that the target faces the camera, whichever way it looks."""
        if self.facing_sectors == 1:
            return np.array([np.nan])
        return np.arange(self.facing_sectors) * (2.0 * math.pi / self.facing_sectors)

    # --- reading -------------------------------------------------------------------------------------

    @property
    def target_prob(self) -> np.ndarray:
        """p(c_i, τ) for every cube, shape ``grid.shape`` (float64)."""
        return self._mass.sum(axis=-1, dtype=np.float64) * self._scale

    @property
    def prob_outside(self) -> float:
        """p(c_out, τ): the target is not in the region at all."""
        return self._outside * self._scale

    @property
    def prob_inside(self) -> float:
        return 1.0 - self.prob_outside

    def coarse_mass(self) -> np.ndarray:
        """Probability per coarse block and facing sector, shape ``coarse_shape + (facing_sectors,)``."""
        return self._coarse * self._scale

    def mass_by_facing(self) -> np.ndarray:
        """Probability per cube and facing sector (a copy), shape ``grid.shape + (facing_sectors,)``."""
        return self._mass.astype(np.float64) * self._scale

    # --- updating ------------------------------------------------------------------------------------

    def set_prior(self, weights: np.ndarray, prob_outside: float) -> None:
        """Start afresh: p(c_i) ∝ ``weights`` (non-negative, grid-shaped), the facing unknown, nothing
        seen yet (no cube ruled out, no facing blocked, P[F] = 0). All-zero weights say the target is
        not in the room: p(c_out) = 1 whatever ``prob_outside`` is."""
        weights = self._grid_factors(weights, "prior weights")
        if not 0.0 <= prob_outside < 1.0:
            raise ValueError(f"p(c_out) must lie in [0, 1), not {prob_outside}")
        for seen in (self._seen_empty, self._facing_blocked, self._solid_done):
            seen[:] = False
        self.success_prob = 0.0
        total = weights.sum()
        inside = (1.0 - prob_outside) * weights / total if total > 0 else np.zeros_like(weights)
        self._mass[:] = (inside / self.facing_sectors)[..., None]
        self._outside = 1.0 - inside.sum() if total > 0 else 1.0
        self._scale = 1.0
        self._stored_total = float(self._mass.sum(dtype=np.float64)) + self._outside
        self._rebuild_coarse()

    def exclude_facings_into_walls(self, clearance_m: float) -> None:
        """No picture faces a wall it almost touches: a facing whose face point (``clearance_m`` out
        from a cube's centre, along the facing) lies outside the room's known boundary gets no mass;
        the rest of each cube's share keeps the prior's total inside the room."""
        if self.facing_sectors == 1:
            return  # the target faces the camera, whichever way it looks
        inside_before = self._mass.sum(dtype=np.float64)
        xs, ys, _ = self.grid.axis_centers()
        for s, azimuth in enumerate(self.facing_azimuths_rad):
            step = clearance_m * np.array([math.cos(azimuth), math.sin(azimuth)])
            for axis, centres in enumerate((xs, ys)):  # x and y apart: no (nx, ny, nz) array of faces
                face = centres + step[axis] - self.grid.origin_m[axis]
                beyond = (face < 0.0) | (face > self.grid.size_m[axis])
                self._mass[(slice(None),) * axis + (beyond, Ellipsis, s)] = 0.0
        if not self._keep_inside_total(inside_before):
            self._renormalise()  # no facing fits anywhere: the target is not in this room
            return
        self._stored_total = float(self._mass.sum(dtype=np.float64)) + self._outside
        self._rebuild_coarse()

    def reweight(self, factors: np.ndarray) -> None:
        """Multiply every cube's mass by a grid-shaped factor (priors that arrive during the search:
        support surfaces, saliency). p(c_out) stays: such a prior says where in the room the target
        is more likely, not whether it is in the room."""
        factors = self._grid_factors(factors, "reweighting factors")
        if factors.max() * max(self._stored_total, 1.0) > _FLOAT32_MAX / 2:  # stored masses ≤ their total
            raise ValueError(f"reweighting factors up to {factors.max():g} overflow the float32 masses")
        factors = factors.astype(np.float32)
        if not factors[self._mass.any(axis=-1)].any():  # checked first: the product cannot be undone
            raise ValueError("reweighting factors are zero (in float32) on every cube that holds mass: "
                             "p(c_out) would become 1")
        inside_before = self._mass.sum(dtype=np.float64)
        self._mass *= factors[..., None]
        self._keep_inside_total(inside_before)
        self._renormalise()

    def _grid_factors(self, factors: np.ndarray, what: str) -> np.ndarray:
        factors = np.asarray(factors, np.float64)
        if factors.shape != self.grid.shape or np.any(factors < 0) or not np.all(np.isfinite(factors)):
            raise ValueError(f"{what} must be finite, non-negative and of shape {self.grid.shape}, "
                             f"not of shape {factors.shape}")
        return factors

    def _keep_inside_total(self, inside_before: float) -> bool:
        """Scale the cubes' stored mass back to ``inside_before`` in all; False if none is left."""
        inside_after = self._mass.sum(dtype=np.float64)
        if inside_after > 0:
            self._mass *= np.float32(inside_before / inside_after)
        return inside_after > 0

    def update_after_miss(self, cube_index: np.ndarray, detection_prob: np.ndarray) -> float:
        """Eq. 4 after a look that did not find the target.

        ``cube_index``: flat indices of the cubes the look could see; ``detection_prob``: b(c, f) for
        each of them and each facing sector, shape (n, facing_sectors). Returns the look's detection
        probability P_Ψ(f) (eq. 1) and folds it into P[F] (§3.2).
        """
        cube_index = self._cube_index(cube_index)
        b = self._detection_prob(detection_prob, len(cube_index), np.float32)
        found_prob = self._observe(cube_index, 1.0 - b)  # eq. 1: Σ p(c) b(c, f), before the update
        self.success_prob += (1.0 - self.success_prob) * found_prob  # P[F] of §3.2, one more term
        return found_prob

    def expected_detection(self, cube_index: np.ndarray, detection_prob: np.ndarray) -> float:
        """Eq. 1, P_Ψ(f) = Σ p(c) b(c, f), over a look's cubes, without updating anything."""
        cube_index = self._cube_index(cube_index)
        b = self._detection_prob(detection_prob, len(cube_index), np.float64)
        mass = self._mass.reshape(-1, self.facing_sectors)[cube_index]
        return float((mass * b).sum()) * self._scale

    def _detection_prob(self, detection_prob: np.ndarray, n: int, dtype: type) -> np.ndarray:
        b = self._per_facing(detection_prob, n, "detection_prob", dtype)
        if b.size and not (b.min() >= 0.0 and b.max() <= 1.0):  # NaN fails both
            raise ValueError(f"detection_prob must lie in [0, 1], not in [{b.min()}, {b.max()}]")
        return b

    def _per_facing(self, values: np.ndarray, n: int, what: str, dtype: type) -> np.ndarray:
        """``values`` as an (n, facing_sectors) array: a transposed or flat one is refused, not reshaped."""
        values = np.ascontiguousarray(values, dtype)
        if values.shape != (n, self.facing_sectors):
            raise ValueError(f"{what} must be of shape {(n, self.facing_sectors)}, not {values.shape}")
        return values

    def _cube_index(self, cube_index: np.ndarray) -> np.ndarray:
        """The listed cubes as int64, each in the grid (the kernel checks no bounds) and listed once (a
        repeat would be updated twice and counted twice in eq. 1)."""
        cube_index = np.ascontiguousarray(cube_index, np.int64)
        if cube_index.ndim != 1:
            raise ValueError(f"cube_index must be 1-D, not of shape {cube_index.shape}")
        if cube_index.size and not (cube_index.min() >= 0 and cube_index.max() < self.grid.num_cubes):
            raise ValueError(f"cube_index must lie in [0, {self.grid.num_cubes}), not in "
                             f"[{cube_index.min()}, {cube_index.max()}]")
        if not np.all(cube_index[1:] > cube_index[:-1]):  # a footprint comes sorted: O(n) then
            ordered = np.sort(cube_index)
            repeated = ordered[1:][ordered[1:] == ordered[:-1]]
            if repeated.size:
                raise ValueError(f"cube_index lists cube {repeated[0]} more than once")
        return cube_index

    def observe(self, cube_index: np.ndarray, likelihood: np.ndarray) -> float:
        """Bayes' rule for one observation: every listed cube's mass, per facing sector, times its
        ``likelihood`` (n, facing_sectors) relative to every other cube and to c_out, whose factor is
        1; then normalised (eq. 4's denominator). Returns the probability that left the listed cubes
        (negative if they gained)."""
        cube_index = self._cube_index(cube_index)
        likelihood = self._per_facing(likelihood, len(cube_index), "likelihood", np.float32)
        if np.any(likelihood < 0) or not np.all(np.isfinite(likelihood)):
            raise ValueError("likelihoods must be finite and non-negative")
        return self._observe(cube_index, likelihood)

    def _observe(self, cube_index: np.ndarray, likelihood: np.ndarray) -> float:
        """:meth:`observe` of checked input."""
        saved = self._mass.reshape(-1, self.facing_sectors)[cube_index] if self._outside <= 0 else None  # a copy
        removed, kept = _scale_seen_mass(self._mass.reshape(-1, self.facing_sectors),
                                         self._coarse.reshape(-1, self.facing_sectors), cube_index, likelihood,
                                         np.array(self.grid.shape, np.int64), np.array(self.coarse_shape, np.int64),
                                         self.coarse_factor)
        left = removed * self._scale
        if self._stored_total - removed <= 0 or self._nothing_kept(kept):  # the belief stays as it was
            if saved is not None:
                self._mass.reshape(-1, self.facing_sectors)[cube_index] = saved
                self._rebuild_coarse()
            raise ValueError("an observation left no probability anywhere")
        self._stored_total -= removed
        self._scale = 1.0 / self._stored_total
        if not 1e-6 < self._scale < 1e6:  # keep stored values in float32's comfortable range
            self._renormalise()
        return left

    def _nothing_kept(self, kept: float) -> bool:
        """No mass left anywhere: tested on the masses themselves, as the running total drifts by
        float32 rounding and may stay just above 0. The full pass runs only if c_out and the listed
        cubes keep nothing."""
        return self._outside <= 0 and kept <= 0 and not self._mass.any()

    # --- checkpoint ----------------------------------------------------------------------------------

    def state(self) -> dict:
        """Everything the belief holds (arrays not copied): :meth:`restore` of it is this belief, bit
        for bit. The coarse copy is kept: updated incrementally, it differs from a rebuilt one."""
        return {"mass": self._mass, "coarse": self._coarse, "seen_empty": self._seen_empty,
                "facing_blocked": self._facing_blocked, "outside": self._outside, "scale": self._scale,
                "stored_total": self._stored_total, "success_prob": self.success_prob}

    def restore(self, state: dict) -> None:
        """Take back a :meth:`state` of a belief over the same grid, sectors and coarse factor."""
        for name, own in (("mass", self._mass), ("coarse", self._coarse), ("seen_empty", self._seen_empty),
                          ("facing_blocked", self._facing_blocked)):
            given = np.asarray(state[name])
            if given.shape != own.shape or given.dtype != own.dtype:
                raise ValueError(f"belief {name}: expected {own.dtype} {own.shape}, got {given.dtype} {given.shape}")
        self._mass[:] = state["mass"]
        self._coarse[:] = state["coarse"]
        self._seen_empty[:] = state["seen_empty"]
        self._facing_blocked[:] = state["facing_blocked"]
        self._solid_done[:] = False  # the next rule_out_blocked_facings goes over every solid cube again
        self._outside, self._scale = float(state["outside"]), float(state["scale"])
        self._stored_total, self.success_prob = float(state["stored_total"]), float(state["success_prob"])

    def rule_out_empty(self, empty: np.ndarray, empty_factor: float) -> float:
        """Cubes stereo has seen empty (grid-shaped bool) keep only ``empty_factor`` of their mass, all
        facings alike; each cube once (the occupancy map already sums its evidence over the looks).
        Returns the probability that left them."""
        self._check_mask(empty, "empty")
        self._check_share(empty_factor, "empty_factor")
        new = np.flatnonzero(np.asarray(empty, bool) & ~self._seen_empty)
        likelihood = np.full((len(new), self.facing_sectors), empty_factor, np.float32)
        left = self._observe(new, likelihood) if len(new) else 0.0
        self._seen_empty.flat[new] = True  # only once applied: evidence refused now is applied next time
        return left

    def _check_mask(self, mask: np.ndarray, what: str) -> None:
        if np.shape(mask) != self.grid.shape:  # a smaller mask would broadcast
            raise ValueError(f"{what} must be a mask of shape {self.grid.shape}, not {np.shape(mask)}")

    @staticmethod
    def _check_share(factor: float, what: str) -> None:
        if not 0.0 <= factor <= 1.0:  # NaN fails too; above 1 would add mass
            raise ValueError(f"{what} must lie in [0, 1], not {factor}")

    def rule_out_blocked_facings(self, solid: np.ndarray, near_m: float, far_m: float, factor: float) -> float:
        """A picture faces open space: a facing with a ``solid`` cube (grid-shaped bool, the mapped
        surfaces) between ``near_m`` and ``far_m`` in front of a cube's centre keeps only ``factor`` of
        its mass; each (cube, facing) once. :meth:`exclude_facings_into_walls` does this for the room's
        walls at the start; this does it for what the map finds. Returns the probability that left."""
        self._check_mask(solid, "solid")
        self._check_share(factor, "factor")
        if self.facing_sectors == 1:
            return 0.0
        sectors, (nx, ny, nz) = self.facing_sectors, self.grid.shape
        solid_cube = np.flatnonzero(solid & ~self._solid_done)  # a cube solid before blocked its facings then
        i, j = solid_cube // (ny * nz), (solid_cube // nz) % ny
        pairs = []  # (cube × sectors + sector) of every facing that has a solid cube ahead
        for s, (dx, dy) in self._facing_steps(near_m, far_m):
            ahead = (i >= dx) & (i - dx < nx) & (j >= dy) & (j - dy < ny)
            pairs.append((solid_cube[ahead] - (dx * ny + dy) * nz) * sectors + s)
        pairs = np.concatenate(pairs) if pairs else np.zeros(0, np.int64)
        blocked = self._facing_blocked.reshape(-1)
        new = np.unique(pairs[~blocked[pairs]])
        left = self._keep_share(new, factor) if len(new) else 0.0
        blocked[new] = True  # only once applied: evidence refused now is applied next time
        self._solid_done.flat[solid_cube] = True
        return left

    def _keep_share(self, pairs: np.ndarray, factor: float) -> float:
        """Observe ``factor`` on the (cube × sectors + sector) ``pairs``, 1 on the cubes' other facings."""
        cubes, row = np.unique(pairs // self.facing_sectors, return_inverse=True)
        likelihood = np.ones((len(cubes), self.facing_sectors), np.float32)
        likelihood[row, pairs % self.facing_sectors] = factor
        return self._observe(cubes, likelihood)

    def _facing_steps(self, near_m: float, far_m: float) -> list[tuple[int, tuple[int, int]]]:
        """(sector, cube offset) of every cube between ``near_m`` and ``far_m`` ahead along each facing,
        sampled every half cube."""
        res = self.grid.resolution_m
        steps = np.arange(near_m, far_m + 1e-9, res / 2)
        return [(s, offset) for s, azimuth in enumerate(self.facing_azimuths_rad)
                for offset in sorted({(round(d * math.cos(azimuth) / res), round(d * math.sin(azimuth) / res))
                                      for d in steps})]

    def mass_near(self, position_m: np.ndarray, radius_m: float) -> float:
        """Probability that the target's centre lies within ``radius_m`` of ``position_m``."""
        lo = self.grid.index_of(np.asarray(position_m) - radius_m)
        hi = self.grid.index_of(np.asarray(position_m) + radius_m) + 1
        lo, hi = np.clip(lo, 0, self.grid.shape), np.clip(hi, 0, self.grid.shape)
        box = tuple(slice(a, b) for a, b in zip(lo, hi))
        inside = self.grid.squared_distances(position_m, box) <= radius_m**2
        return float(self._mass[box].sum(axis=-1, dtype=np.float64)[inside].sum()) * self._scale

    def _renormalise(self) -> None:
        """Stored masses × scale, divided by their total: a chunk at a time, as a float64 copy of the
        whole belief would be 8 bytes a (cube, facing), 430 MB in a 20 × 14 × 3 m room."""
        flat = self._mass.reshape(-1)
        outside = self._outside * self._scale
        total = _scaled_total(flat, self._scale, 0, len(flat)) + outside
        for lo in range(0, len(flat), _CHUNK):
            flat[lo:lo + _CHUNK] = flat[lo:lo + _CHUNK].astype(np.float64) * self._scale / total
        self._outside = outside / total
        self._scale = 1.0
        self._stored_total = float(self._mass.sum(dtype=np.float64)) + self._outside
        self._rebuild_coarse()

    def _rebuild_coarse(self) -> None:
        """The coarse copy summed afresh from the cubes, a few slabs of blocks at a time."""
        f, sectors = self.coarse_factor, self.facing_sectors
        nx, ny, nz = self.grid.shape
        cx, cy, cz = self.coarse_shape
        slabs = max(2, _CHUNK // (f ** 3 * cy * cz * sectors))
        for i in range(0, cx, slabs):
            n = min(slabs, cx - i)
            padded = np.zeros((n * f, cy * f, cz * f, sectors), np.float64)
            part = self._mass[i * f:(i + n) * f]
            padded[:len(part), :ny, :nz] = part
            self._coarse[i:i + n] = padded.reshape(n, f, cy, f, cz, f, sectors).sum(axis=(1, 3, 5))


_CHUNK = 1 << 20  # (cube, facing) values per float64 temporary: 8 MB
_FLOAT32_MAX = float(np.finfo(np.float32).max)


def _scaled_total(flat: np.ndarray, scale: float, lo: int, n: int) -> float:
    """Σ float64(flat[lo:lo + n]) × scale, summed as numpy sums one float64 array (pairwise, each
    half rounded down to a multiple of 8), so the same to the bit, but without the copy."""
    if n <= _CHUNK:
        return float((flat[lo:lo + n].astype(np.float64) * scale).sum())
    half = n // 2 - (n // 2) % 8
    return _scaled_total(flat, scale, lo, half) + _scaled_total(flat, scale, lo + half, n - half)


@numba.njit(cache=True)
def _scale_seen_mass(mass, coarse, cube_index, factor, shape, coarse_shape, factor_coarse):
    """m(c, k) *= factor(c, k) for the listed cubes, mirrored into the coarse blocks; returns the
    stored mass that left them, Σ m (1 - factor), and the stored mass they kept."""
    removed_total = kept_total = 0.0
    plane = shape[1] * shape[2]
    for n in range(cube_index.shape[0]):
        c = cube_index[n]
        i, j, k = c // plane, (c // shape[2]) % shape[1], c % shape[2]
        block = ((i // factor_coarse) * coarse_shape[1] + j // factor_coarse) * coarse_shape[2] + k // factor_coarse
        for s in range(mass.shape[1]):
            kept = np.float64(mass[c, s]) * np.float64(factor[n, s])
            removed = np.float64(mass[c, s]) - kept
            mass[c, s] = kept
            coarse[block, s] -= removed
            removed_total += removed
            kept_total += mass[c, s]  # as stored: a float32 that rounds to 0 keeps nothing
    return removed_total, kept_total

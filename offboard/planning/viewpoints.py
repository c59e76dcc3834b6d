"""Candidate camera positions: the report's floor-grid vertices, plus viewpoints aimed at the belief.

The report (§3.3.3) moves only between the vertices of a 1 m floor grid. A one-sided target on a
shelf may be visible only from between them, and a place is ruled out only once it has been seen
from every side its picture could face (§6.2). So each decision also proposes viewpoints where the
belief says something is left to look at: for the blocks and facings holding the most target
probability, the floor point straight in front of that facing at the detector's best distance.
Proposals are snapped to a lattice (so the expensive per-position geometry can be cached), voted
for by the mass they face, and kept more than one lattice step apart.
"""

from __future__ import annotations

import math

import numpy as np

from offboard.perception.detectability import DetectabilityTable


def grid_vertices(room_size_m: tuple[float, float, float], spacing_m: float) -> np.ndarray:
    """Interior vertices of the floor grid (report §3.3.3): 32 in a 9 × 5 m room at 1 m."""
    xs = np.arange(spacing_m, room_size_m[0] - 1e-9, spacing_m)
    ys = np.arange(spacing_m, room_size_m[1] - 1e-9, spacing_m)
    return np.array([(x, y) for x in xs for y in ys], float).reshape(-1, 2)  # (0, 2) in a room under 2 steps


def best_distance_m(table: DetectabilityTable, within: float = 0.05) -> float:
    """The detector's good range for a viewpoint: the middle of the distances at which it does
    within ``within`` of its best head-on (nearer sees less of the room, farther less reliably)."""
    head_on = table.rate[:, 0, 0]
    good = np.nonzero(head_on >= head_on.max() * (1.0 - within))[0]
    return float((table.distance_edges_m[good[0]] + table.distance_edges_m[good[-1] + 1]) / 2)


class AimedViewpoints:
    """Floor positions in front of where the most target probability is.

    Every block and facing votes, with its mass, for the lattice node ``distance_m`` from it
    (horizontally less, by the height difference to the camera) along the facing; nodes within
    ``margin_m`` of a wall get no votes. Where each vote goes depends only on the room, so it is
    worked out once; a decision only weighs the votes by the belief of the moment.
    """

    def __init__(self, block_centers_m: np.ndarray, facing_azimuths_rad: np.ndarray, distance_m: float,
                 head_height_m: float, room_size_m: tuple[float, float, float], margin_m: float, lattice_m: float):
        """``block_centers_m`` (B, 3); ``facing_azimuths_rad`` (F,), NaN for a target that faces the
        camera (then eight directions share its mass)."""
        directions, self._shares = _directions(facing_azimuths_rad)  # (F, D, 2), (F, D)
        rise = block_centers_m[:, 2] - head_height_m
        reach = np.sqrt(np.maximum(distance_m**2 - rise**2, (0.5 * distance_m) ** 2))  # (B,)
        points = block_centers_m[:, None, None, :2] + directions[None] * reach[:, None, None, None]  # (B, F, D, 2)
        nodes = np.round(points.reshape(-1, 2) / lattice_m).astype(np.int64)
        lo = np.ceil(margin_m / lattice_m)
        hi = np.floor((np.array(room_size_m[:2]) - margin_m) / lattice_m)
        self._shape = tuple(int(n) for n in hi.astype(np.int64) + 1)
        self._keep = np.all((nodes >= lo) & (nodes <= hi), axis=1)
        self._node = np.ravel_multi_index(nodes[self._keep].T, self._shape)
        self.lattice_m, self.margin_m = lattice_m, margin_m

    def propose(self, mass: np.ndarray, count: int) -> np.ndarray:
        """Up to ``count`` positions (k, 2), the most voted for first, more than one lattice step
        apart; ``mass`` (B, F): target probability per block and facing sector."""
        if count <= 0 or not mass.size or mass.max() <= 0:
            return np.zeros((0, 2))
        votes = (mass[:, :, None] * self._shares[None]).ravel()[self._keep]
        votes = np.where(votes > 0, votes, 0.0)  # a block's mass, kept incrementally, may drift just below 0
        totals = np.bincount(self._node, weights=votes, minlength=int(np.prod(self._shape)))
        return _strongest_apart(totals.reshape(self._shape), count) * self.lattice_m


def _directions(facing_azimuths_rad: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit floor directions per facing sector (F, D, 2) and each one's share of the sector's mass (F, D)."""
    facings = np.asarray(facing_azimuths_rad, float)
    if facings.size == 1 and np.isnan(facings[0]):
        az = np.arange(8) * (2 * math.pi / 8)
        dirs = np.stack([np.cos(az), np.sin(az)], axis=-1)[None]
        return dirs, np.full((1, 8), 1.0 / 8)
    dirs = np.stack([np.cos(facings), np.sin(facings)], axis=-1)[:, None, :]
    return dirs, np.ones((len(facings), 1))


def _strongest_apart(totals: np.ndarray, count: int) -> np.ndarray:
    """The ``count`` lattice nodes with the most votes, each more than one step from the others."""
    free = np.pad(totals > 0, 1)  # padded: a node's 3 × 3 neighbourhood is always in range
    chosen = []
    for flat in np.argsort(-totals, axis=None, kind="stable"):
        i, j = divmod(int(flat), totals.shape[1])
        if len(chosen) == count or totals[i, j] <= 0:
            break
        if free[i + 1, j + 1]:
            chosen.append((i, j))
            free[i:i + 3, j:j + 3] = False
    return np.array(chosen, float).reshape(-1, 2)

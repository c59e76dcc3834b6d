"""Exact, compact encoding of 4-byte arrays whose values mostly repeat (a checkpoint's belief and map).

A search's belief is 900,000 cubes × 8 facing sectors of float32 (29 MB at 5 cm), yet after a few
looks most values are still the prior's: a look that misses rescales only the cubes it saw, and
only in the facings it could have seen; the rest of each cube keeps its earlier value, which is
usually its neighbour's too. So each row (a cube's sectors) is coded against a reference value:

- the reference is the previous row's if it occurs in this row, else this row's most frequent value
  (one flag bit; a new reference is stored once);
- one bit per sector says whether it differs from the reference; those that differ are stored.

Values are compared as bit patterns, so the decoding is exact to the bit (−0.0, NaN included)
whatever the values are; only the size depends on how much repeats (the worst case is the raw
size plus one bit per value). An occupancy grid codes the same way with one value a row: its
unobserved zeros are runs of one reference.

The stored values are few distinct ones (a belief's change comes from a detectability table's
cells: a few thousand values among millions), so they are stored once, in a palette, and the stream
holds indices into it: 16-bit ones for at most 65,536 distinct values (half the size), else 24-bit
ones (three bytes each) for at most 2,097,152; beyond that, the values themselves.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

# (hash table bits, index dtype, most distinct values): the table has twice the slots, so probes stay short
PALETTES = ((17, np.uint16, 1 << 16), (22, np.uint32, 1 << 21))

@dataclass(frozen=True)
class Encoded:
    """An encoded array: ``flags`` (packed bits, row by row: new reference, then one per sector) and
    the ``values`` stream (uint32 bit patterns, or indices into ``palette``: uint16, or uint8 triplets
    little-endian), plus what the decoder needs to rebuild it."""

    shape: tuple[int, ...]
    dtype: str
    flags: np.ndarray  # uint8
    values: np.ndarray  # uint32; with a palette uint16, or uint8 (three per index)
    palette: np.ndarray | None = None  # uint32

    @property
    def nbytes(self) -> int:
        return self.flags.nbytes + self.values.nbytes + (0 if self.palette is None else self.palette.nbytes)


def encode(array: np.ndarray) -> Encoded:
    """Code a C-contiguous array of a 4-byte dtype; its last axis is a row (a 1-D array: rows of one)."""
    if array.dtype.itemsize != 4 or not array.flags.c_contiguous:
        raise ValueError(f"repeat_codec takes C-contiguous arrays of a 4-byte dtype, not {array.dtype}")
    width = array.shape[-1] if array.ndim > 1 else 1
    rows = array.view(np.uint32).reshape(-1, width)
    flags = np.zeros(-(-rows.shape[0] * (width + 1) // 8), np.uint8)
    values = np.empty(rows.size + rows.shape[0], np.uint32)
    count = _encode(rows, flags, values)
    for bits, index_dtype, most in PALETTES:
        codes, palette = np.empty(count, index_dtype), np.empty(most, np.uint32)
        distinct = _palette(values[:count], bits, codes, palette)
        index_bytes = 2 if index_dtype == np.uint16 else 3  # 2**21 indices fit in three bytes
        if distinct >= 0 and distinct * 4 + count * index_bytes < count * 4:  # the palette pays for itself
            if index_bytes == 3:
                codes = codes.view(np.uint8).reshape(-1, 4)[:, :3].reshape(-1)
            return Encoded(tuple(array.shape), array.dtype.str, flags, codes, palette[:distinct].copy())
    return Encoded(tuple(array.shape), array.dtype.str, flags, values[:count].copy())


def decode(encoded: Encoded) -> np.ndarray:
    """The array :func:`encode` was given, bit for bit; a ``ValueError`` if the code is damaged."""
    shape, dtype = encoded.shape, np.dtype(encoded.dtype)
    width = shape[-1] if len(shape) > 1 else 1
    n_rows = int(np.prod(shape, dtype=np.int64)) // width
    if dtype.itemsize != 4 or encoded.flags.size != -(-n_rows * (width + 1) // 8):
        raise ValueError(f"encoded array of shape {shape} and dtype {dtype}: flags of the wrong size")
    values = encoded.values if encoded.palette is None else _looked_up(encoded)
    rows = np.empty((n_rows, width), np.uint32)
    used = _decode(np.ascontiguousarray(encoded.flags, np.uint8), np.ascontiguousarray(values, np.uint32), rows)
    if used != values.size:
        raise ValueError(f"encoded array of shape {shape}: {values.size} values stored, {used} used")
    return rows.view(dtype).reshape(shape)


def _looked_up(encoded: Encoded) -> np.ndarray:
    """The values a palette's indices stand for."""
    codes = encoded.values
    if codes.dtype == np.uint8 and codes.size % 3 == 0:
        triplets = codes.reshape(-1, 3).astype(np.uint32)
        codes = triplets[:, 0] | triplets[:, 1] << 8 | triplets[:, 2] << 16
    elif codes.dtype != np.uint16:
        raise ValueError(f"palette indices must be uint16 or uint8 triplets, not {codes.dtype} × {codes.size}")
    if codes.size and int(codes.max()) >= encoded.palette.size:
        raise ValueError(f"encoded array of shape {encoded.shape}: indices beyond its palette of {encoded.palette.size}")
    return encoded.palette[codes]


@numba.njit(cache=True)
def _encode(rows, flags, values):
    width = rows.shape[1]
    bit = 0
    count = 0
    ref = np.uint32(0)
    for r in range(rows.shape[0]):
        row = rows[r]
        if r == 0 or not _occurs(row, ref):
            ref = _most_frequent(row)
            flags[bit >> 3] |= np.uint8(1 << (bit & 7))
            values[count] = ref
            count += 1
        bit += 1
        for s in range(width):
            if row[s] != ref:
                flags[bit >> 3] |= np.uint8(1 << (bit & 7))
                values[count] = row[s]
                count += 1
            bit += 1
    return count


@numba.njit(cache=True)
def _decode(flags, values, rows):
    width = rows.shape[1]
    bit = 0
    count = 0
    ref = np.uint32(0)
    for r in range(rows.shape[0]):
        if flags[bit >> 3] & (1 << (bit & 7)):
            if count >= values.size:
                raise ValueError("encoded array: too few values")
            ref = values[count]
            count += 1
        elif r == 0:
            raise ValueError("encoded array: the first row has no reference")
        bit += 1
        for s in range(width):
            if flags[bit >> 3] & (1 << (bit & 7)):
                if count >= values.size:
                    raise ValueError("encoded array: too few values")
                rows[r, s] = values[count]
                count += 1
            else:
                rows[r, s] = ref
            bit += 1
    return count


@numba.njit(cache=True)
def _palette(values, bits, codes, palette):
    """Fill ``codes`` with the indices of ``values`` into ``palette``, their distinct values in order
    of first appearance, by an open-addressing hash table of ``2**bits`` slots; return how many
    there are, or -1 if more than ``palette`` holds."""
    mask = np.uint64((1 << bits) - 1)
    keys = np.empty(1 << bits, np.uint32)
    slots = np.full(1 << bits, -1, np.int32)
    n = 0
    last_value, last_code = np.uint32(0), -1
    for i in range(values.size):
        v = values[i]
        if last_code >= 0 and v == last_value:  # runs are common: skip the table
            codes[i] = last_code
            continue
        h = ((np.uint64(v) * np.uint64(2654435761)) >> np.uint64(32 - bits)) & mask  # Knuth's multiplicative hash
        while slots[h] != -1 and keys[h] != v:
            h = (h + np.uint64(1)) & mask
        if slots[h] == -1:
            if n == palette.size:
                return -1
            keys[h], slots[h], palette[n] = v, n, v
            n += 1
        codes[i] = slots[h]
        last_value, last_code = v, slots[h]
    return n


@numba.njit(cache=True, inline="always")
def _occurs(row, value):
    for s in range(row.shape[0]):
        if row[s] == value:
            return True
    return False


@numba.njit(cache=True)
def _most_frequent(row):
    """The row's most frequent value; the earliest among equals."""
    best, best_count = row[0], 0
    for s in range(row.shape[0]):
        count = 0
        for t in range(row.shape[0]):
            count += row[t] == row[s]
        if count > best_count:
            best, best_count = row[s], count
    return best

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
cells: a few thousand values among millions), so when there are at most 65,536 of them they are
stored once, in a palette, and the stream holds 16-bit indices into it: half the size.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

PALETTE_HASH_BITS = 17  # the palette's hash table: 131,072 slots for at most 65,536 values

@dataclass(frozen=True)
class Encoded:
    """An encoded array: ``flags`` (packed bits, row by row: new reference, then one per sector) and
    the ``values`` stream (uint32 bit patterns, or uint16 indices into ``palette``), plus what the
    decoder needs to rebuild it."""

    shape: tuple[int, ...]
    dtype: str
    flags: np.ndarray  # uint8
    values: np.ndarray  # uint32, or uint16 with a palette
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
    codes, palette, distinct = _palette(values[:count], PALETTE_HASH_BITS)
    if distinct < 0:
        return Encoded(tuple(array.shape), array.dtype.str, flags, values[:count].copy())
    return Encoded(tuple(array.shape), array.dtype.str, flags, codes, palette[:distinct].copy())


def decode(encoded: Encoded) -> np.ndarray:
    """The array :func:`encode` was given, bit for bit; a ``ValueError`` if the code is damaged."""
    shape, dtype = encoded.shape, np.dtype(encoded.dtype)
    width = shape[-1] if len(shape) > 1 else 1
    n_rows = int(np.prod(shape, dtype=np.int64)) // width
    if dtype.itemsize != 4 or encoded.flags.size != -(-n_rows * (width + 1) // 8):
        raise ValueError(f"encoded array of shape {shape} and dtype {dtype}: flags of the wrong size")
    values = encoded.values
    if encoded.palette is not None:
        if values.dtype != np.uint16 or (values.size and int(values.max()) >= encoded.palette.size):
            raise ValueError(f"encoded array of shape {shape}: indices beyond its palette of {encoded.palette.size}")
        values = encoded.palette[values]
    rows = np.empty((n_rows, width), np.uint32)
    used = _decode(np.ascontiguousarray(encoded.flags, np.uint8), np.ascontiguousarray(values, np.uint32), rows)
    if used != encoded.values.size:
        raise ValueError(f"encoded array of shape {shape}: {encoded.values.size} values stored, {used} used")
    return rows.view(dtype).reshape(shape)


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
def _palette(values, bits):
    """uint16 indices of ``values`` into their distinct values (in order of first appearance), by
    an open-addressing hash table; the count is -1 if there are more than 65,536."""
    mask = np.uint64((1 << bits) - 1)
    keys = np.empty(1 << bits, np.uint32)
    slots = np.full(1 << bits, -1, np.int32)
    codes = np.empty(values.size, np.uint16)
    palette = np.empty(65536, np.uint32)
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
            if n == 65536:
                return codes, palette, -1
            keys[h], slots[h], palette[n] = v, n, v
            n += 1
        codes[i] = slots[h]
        last_value, last_code = v, slots[h]
    return codes, palette, n


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

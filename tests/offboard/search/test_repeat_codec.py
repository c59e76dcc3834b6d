"""The repeat codec: exact to the bit for any 4-byte array, small when values repeat."""

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from offboard.search import repeat_codec


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10_000), rows=st.integers(1, 300), width=st.sampled_from([1, 3, 8]),
       kinds=st.integers(1, 6), dtype=st.sampled_from([np.float32, np.int32, np.uint32]))
def test_any_array_decodes_to_the_same_bits(seed, rows, width, kinds, dtype):
    rng = np.random.default_rng(seed)
    palette = rng.integers(0, 2**32, kinds, dtype=np.uint64).astype(np.uint32)
    palette[0] = 0x80000000  # -0.0 as a float
    if kinds > 1:
        palette[1] = 0x7FC00001  # a NaN with a payload
    array = palette[rng.integers(0, kinds, (rows, width))].view(dtype)
    array = array[:, 0].copy() if width == 1 else array
    back = repeat_codec.decode(repeat_codec.encode(array))
    assert back.dtype == array.dtype and back.shape == array.shape
    assert np.array_equal(back.view(np.uint32), array.view(np.uint32))


def test_repeated_values_cost_about_a_bit_each():
    mass = np.full((10_000, 8), 0.25, np.float32)
    mass[::10, 2] *= np.float32(0.5)  # a tenth of the cubes seen from one facing
    encoded = repeat_codec.encode(mass)
    assert encoded.nbytes < 10_000 * 9 / 8 + 1_000 * 4 + 16
    assert np.array_equal(repeat_codec.decode(encoded), mass)


def test_the_palette_takes_two_bytes_an_index_then_three_then_none():
    rng = np.random.default_rng(0)
    few = rng.choice(np.float32([0.1, 0.2, 0.3]), (5_000, 8))
    more = rng.integers(0, 100_000, (125_000, 8)).astype(np.float32)  # ~100,000 distinct
    most = rng.permutation(np.arange(2_400_000, dtype=np.uint32)).reshape(-1, 8).view(np.float32)
    coded = [repeat_codec.encode(a) for a in (few, more, most)]
    assert [None if c.palette is None else c.values.dtype for c in coded] == [np.uint16, np.uint8, None]
    assert coded[1].palette.size > 65_536 and coded[1].nbytes < 0.9 * more.nbytes  # 3 bytes a value, not 4
    for array, code in zip((few, more, most), coded):
        assert np.array_equal(repeat_codec.decode(code).view(np.uint32), array.view(np.uint32))


def test_damaged_codes_and_unsupported_arrays_are_refused():
    encoded = repeat_codec.encode(np.tile(np.arange(10, dtype=np.float32), 10))  # 100 values stored, 10 distinct
    assert encoded.palette is not None
    with pytest.raises(ValueError, match="too few values"):
        repeat_codec.decode(dataclasses.replace(encoded, values=encoded.values[:-1]))
    with pytest.raises(ValueError, match="101 values stored, 100 used"):
        repeat_codec.decode(dataclasses.replace(encoded, values=np.append(encoded.values, np.uint16(7))))
    with pytest.raises(ValueError, match="beyond its palette"):
        repeat_codec.decode(dataclasses.replace(encoded, palette=encoded.palette[:5]))
    with pytest.raises(ValueError, match="flags of the wrong size"):
        repeat_codec.decode(dataclasses.replace(encoded, flags=encoded.flags[:-1]))
    with pytest.raises(ValueError, match="4-byte"):
        repeat_codec.encode(np.zeros(4, np.float64))

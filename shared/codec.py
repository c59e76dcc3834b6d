"""msgpack encoding of the messages in :mod:`shared.messages`, with strict decoding.

A payload is a map ``{"schema": SCHEMA_VERSION, "type": "<class name>", "body": {...}}``. Arrays
travel as ``{"dtype", "shape", "encoding": "raw" | "png", "data": <bytes>}``, never as lists.
Whatever is wrong with a payload, :func:`decode` raises one :class:`ProtocolError` naming the field
and the value, so a malformed message can be answered instead of crashing the process.
"""

from __future__ import annotations

import math
from typing import Any, Literal, TypeVar

import cv2
import msgpack
import numpy as np

from shared.messages import MESSAGE_TYPES, SCHEMA_VERSION
from shared.strict import StructureError, build, check, to_plain

T = TypeVar("T")
ArrayEncoding = Literal["raw", "png"]

_DTYPES = {"uint8", "uint16", "int16", "int32", "float32", "float64"}
_PNG_DTYPES = {"uint8", "uint16"}
MAX_PAYLOAD_BYTES = 64 * 1024 * 1024


class ProtocolError(StructureError):
    """A payload that is not a valid message; ``field`` names what was wrong."""


def encode(message: Any, arrays: ArrayEncoding = "raw") -> bytes:
    """Serialise a message dataclass; ``arrays`` chooses how its image arrays travel. What :func:`decode`
    would refuse on the other side (a wrong type, an option not offered, a number out of range or not
    finite) raises :class:`~shared.strict.StructureError` here, naming the field."""
    name = type(message).__name__
    if MESSAGE_TYPES.get(name) is not type(message):
        raise TypeError(f"{name} is not a message type of shared.messages")
    check(message)
    body = to_plain(message, lambda a: _encode_array(a, arrays))
    return msgpack.packb({"schema": SCHEMA_VERSION, "type": name, "body": body}, use_bin_type=True)


def decode(payload: bytes, *expected: type[T]) -> T:
    """Parse and check a payload; it must be one of the ``expected`` message types."""
    if len(payload) > MAX_PAYLOAD_BYTES:
        raise ProtocolError("", f"{len(payload)} bytes", f"payload larger than {MAX_PAYLOAD_BYTES} bytes")
    try:
        envelope = msgpack.unpackb(payload, raw=False, strict_map_key=True)
    except Exception as exc:  # msgpack raises several unrelated types for garbage
        raise ProtocolError("", payload[:16], f"not a msgpack payload ({exc.__class__.__name__})") from None
    if not isinstance(envelope, dict) or set(envelope) != {"schema", "type", "body"}:
        raise ProtocolError("", envelope, "expected a map with exactly schema, type and body")
    if type(envelope["schema"]) is not int or envelope["schema"] != SCHEMA_VERSION:  # not True, not 1.0
        raise ProtocolError("schema", envelope["schema"], f"unsupported schema version (this side speaks {SCHEMA_VERSION})")
    cls = MESSAGE_TYPES.get(envelope["type"]) if isinstance(envelope["type"], str) else None
    if cls is None or (expected and cls not in expected):
        wanted = ", ".join(t.__name__ for t in expected) or "a known message type"
        raise ProtocolError("type", envelope["type"], f"expected {wanted}")
    return build(cls, envelope["body"], ProtocolError, "", _decode_array)


def _encode_array(array: np.ndarray, encoding: ArrayEncoding) -> dict[str, Any]:
    array = np.ascontiguousarray(array)
    if str(array.dtype) not in _DTYPES:
        raise TypeError(f"arrays of dtype {array.dtype} cannot travel")
    # PNG holds 1, 3 or 4 channels of a non-empty image, and gives one channel back as 2-D: else raw
    if (encoding == "png" and str(array.dtype) in _PNG_DTYPES and array.size
            and (array.ndim == 2 or (array.ndim == 3 and array.shape[2] in (3, 4)))):
        ok, buf = cv2.imencode(".png", array, [cv2.IMWRITE_PNG_COMPRESSION, 1])
        if not ok:
            raise ValueError("PNG encoding failed")
        data = buf.tobytes()
    else:
        encoding, data = "raw", array.tobytes()
    return {"dtype": str(array.dtype), "shape": list(array.shape), "encoding": encoding, "data": data}


def _png_size(data: bytes) -> tuple[int, int] | None:
    """(width, height) from a PNG's IHDR chunk; None if ``data`` does not start like a PNG."""
    if len(data) < 24 or data[:8] != b"\x89PNG\r\n\x1a\n" or data[12:16] != b"IHDR":
        return None
    return int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big")


def _decode_array(value: Any, where: str) -> np.ndarray:
    if not isinstance(value, dict) or set(value) != {"dtype", "shape", "encoding", "data"}:
        raise ProtocolError(where, value, "expected an array header with dtype, shape, encoding, data")
    dtype, shape, encoding, data = value["dtype"], value["shape"], value["encoding"], value["data"]
    if not isinstance(dtype, str) or dtype not in _DTYPES:  # a list or map is unhashable: check the type first
        raise ProtocolError(f"{where}.dtype", dtype, f"must be one of {sorted(_DTYPES)}")
    if (not isinstance(shape, list) or not 1 <= len(shape) <= 4
            or not all(isinstance(n, int) and not isinstance(n, bool) and 0 <= n <= 100_000 for n in shape)):
        raise ProtocolError(f"{where}.shape", shape, "must be 1 to 4 sizes between 0 and 100000")
    if not isinstance(data, bytes):
        raise ProtocolError(f"{where}.data", type(data).__name__, "must be bytes")
    if encoding == "raw":
        expected = math.prod(shape) * np.dtype(dtype).itemsize  # Python ints: np.prod wraps around
        if len(data) != expected:
            raise ProtocolError(f"{where}.data", f"{len(data)} bytes", f"shape {shape} of {dtype} needs {expected} bytes")
        return np.frombuffer(data, dtype=dtype).reshape(shape)
    if encoding == "png":
        size = _png_size(data)  # checked before decoding: a small PNG declaring a huge image would be allocated
        if size is not None and size != (shape[1] if len(shape) > 1 else 1, shape[0]):
            raise ProtocolError(f"{where}.data", f"PNG of {size} (width, height)", f"must match shape {shape}")
        try:
            array = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        except cv2.error:  # raised for some garbage (an empty buffer) instead of returning None
            array = None
        if array is None or list(array.shape) != shape or str(array.dtype) != dtype:
            got = None if array is None else f"{array.dtype} {list(array.shape)}"
            raise ProtocolError(f"{where}.data", got, f"PNG does not decode to {dtype} {shape}")
        return array
    raise ProtocolError(f"{where}.encoding", encoding, "must be 'raw' or 'png'")

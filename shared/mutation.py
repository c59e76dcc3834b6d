"""Hypothesis strategies that break valid plain data in one known place.

The fuzzer starts from valid inputs (encoded messages, bundled worlds, deploy configs) and breaks
one thing per case, so it knows which field the decoder's error must name:

- a value of the wrong type (a string for a number, a list for a table, a date in TOML...);
- NaN, infinities and integers too large for a float;
- a number just or far outside a field's declared range;
- a required key removed, an unknown key added;
- another value of the right type (may be valid: such cases need not be refused);
- huge strings and lists.

Where the data comes from a dataclass (messages, configs) its fields give the types, ranges and
which keys are required; otherwise (worlds) the valid value's own type does. :func:`plain_cases`
yields ``(data, Case fields)``; the targets then encode the data (msgpack or TOML) and may damage
the bytes further (:func:`wire_damage`, :func:`toml_damage`).
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import math
import types
import typing
from dataclasses import dataclass
from typing import Any, Literal, Union

import msgpack
import numpy as np
from hypothesis import strategies as st

HUGE_INT = 10**400  # TOML integers are unbounded: no float holds this
_UNKNOWN_KEY = "surplus_key"


@dataclass(frozen=True)
class Slot:
    """One place in the data that a case may break."""

    path: str  # as decoders name it: "pose.x_m", "obstacle[0].min", "waypoint_m[1]"
    route: tuple[str | int, ...]  # keys and indices from the root
    kind: str  # number | integer | bool | string | literal | vector | table | tables | array
    required: bool = False  # removing the key must be refused (known only from a dataclass)
    nullable: bool = False  # null is a valid value (an Optional field)
    bounds: tuple[float | None, float | None] | None = None
    options: tuple[Any, ...] = ()  # a Literal's values
    length: int | None = None  # a fixed-length tuple's length


# --- where the data can be broken -------------------------------------------------------------------

def slots(data: dict[str, Any], cls: type | None = None) -> list[Slot]:
    """Every place in ``data``: its keys (with ``cls``'s field types if given), nested all the way."""
    found = [Slot("", (), "table")]
    _table_slots(data, cls, "", (), found)
    return found


def _join(path: str, name: str) -> str:
    return f"{path}.{name}" if path else name


def _table_slots(data: dict[str, Any], cls: type | None, path: str, route: tuple, found: list[Slot]) -> None:
    fields = {f.name: f for f in dataclasses.fields(cls)} if cls is not None else {}
    hints = typing.get_type_hints(cls) if cls is not None else {}
    for name, value in data.items():
        f = fields.get(name)
        if f is None:
            _value_slots(value, None, _join(path, name), (*route, name), found, required=False)
            continue
        required = f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
        _value_slots(value, hints[name], _join(path, name), (*route, name), found, required,
                     f.metadata.get("bounds"))


def _value_slots(value: Any, hint: Any, path: str, route: tuple, found: list[Slot], required: bool,
                 bounds: tuple | None = None) -> None:
    nullable = False
    if typing.get_origin(hint) in (Union, types.UnionType):
        nullable = type(None) in typing.get_args(hint)
        (hint,) = [a for a in typing.get_args(hint) if a is not type(None)]
    kind, options, length = _kind(value, hint)
    found.append(Slot(path, route, kind, required, nullable, bounds, options, length))
    if kind == "table" and isinstance(value, dict):
        _table_slots(value, hint if dataclasses.is_dataclass(hint) else None, path, route, found)
    elif kind in ("vector", "tables") and isinstance(value, list):
        args = typing.get_args(hint)
        for i, item in enumerate(value):
            inner = args[0] if len(args) == 2 and args[1] is Ellipsis else (args[i] if i < len(args) else None)
            _value_slots(item, inner, f"{path}[{i}]", (*route, i), found, required=False)


def _kind(value: Any, hint: Any) -> tuple[str, tuple, int | None]:
    if hint is None:  # no schema: the valid value's own type
        hint = {bool: bool, str: str, int: float, float: float}.get(type(value))
        if isinstance(value, dict):
            return "table", (), None
        if isinstance(value, list):
            return ("tables" if value and all(isinstance(v, dict) for v in value) else "vector"), (), None
    if typing.get_origin(hint) is Literal:
        return "literal", typing.get_args(hint), None
    if typing.get_origin(hint) is tuple:
        args = typing.get_args(hint)
        if len(args) == 2 and args[1] is Ellipsis:
            return ("tables" if dataclasses.is_dataclass(args[0]) else "vector"), (), None
        return "vector", (), len(args)
    if dataclasses.is_dataclass(hint):
        return "table", (), None
    if hint is np.ndarray:
        return "array", (), None
    return {bool: "bool", str: "string", int: "integer", float: "number"}.get(hint, "any"), (), None


# --- how to break it --------------------------------------------------------------------------------

def _wrong_values(kind: str, wire: bool) -> list[Any]:
    """Values of a type no field of ``kind`` accepts (null is added for non-nullable fields)."""
    pools = {
        "number": ["3.5", True, [1.0], {"x_m": 1.0}],
        "integer": [1.5, "3", True, [1], {"n": 1}],
        "bool": [0, 1, "true", [True]],
        "string": [3, 1.5, True, ["text"], {"name": "x"}],
        "literal": [1, True, ["raw"], "no-such-option", ""],
        "vector": ["1, 2, 3", 3, {"x": 1.0}, [[1.0, 2.0]], ["1", "2", "3"]],
        "table": [1, "table", [1, 2], True],
        "tables": ["tables", 1, [1, 2], {"min": [0, 0, 0]}],
        "array": [[1, 2, 3], "pixels", 0],
    }
    extra = [b"\x00bytes", msgpack.ExtType(7, b"ext")] if wire else [dt.date(2024, 2, 29)]
    return pools.get(kind, []) + extra


def _out_of_range(slot: Slot, wire: bool) -> st.SearchStrategy[Any]:
    lo, hi = slot.bounds
    if slot.kind == "integer":
        smallest, largest = -(2**63), (2**64 - 1 if wire else HUGE_INT)  # what msgpack or TOML can carry
        sides = ([st.integers(smallest, int(lo) - 1)] if lo is not None else []) + \
                ([st.integers(int(hi) + 1, largest)] if hi is not None else [])
        return st.one_of(*sides)
    ends = [(end, sign) for end, sign in ((lo, -1.0), (hi, 1.0)) if end is not None]
    steps = st.sampled_from([1e-6, 1e-3, 0.5, 1.0, 1e3, 1e9, 1e300])
    return st.tuples(st.sampled_from(ends), steps).map(
        lambda e: e[0][0] + e[0][1] * e[1] * max(1.0, abs(e[0][0]))).filter(
        lambda v: math.isfinite(v) and ((lo is not None and v < lo) or (hi is not None and v > hi)))


def _same_type(kind: str) -> st.SearchStrategy[Any]:
    numbers = st.floats(allow_nan=False, allow_infinity=False) | st.integers(-(2**63), 2**63 - 1)
    return {
        "number": numbers,
        "integer": st.integers(-(2**63), 2**63 - 1),
        "bool": st.booleans(),
        "string": st.text(max_size=40) | st.sampled_from(["", "x" * 10_000]),
        "vector": st.lists(numbers, max_size=6) | st.just([0.5] * 10_000),
    }.get(kind, st.nothing())


def plain_cases(valid: list[dict[str, Any]], cls: type | None = None, *,
                wire: bool) -> st.SearchStrategy[tuple[dict[str, Any], dict[str, Any]]]:
    """A copy of one of ``valid`` broken in one place, and the :class:`Case` fields saying where.

    ``wire``: msgpack can carry null, bytes and extension types but no integer beyond 64 bits;
    TOML the reverse (and dates). Every strategy is built here, once: building them per case
    would cost more than running the case.
    """
    choices = [(example, slot, move) for example in valid for slot in slots(example, cls)
               for move in _moves(slot, wire)]
    pick = st.integers(0, len(choices) - 1)

    @st.composite
    def cases(draw: st.DrawFn) -> tuple[dict[str, Any], dict[str, Any]]:
        example, slot, move = choices[draw(pick)]
        how, value, exact, must_refuse = draw(move)
        data = _copy(example)
        if how == "unknown key":
            _at(data, slot.route)[_UNKNOWN_KEY] = value
            return data, {"field": _join(slot.path, _UNKNOWN_KEY), "how": how, "exact": True, "must_refuse": True}
        if how == "key removed":
            del _at(data, slot.route[:-1])[slot.route[-1]]
        else:
            _at(data, slot.route[:-1])[slot.route[-1]] = value
        return data, {"field": slot.path, "how": f"{how} at {slot.path}", "exact": exact, "must_refuse": must_refuse}
    return cases()


def _moves(slot: Slot, wire: bool) -> list[st.SearchStrategy[tuple[str, Any, bool, bool]]]:
    """Strategies of ``(how, new value, exact, must_refuse)`` that apply to ``slot``."""
    def move(how: str, values: st.SearchStrategy[Any], exact: bool = True, refuse: bool = True):
        return values.map(lambda v: (how, v, exact, refuse))

    if slot.kind == "table":
        moves = [move("unknown key", st.integers(-(2**63), 2**63 - 1) if wire else st.text(max_size=5))]
        if not slot.route:
            return moves
    else:
        moves = []
    if slot.kind != "any":
        wrong = [v for v in _wrong_values(slot.kind, wire) + ([None] if wire and not slot.nullable else [])
                 if isinstance(v, bool) or v not in slot.options]  # a Literal may take 1 or ""
        wrong += [float(o) for o in slot.options if type(o) is int]  # 3.0 equals 3 but is no integer
        moves.append(move("wrong type", st.sampled_from(wrong)))
    if isinstance(slot.route[-1], str):  # a key, not a list item
        moves.append(move("key removed", st.none(), exact=slot.required, refuse=slot.required))
    if slot.kind == "number":
        moves.append(move("not finite", st.sampled_from([math.nan, math.inf, -math.inf])))
        if not wire:
            moves.append(move("integer beyond a float", st.sampled_from([HUGE_INT, -HUGE_INT])))
    if slot.bounds is not None and slot.kind in ("number", "integer"):
        moves.append(move("out of range", _out_of_range(slot, wire)))
    if slot.kind == "vector" and slot.length is not None:
        moves.append(move("wrong length", st.lists(st.floats(0, 1), max_size=8).filter(
            lambda v: len(v) != slot.length) | st.just([0.5] * 10_000)))
    if slot.kind == "array":
        moves.append(move("bad array header", array_headers()))
    if slot.kind in ("number", "integer", "bool", "string", "vector"):
        moves.append(move("other value", _same_type(slot.kind), exact=False, refuse=False))
    return moves


def array_headers() -> st.SearchStrategy[Any]:
    """Array headers (``shared.codec``) that are wrong in one way or many."""
    good = {"dtype": "uint8", "shape": [2, 2, 3], "encoding": "raw", "data": bytes(12)}
    broken = st.sampled_from([
        {**good, "dtype": "float16"}, {**good, "dtype": "object"}, {**good, "dtype": 1},
        {**good, "shape": [-1, 2, 3]}, {**good, "shape": [65536] * 4, "data": b""},
        {**good, "shape": [2**40]}, {**good, "shape": [1] * 5}, {**good, "shape": []}, {**good, "shape": "2x2"},
        {**good, "shape": [2.0, 2, 3]}, {**good, "shape": [True, 2, 3]}, {**good, "data": "pixels"},
        {**good, "data": bytes(11)}, {**good, "encoding": "jpeg"}, {**good, "encoding": "png"},
        {**good, "encoding": "png", "data": b"\x89PNG\r\n\x1a\n" + bytes(40)},
        {**good, "dtype": "float32", "shape": [2, 2, 3], "data": bytes(48)}, {**good, "shape": [4, 3]},
        {k: v for k, v in good.items() if k != "data"}, {**good, "extra": 1},
    ])
    return broken | st.fixed_dictionaries({"dtype": st.sampled_from(["uint8", "int16", "float64"]),
                                           "shape": st.lists(st.integers(0, 70_000), max_size=5),
                                           "encoding": st.sampled_from(["raw", "png"]),
                                           "data": st.binary(max_size=64)})


def _copy(data: Any) -> Any:
    if isinstance(data, dict):
        return {k: _copy(v) for k, v in data.items()}
    if isinstance(data, list):
        return [_copy(v) for v in data]
    return data


def _at(data: Any, route: tuple) -> Any:
    for step in route:
        data = data[step]
    return data


# --- damage to the encoded bytes --------------------------------------------------------------------

@st.composite
def wire_damage(draw: st.DrawFn, payload: bytes) -> tuple[bytes, str, bool]:
    """``(bytes, how, must_refuse)``: ``payload`` cut, extended, flipped, or replaced by hostile msgpack."""
    how = draw(st.sampled_from(["truncated", "trailing bytes", "bytes flipped", "random bytes",
                                "deep nesting", "huge length header"]))
    if how == "truncated":
        return payload[:draw(st.integers(0, len(payload) - 1))], how, True
    if how == "trailing bytes":
        return payload + draw(st.binary(min_size=1, max_size=16)), how, True
    if how == "bytes flipped":
        damaged = bytearray(payload)
        for i in draw(st.lists(st.integers(0, len(payload) - 1), min_size=1, max_size=4)):
            damaged[i] ^= 1 << draw(st.integers(0, 7))
        return bytes(damaged), how, False
    if how == "random bytes":
        return draw(st.binary(max_size=200)), how, False
    if how == "deep nesting":  # msgpack unpacks up to 1023 levels: near its edge, deeper than repr() can go
        depth = draw(st.sampled_from([1000, 1023, 1024]) | st.integers(100, 100_000))
        return b"\x91" * depth + b"\xc0", how, True
    header = draw(st.sampled_from([b"\xdf", b"\xdd", b"\xdb", b"\xc6", b"\xc9\x01"]))
    return header + b"\xff\xff\xff\xff" + draw(st.binary(max_size=16)), how, True


@st.composite
def toml_damage(draw: st.DrawFn, text: str) -> tuple[bytes, str, bool]:
    """``(bytes, how, must_refuse)``: TOML text cut, spliced, or made unreadable."""
    lines = text.splitlines(keepends=True) or [""]
    how = draw(st.sampled_from(["truncated", "text inserted", "line repeated", "line removed",
                                "invalid UTF-8", "NUL byte", "deep nesting", "5000-digit integer"]))
    at = draw(st.integers(0, len(text)))
    line = draw(st.integers(0, len(lines) - 1))
    if how == "truncated":
        return text[:at].encode(), how, False
    if how == "text inserted":
        return (text[:at] + draw(st.text(min_size=1, max_size=20)) + text[at:]).encode(), how, False
    if how == "line repeated":
        return "".join(lines[:line + 1] + lines[line:]).encode(), how, False
    if how == "line removed":
        return "".join(lines[:line] + lines[line + 1:]).encode(), how, False
    if how == "invalid UTF-8":
        return text[:at].encode() + b"\xff\xfe" + text[at:].encode(), how, True
    if how == "NUL byte":
        return text[:at].encode() + b"\x00" + text[at:].encode(), how, True
    if how == "5000-digit integer":  # beyond what Python converts from text
        return ("huge_integer = 1" + "0" * 5000 + "\n" + text).encode(), how, True
    depth = draw(st.integers(100, 50_000))
    return (f"deeply_nested = {'[' * depth}{']' * depth}\n" + text).encode(), how, True

"""Strict conversion of plain data (decoded msgpack, parsed TOML) into typed frozen dataclasses.

One checker serves both the wire messages and the configuration files, so the two reject bad input
the same way: unknown or missing fields, wrong types, NaN or infinite numbers and values outside a
field's declared range all raise the caller's error class with the dotted path of the field and the
offending value.

A field declares its range with ``field(metadata=bounds(lo, hi))``; either end may be ``None``.
"""

from __future__ import annotations

import dataclasses
import math
import reprlib
import types
import typing
from functools import cache
from typing import Any, Literal, Union

import numpy as np


class _Shown(reprlib.Repr):
    """A value shown a few levels deep: plain repr recurses, so a payload of ~1000 nested arrays (which
    msgpack still unpacks) raised RecursionError while its own error was being written. Bytes are cut
    before they are shown: reprlib would repr all of them first (four times a 100 MB payload's size)."""

    def repr_bytes(self, value: bytes, level: int) -> str:
        head = repr(value[:self.maxstring])
        return head if len(value) <= self.maxstring else f"{len(value)} bytes: {head}..."  # the length first


_SHOWN = _Shown()
_SHOWN.maxlevel, _SHOWN.maxstring, _SHOWN.maxother, _SHOWN.maxlong = 3, 80, 80, 80


class StructureError(ValueError):
    """Plain data that does not fit a dataclass; ``field`` is the dotted path, ``value`` what was there."""

    def __init__(self, field: str, value: Any, problem: str):
        self.field = field
        self.value = value
        self.problem = problem
        shown = _SHOWN.repr(value)
        if len(shown) > 80:
            shown = shown[:77] + "..."
        super().__init__(f"{field or '<message>'}: {problem} (got {shown})")


def bounds(lo: float | None = None, hi: float | None = None) -> dict[str, Any]:
    """Field metadata declaring an inclusive numeric range."""
    return {"bounds": (lo, hi)}


@cache
def _hints(cls: type) -> dict[str, Any]:
    return typing.get_type_hints(cls)


ArrayDecoder = typing.Callable[[Any, str], np.ndarray]


def build(cls: type, data: Any, error: type[StructureError] = StructureError, path: str = "",
          array_decoder: ArrayDecoder | None = None) -> Any:
    """Build dataclass ``cls`` from a mapping, checking every field; raise ``error`` on the first problem."""
    if not isinstance(data, dict):
        raise error(path, data, f"expected a table of {cls.__name__} fields")
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(data) - set(fields), key=str)
    if unknown:
        raise error(_join(path, str(unknown[0])), data[unknown[0]], f"unknown field for {cls.__name__}")
    values = {}
    for name, f in fields.items():
        where = _join(path, name)
        if name not in data:
            if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING:
                raise error(where, None, "missing required field")
            continue
        value = _convert(_hints(cls)[name], data[name], where, error, array_decoder)
        _check_bounds(f, value, where, error)
        values[name] = value
    try:
        return cls(**values)
    except (ValueError, TypeError) as exc:  # a dataclass's own __post_init__ check
        if isinstance(exc, StructureError):
            raise
        raise error(path, data, str(exc)) from None


def check(obj: Any, error: type[StructureError] = StructureError) -> None:
    """Check a dataclass built in code, not by :func:`build`, as :func:`build` checks plain data (types,
    options, ranges, finiteness, the class's own checks), on the plain values it would travel as
    (:func:`to_plain`: a numpy scalar as the number it is); arrays pass as they are. For the side
    that sends: a message out of range fails where it is made, naming the field."""
    build(type(obj), to_plain(obj, _as_is), error, "", lambda value, where: value)


def _as_is(array: np.ndarray) -> np.ndarray:
    return array


def _join(path: str, name: str) -> str:
    return f"{path}.{name}" if path else name


def _check_bounds(f: dataclasses.Field, value: Any, where: str, error: type[StructureError]) -> None:
    lo, hi = f.metadata.get("bounds", (None, None))
    if value is None or isinstance(value, bool) or not isinstance(value, (int, float)):
        return
    if (lo is not None and value < lo) or (hi is not None and value > hi):
        raise error(where, value, f"out of range [{lo if lo is not None else '-inf'}, "
                                  f"{hi if hi is not None else 'inf'}]")


def _convert(tp: Any, value: Any, where: str, error: type[StructureError],
             array_decoder: ArrayDecoder | None) -> Any:
    origin = typing.get_origin(tp)
    if origin in (Union, types.UnionType):
        options = typing.get_args(tp)
        if value is None:
            if type(None) in options:
                return None
            raise error(where, value, "must not be null")
        (inner,) = [o for o in options if o is not type(None)]
        return _convert(inner, value, where, error, array_decoder)
    if origin is Literal:  # by type too: 3.0 and True equal 3 and 1 but are no such option
        if not any(value == o and type(value) is type(o) for o in typing.get_args(tp)):
            raise error(where, value, f"must be one of {list(typing.get_args(tp))}")
        return value
    if origin is tuple:
        return _convert_tuple(tp, value, where, error, array_decoder)
    if dataclasses.is_dataclass(tp):
        return build(tp, value, error, where, array_decoder)
    if tp is np.ndarray:
        if array_decoder is None:
            raise error(where, value, "arrays are not accepted here")
        return array_decoder(value, where)
    return _convert_scalar(tp, value, where, error)


def _convert_tuple(tp: Any, value: Any, where: str, error: type[StructureError],
                   array_decoder: ArrayDecoder | None) -> tuple:
    if not isinstance(value, (list, tuple)):
        raise error(where, value, "expected a list")
    args = typing.get_args(tp)
    if len(args) == 2 and args[1] is Ellipsis:
        kinds = [args[0]] * len(value)
    else:
        if len(value) != len(args):
            raise error(where, value, f"expected {len(args)} items")
        kinds = list(args)
    return tuple(_convert(k, v, f"{where}[{i}]", error, array_decoder)
                 for i, (k, v) in enumerate(zip(kinds, value)))


def finite_float(value: Any) -> float:
    """``value`` as a float if it is a finite number, not a bool or a string that ``float`` would
    take; else ValueError saying which of those it failed."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError("must be a number")
    try:
        number = float(value)
    except OverflowError:  # a TOML integer has no size limit
        raise ValueError("too large for a number") from None
    if not math.isfinite(number):
        raise ValueError("must be finite")
    return number


def _convert_scalar(tp: Any, value: Any, where: str, error: type[StructureError]) -> Any:
    if tp is float:
        try:
            return finite_float(value)
        except ValueError as exc:
            raise error(where, value, str(exc)) from None
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise error(where, value, "expected an integer")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise error(where, value, "expected true or false")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise error(where, value, "expected a string")
        return value
    raise TypeError(f"{where}: field type {tp!r} is not supported by shared.strict")


def to_plain(obj: Any, array_encoder: typing.Callable[[np.ndarray], Any] | None = None) -> Any:
    """The inverse of :func:`build`: a dataclass as nested dicts, lists and scalars."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {f.name: to_plain(getattr(obj, f.name), array_encoder) for f in dataclasses.fields(obj)}
    if isinstance(obj, (tuple, list)):
        return [to_plain(v, array_encoder) for v in obj]
    if isinstance(obj, np.ndarray):
        if array_encoder is None:
            raise TypeError("arrays need an array encoder")
        return array_encoder(obj)
    if isinstance(obj, np.generic):
        return obj.item()
    return obj

"""Plain data (nested dicts, lists, scalars) written as TOML text, the inverse of ``tomllib.loads``.

The standard library reads TOML but does not write it; the fuzzer needs to write mutated worlds and
configurations, including values no valid file holds (``nan``, ``inf``, dates where numbers belong).
Tables become ``[a.b]`` sections, lists of tables ``[[a]]`` sections, anything nested in a list an
inline table.
"""

from __future__ import annotations

import datetime as dt
import math
import re
from typing import Any

_BARE_KEY = re.compile(r"^[A-Za-z0-9_-]+$")
_NOT_IN_COMMENT = re.compile(r"[\x00-\x08\x0b-\x1f\x7f]")  # a comment may hold a tab, and no other control


def comment(text: str) -> str:
    """``text`` as ``#`` lines, one per line of it, each control character a comment cannot hold
    spelled out as an escape: no text can end the comment and start a line of the file's own."""
    return "".join(("# " + _NOT_IN_COMMENT.sub(lambda m: repr(m.group())[1:-1], line)).rstrip() + "\n"
                   for line in text.splitlines())


def dumps(data: dict[str, Any]) -> str:
    """TOML text of a top-level table."""
    lines: list[str] = []
    _table(data, (), lines)
    return "\n".join(lines) + "\n"


def _is_table_array(value: Any) -> bool:
    return isinstance(value, list) and bool(value) and all(isinstance(v, dict) for v in value)


def _table(data: dict[str, Any], path: tuple[str, ...], lines: list[str]) -> None:
    # Plain keys first: after a section header every key belongs to that section.
    nested = {k: v for k, v in data.items() if isinstance(v, dict) or _is_table_array(v)}
    for key, value in data.items():
        if key not in nested:
            lines.append(f"{_key(key)} = {_value(value)}")
    for key, value in nested.items():
        inner = (*path, key)
        header = ".".join(_key(k) for k in inner)
        for table in value if isinstance(value, list) else [value]:
            lines.append(f"[[{header}]]" if isinstance(value, list) else f"[{header}]")
            _table(table, inner, lines)


def _key(key: str) -> str:
    return key if _BARE_KEY.match(key) else _string(key)


def _string(text: str) -> str:
    """A basic string: quotes, backslashes and control characters escaped, the rest as it is."""
    escaped = (f"\\u{ord(c):04x}" if ord(c) < 0x20 or ord(c) == 0x7F else "\\" + c if c in '"\\' else c
               for c in text)
    return '"' + "".join(escaped) + '"'


def _value(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return _string(value)
    if isinstance(value, (dt.datetime, dt.date, dt.time)):
        return value.isoformat()
    if isinstance(value, list):
        return "[" + ", ".join(_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{_key(k)} = {_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(f"{type(value).__name__} has no TOML form")

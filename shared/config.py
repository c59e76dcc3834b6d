"""Typed configuration: frozen dataclasses loaded from TOML and validated at load.

Every config class has defaults that run, so an empty file (or none) is a valid configuration. A
mistake is refused with a :class:`ConfigError` naming the file, the key and the problem.
"""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any, TypeVar

from shared.strict import StructureError, build

T = TypeVar("T")


class ConfigError(StructureError):
    """A configuration value that is missing, unknown, mistyped or out of range."""


def load_config(cls: type[T], path: Path | None = None, overrides: dict[str, Any] | None = None) -> T:
    """Load ``cls`` from a TOML file (or defaults) with dotted-key ``overrides`` applied on top."""
    data: dict[str, Any] = {}
    if path is not None:
        try:
            data = tomllib.loads(Path(path).read_text())
        except OSError as exc:
            raise ConfigError(str(path), None, f"cannot read the config file: {exc.strerror}") from None
        except (ValueError, RecursionError) as exc:  # TOMLDecodeError, bad UTF-8, a 4300-digit integer, deep nesting
            raise ConfigError(str(path), None, f"not valid TOML: {exc}") from None
    for dotted, value in (overrides or {}).items():
        _set_dotted(data, dotted, value)
    try:
        return build(cls, data, ConfigError)
    except ConfigError as exc:
        if path is not None:
            raise ConfigError(f"{path}: {exc.field}", exc.value, exc.problem) from None
        raise


def _set_dotted(data: dict[str, Any], dotted: str, value: Any) -> None:
    *parents, leaf = dotted.split(".")
    for name in parents:
        data = data.setdefault(name, {})
        if not isinstance(data, dict):
            raise ConfigError(dotted, data, f"{name} is not a table")
    data[leaf] = value

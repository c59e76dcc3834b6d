"""Command-line value types both programs use (transport flags live in :mod:`shared.transport`)."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable


def floats(count: int, flag: str, positive: bool = False) -> Callable[[str], tuple[float, ...]]:
    """An argparse type for ``count`` comma-separated finite numbers, e.g. ``--start 1.5,2.0,90``."""
    kind = "positive" if positive else "finite"

    def parse(text: str) -> tuple[float, ...]:
        try:
            values = tuple(float(v) for v in text.split(","))
        except ValueError:
            raise argparse.ArgumentTypeError(f"{flag}: expected {count} comma-separated numbers, got {text!r}") from None
        if len(values) != count or not all(math.isfinite(v) and (v > 0 or not positive) for v in values):
            raise argparse.ArgumentTypeError(f"{flag}: expected {count} {kind} comma-separated numbers, got {text!r}")
        return values
    return parse


def number(flag: str, lo: float, hi: float, kind: type = float) -> Callable[[str], float]:
    """An argparse type for a number (``kind``: float or int) in [lo, hi], e.g. ``--budget-s 600``."""

    def parse(text: str) -> float:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{flag}: expected a number in [{lo:g}, {hi:g}], got {text!r}") from None
        if not lo <= value <= hi:  # NaN fails too
            raise argparse.ArgumentTypeError(f"{flag} must lie in [{lo:g}, {hi:g}], got {text}")
        return value
    return parse


def probability(flag: str) -> Callable[[str], float]:
    """An argparse type for a probability in [0, 1], e.g. ``--move-threshold 0.05``."""
    return number(flag, 0.0, 1.0)

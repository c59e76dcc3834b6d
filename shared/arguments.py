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


def probability(flag: str) -> Callable[[str], float]:
    """An argparse type for a probability in [0, 1], e.g. ``--move-threshold 0.05``."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{flag}: expected a number in [0, 1], got {text!r}") from None
        if not 0.0 <= value <= 1.0:
            raise argparse.ArgumentTypeError(f"{flag} must lie in [0, 1], got {text}")
        return value
    return parse

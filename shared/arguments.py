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

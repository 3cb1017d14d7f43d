"""Checks that turn bad input into a clear error before any compute starts."""

from __future__ import annotations

import math
from collections.abc import Collection, Sequence
from typing import Any


def check_range(name: str, value: float, low: float, high: float) -> None:
    """Raise ValueError naming the parameter, its range and the value unless low <= value <= high."""
    try:
        ok = math.isfinite(float(value)) and low <= float(value) <= high
    except (TypeError, ValueError):
        ok = False
    if not ok:
        raise ValueError(f"{name} must be a finite number in [{low}, {high}], got {value!r}")


def check_int(name: str, value: int, low: int, high: int | None = None) -> None:
    """Raise ValueError unless value is an integer in [low, high] (high=None: no upper bound)."""
    ok = isinstance(value, int) and not isinstance(value, bool) and value >= low
    ok = ok and (high is None or value <= high)
    if not ok:
        bound = f"[{low}, {high}]" if high is not None else f">= {low}"
        raise ValueError(f"{name} must be an integer {bound}, got {value!r}")


def check_choice(name: str, value: Any, allowed: Collection[Any]) -> None:
    """Raise ValueError unless value is one of allowed."""
    if value not in allowed:
        raise ValueError(f"{name} must be one of {sorted(allowed)}, got {value!r}")


def check_vector(name: str, value: Sequence[float], length: int, *, positive: bool = False) -> None:
    """Raise ValueError unless value is a sequence of `length` finite (and, if asked, positive) numbers."""
    try:
        ok = len(value) == length and all(math.isfinite(float(v)) for v in value)
        ok = ok and (not positive or all(float(v) > 0 for v in value))
    except (TypeError, ValueError):
        ok = False
    if not ok:
        kind = "positive finite numbers" if positive else "finite numbers"
        raise ValueError(f"{name} must be {length} {kind}, got {value!r}")

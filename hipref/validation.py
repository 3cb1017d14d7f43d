"""Checks that turn bad input into a clear error before any compute starts."""

from __future__ import annotations

import dataclasses
import math
import numbers
import typing
from collections.abc import Collection, Iterable, Sequence
from typing import Any


def is_number(value: object) -> bool:
    """A real number: not a string that would convert to one, nor a bool (True is no noise level)."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


SCALAR_KINDS: dict[type, tuple[str, Any]] = {
    float: ("a number", is_number),
    int: ("an integer", lambda v: isinstance(v, numbers.Integral) and not isinstance(v, bool)),
    bool: ("True or False", lambda v: isinstance(v, bool)),
    str: ("a string", lambda v: isinstance(v, str)),
}
"""The field annotations `check_field_types` checks, each with what it asks for and its test."""


def check_field_types(obj: Any) -> None:
    """Raise ValueError naming the field unless every field of the dataclass `obj` annotated `float`, `int`,
    `bool` or `str` holds a value of that kind (an integer is a number; a bool or a string that would
    convert is none), so a cell or config with a value of the wrong kind fails where it is made or swept,
    not deep inside the compute. Fields with other annotations are left to the class's own checks."""
    try:
        hints = typing.get_type_hints(type(obj))
    except NameError:  # an annotation only a type checker resolves: nothing to check by
        return
    for field in dataclasses.fields(obj):
        kind = SCALAR_KINDS.get(hints.get(field.name))  # type: ignore[arg-type]
        value = getattr(obj, field.name)
        if kind is not None and not kind[1](value):
            raise ValueError(
                f"{type(obj).__name__}.{field.name} must be {kind[0]}, got {value!r} ({type(value).__name__})"
            )


def check_grids(config: Any, sequences: tuple[str, ...] = ()) -> None:
    """Raise ValueError naming the field unless every `tuple[X, ...]` field of the dataclass `config` holds
    a tuple or list (not a scalar or a string, whose characters would be taken for its items) of distinct
    items: a repeated value would run the same cells twice and fail only when their rows are combined;
    and every scalar field a value of its annotated kind (`check_field_types`). The fields named in
    `sequences` are ordered values that may repeat (a network's layer widths), not grids of cells."""
    check_field_types(config)
    hints = typing.get_type_hints(type(config))
    for field in dataclasses.fields(config):
        hint = hints[field.name]
        if typing.get_origin(hint) is not tuple or typing.get_args(hint)[1:] != (Ellipsis,):
            continue
        value = getattr(config, field.name)
        if not isinstance(value, tuple | list):
            raise ValueError(f"{field.name} must be a list or tuple of values, got {value!r}")
        repeated = sorted({repr(v) for v in value if list(value).count(v) > 1})
        if repeated and field.name not in sequences:
            raise ValueError(
                f"{field.name} must not repeat a value, got {value!r} ({', '.join(repeated)} twice)"
            )


def check_range(name: str, value: float, low: float, high: float) -> None:
    """Raise ValueError naming the parameter, its range and the value unless low <= value <= high."""
    try:
        ok = is_number(value) and math.isfinite(float(value)) and low <= float(value) <= high
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
        ok = len(value) == length and all(is_number(v) and math.isfinite(float(v)) for v in value)
        ok = ok and (not positive or all(float(v) > 0 for v in value))
    except (TypeError, ValueError):
        ok = False
    if not ok:
        kind = "positive finite numbers" if positive else "finite numbers"
        raise ValueError(f"{name} must be {length} {kind}, got {value!r}")


def check_parameter(name: str, value: float, bounds: tuple[float, float]) -> float:
    """The unknown parameter (or an estimate of it) must be finite and inside its range."""
    check_range(name, value, bounds[0], bounds[1])
    return float(value)


def check_interval(
    name: str,
    value: object,
    low: float,
    high: float,
    *,
    low_open: bool = False,
    high_open: bool = False,
    point: bool = False,
    unit: str = "",
    why: str = "",
) -> None:
    """Raise ValueError naming the field, its allowed values and the value given unless `value` is a pair
    (a, b) of finite numbers ordered a < b (a <= b when `point`) inside [low, high] (bounds excluded when
    `low_open`, `high_open`; an infinite bound is no bound)."""
    try:
        if not isinstance(value, Iterable):
            raise TypeError(value)
        ok = all(is_number(v) for v in value)
        a, b = (float(v) for v in value)
        ok = ok and math.isfinite(a) and math.isfinite(b) and (a <= b if point else a < b)
        ok = ok and (a > low if low_open else a >= low) and (b < high if high_open else b <= high)
    except (TypeError, ValueError):
        ok = False
    if not ok:
        bounds = "low " + ("<=" if point else "<") + " high"
        if math.isfinite(low):
            bounds = f"{low:g} {'<' if low_open else '<='} {bounds}"
        if math.isfinite(high):
            bounds = f"{bounds} {'<' if high_open else '<='} {high:g}"
        unit = f" in {unit}" if unit else ""
        raise ValueError(f"{name} must be (low, high){unit} with {bounds}{why}, got {value!r}")

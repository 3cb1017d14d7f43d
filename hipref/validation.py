"""Checks that turn bad input into a clear error before any compute starts.

A dataclass field declares its constraint in its annotation, `typing.Annotated` metadata that
`check_fields` reads: `noise: Annotated[float, Range(0.0, 1.0)]`, and for a grid of values the item
carries it, `levels: NonEmptyTuple[Annotated[float, Range(0.0, 1.0)]]` (`tuple[..., ...]` when it may be
empty). Checks that depend on another field or on a value known only at run time stay in the class's
`__post_init__`, after `check_fields`."""

from __future__ import annotations

import dataclasses
import math
import numbers
import typing
from collections.abc import Collection, Iterable, Sequence
from typing import Annotated, Any, TypeVar


def is_number(value: object) -> bool:
    """A real number: not a string that would convert to one, nor a bool (True is no noise level)."""
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


SCALAR_KINDS: dict[type, tuple[str, Any]] = {
    float: ("a number", is_number),
    int: ("an integer", lambda v: isinstance(v, numbers.Integral) and not isinstance(v, bool)),
    bool: ("True or False", lambda v: isinstance(v, bool)),
    str: ("a string", lambda v: isinstance(v, str)),
}
"""The field (and grid item) annotations `check_fields` checks the kind of, each with what it asks for
and its test."""


@dataclasses.dataclass(frozen=True)
class Range:
    """A finite number in [low, high] (`check_range`)."""

    low: float
    high: float

    def check(self, name: str, value: Any) -> None:
        check_range(name, value, self.low, self.high)

    def items(self) -> str:
        return f"value in [{self.low}, {self.high}]"


@dataclasses.dataclass(frozen=True)
class Integer:
    """An integer in [low, high], or at least low when high is None (`check_int`)."""

    low: int
    high: int | None = None

    def check(self, name: str, value: Any) -> None:
        check_int(name, value, self.low, self.high)

    def items(self) -> str:
        return f"integer in [{self.low}, {self.high}]" if self.high is not None else f"integer >= {self.low}"


@dataclasses.dataclass(frozen=True)
class OneOf:
    """One of `choices`, kept as a tuple (`check_choice`)."""

    choices: tuple[Any, ...]

    def __post_init__(self) -> None:
        object.__setattr__(self, "choices", tuple(self.choices))

    def check(self, name: str, value: Any) -> None:
        check_choice(name, value, self.choices)

    def items(self) -> str:
        return f"of {sorted(self.choices)}"


@dataclasses.dataclass(frozen=True)
class NonEmpty:
    """A tuple field that holds at least one item (`NonEmptyTuple`)."""

    def check(self, name: str, value: Any, items: str = "value") -> None:
        if not len(value):
            raise ValueError(f"{name} must hold at least one {items}, got {value!r}")


Constraint = Range | Integer | OneOf | NonEmpty

T = TypeVar("T")
NonEmptyTuple = Annotated[tuple[T, ...], NonEmpty()]
"""A tuple of at least one item: `NonEmptyTuple[Annotated[float, Range(0.0, 1.0)]]`."""


@dataclasses.dataclass(frozen=True)
class FieldRule:
    """What `check_fields` checks of one field, read from its annotation."""

    name: str
    kind: Any
    """The annotation of the field, or of a grid's items, without its constraints: of float, int, bool and
    str the value's kind is checked (`SCALAR_KINDS`), of any other nothing."""
    constraints: tuple[Constraint, ...]
    """The field's own: of its value, or of a grid as a whole (`NonEmpty`)."""
    grid: bool = False
    """A `tuple[X, ...]` field: a list or tuple of items of the kind X."""
    item_constraints: tuple[Constraint, ...] = ()


def split(hint: Any) -> tuple[Any, tuple[Constraint, ...]]:
    """An annotation without its `Annotated` metadata, and the constraints among that metadata."""
    if typing.get_origin(hint) is not Annotated:
        return hint, ()
    base, *metadata = typing.get_args(hint)
    return base, tuple(m for m in metadata if isinstance(m, Constraint))


FIELD_RULES: dict[type, tuple[FieldRule, ...]] = {}
"""The rules of every class `check_fields` has read, by class."""


def field_rules(cls: type) -> tuple[FieldRule, ...]:
    """The rule of every field of the dataclass `cls`, read once per class (NameError, not remembered, while
    an annotation names what is not yet defined)."""
    if cls in FIELD_RULES:
        return FIELD_RULES[cls]
    hints = typing.get_type_hints(cls, include_extras=True)
    rules = []
    for field in dataclasses.fields(cls):
        hint, constraints = split(hints[field.name])
        args = typing.get_args(hint)
        if typing.get_origin(hint) is tuple and args[1:] == (Ellipsis,):
            item, item_constraints = split(args[0])
            rules.append(FieldRule(field.name, item, constraints, True, item_constraints))
        else:
            rules.append(FieldRule(field.name, hint, constraints))
    FIELD_RULES[cls] = tuple(rules)
    return FIELD_RULES[cls]


def check_kind(obj: object, name: str, value: Any, kind: Any) -> None:
    """Raise ValueError naming the field unless `value` is of the scalar kind `kind` (any other: no check)."""
    test = SCALAR_KINDS.get(kind)
    if test is not None and not test[1](value):
        raise ValueError(
            f"{type(obj).__name__}.{name} must be {test[0]}, got {value!r} ({type(value).__name__})"
        )


def check_fields(obj: object, sequences: Collection[str] = ()) -> None:
    """Raise ValueError naming the field, its allowed values and the value given unless every field of the
    dataclass `obj` meets its annotation, field by field:

    - a field annotated `float`, `int`, `bool` or `str` holds a value of that kind (an integer is a number;
      a bool or a string that would convert is none), so a value of the wrong kind fails where the config
      or cell is made or swept, not deep inside the compute;
    - a `tuple[X, ...]` field holds a tuple or list (not a scalar or a string, whose characters would be
      taken for its items) of distinct items of the kind X: a repeated value would run the same cells twice
      and fail only when their rows are combined. The fields named in `sequences` are ordered values that
      may repeat (a network's layer widths), not grids of cells;
    - every constraint in the field's `Annotated` metadata (`Range`, `Integer`, `OneOf`, `NonEmpty`) holds,
      and for `tuple[Annotated[X, c], ...]` every item meets c.

    A field's constraints are checked before its kind: they name the allowed values. A class whose
    annotations name what only a type checker resolves (an import under TYPE_CHECKING) has nothing to check
    by; the package's own resolve (tests/test_validation.py)."""
    try:
        rules = field_rules(type(obj))
    except NameError:
        return
    for rule in rules:
        value = getattr(obj, rule.name)
        if not rule.grid:
            for constraint in rule.constraints:
                constraint.check(rule.name, value)
            check_kind(obj, rule.name, value, rule.kind)
            continue
        if not isinstance(value, tuple | list):
            raise ValueError(f"{rule.name} must be a list or tuple of values, got {value!r}")
        repeated = sorted({repr(v) for v in value if list(value).count(v) > 1})
        if repeated and rule.name not in sequences:
            raise ValueError(
                f"{rule.name} must not repeat a value, got {value!r} ({', '.join(repeated)} twice)"
            )
        items = next((c.items() for c in rule.item_constraints if not isinstance(c, NonEmpty)), "value")
        for constraint in rule.constraints:
            if isinstance(constraint, NonEmpty):
                constraint.check(rule.name, value, items)
            else:
                constraint.check(rule.name, value)
        for item in value:
            for constraint in rule.item_constraints:
                constraint.check(rule.name, item)
            check_kind(obj, f"{rule.name} item", item, rule.kind)


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
        bound = f"in [{low}, {high}]" if high is not None else f">= {low}"
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

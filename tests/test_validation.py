"""The input checks (`hipref.validation`): on hand-picked values at and beside each bound, what each check
accepts and refuses, and that a refusal names the parameter."""

from __future__ import annotations

import dataclasses
import importlib
import math
import pkgutil
from dataclasses import dataclass
from typing import Annotated

import numpy as np
import pytest

import hipref
from hipref.validation import (
    Integer,
    NonEmptyTuple,
    OneOf,
    Range,
    check_choice,
    check_fields,
    check_int,
    check_interval,
    check_range,
    check_vector,
    field_rules,
    is_number,
)


@pytest.mark.parametrize("value", [1, 1.5, np.float64(0.2), np.int64(3), -0.0])
def test_real_numbers_are_numbers(value: object) -> None:
    assert is_number(value)


@pytest.mark.parametrize("value", [True, False, "1.5", None, [1.0], 1j])
def test_bools_strings_and_others_are_not_numbers(value: object) -> None:
    assert not is_number(value)


@pytest.mark.parametrize("value", [0.0, 0.5, 1.0, 1, np.float32(0.25)])
def test_check_range_accepts_its_closed_interval(value: float) -> None:
    check_range("rate", value, 0.0, 1.0)


@pytest.mark.parametrize("value", [-1e-12, 1.0 + 1e-12, math.nan, math.inf, True, "0.5", None])
def test_check_range_refuses_outside_values_non_numbers_and_non_finite_naming_the_parameter(
    value: object,
) -> None:
    with pytest.raises(ValueError, match=r"rate must be a finite number in \[0.0, 1.0\]"):
        check_range("rate", value, 0.0, 1.0)  # type: ignore[arg-type]


def test_check_range_refuses_infinity_even_with_no_upper_bound() -> None:
    check_range("scale", 1e300, 0.0, math.inf)
    for value in (math.inf, -math.inf):
        with pytest.raises(ValueError, match="scale must be a finite number"):
            check_range("scale", value, -math.inf, math.inf)


def test_a_bool_is_no_integer_even_where_its_value_would_fit() -> None:
    check_int("n", 1, 0, 1)
    for value in (True, False):
        with pytest.raises(ValueError, match="n must be an integer"):
            check_int("n", value, 0, 1)


def test_check_int_accepts_integers_in_range_and_an_open_top() -> None:
    for value in (2, 3, 5):
        check_int("n", value, 2, 5)
    check_int("n", 10**12, 2)


@pytest.mark.parametrize(
    ("value", "high"), [(1, 5), (6, 5), (3.0, 5), (True, None), ("3", None), (np.float64(3), 5)]
)
def test_check_int_refuses_outside_values_floats_and_bools(value: object, high: int | None) -> None:
    with pytest.raises(ValueError, match="n must be an integer"):
        check_int("n", value, 2, high)  # type: ignore[arg-type]


def test_check_choice_accepts_members_only() -> None:
    check_choice("kind", "b", ("a", "b"))
    with pytest.raises(ValueError, match=r"kind must be one of \['a', 'b'\], got 'c'"):
        check_choice("kind", "c", ("b", "a"))


def test_check_vector_wants_the_length_finite_entries_and_if_asked_positive_ones() -> None:
    check_vector("gains", (1.0, 2, np.float64(0.5)), 3)
    check_vector("gains", (0.0, -1.0), 2)
    cases = [
        ((1.0, 2.0), 3, False),
        ((1.0, math.nan, 1.0), 3, False),
        ((1.0, 0.0), 2, True),
        ("ab", 2, False),
    ]
    for bad, length, positive in cases:
        with pytest.raises(ValueError, match="gains must be"):
            check_vector("gains", bad, length, positive=positive)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("value", "options", "ok"),
    [
        ((0.0, 1.0), {}, True),
        ((0.0, 1.0), {"low_open": True}, False),  # a touches the excluded low bound
        ((0.0, 1.0), {"high_open": True}, False),
        ((0.1, 0.9), {"low_open": True, "high_open": True}, True),
        ((0.5, 0.5), {}, False),  # a < b asked
        ((0.5, 0.5), {"point": True}, True),
        ((0.6, 0.5), {"point": True}, False),
        ((-0.1, 0.5), {}, False),
        ((0.2, 1.1), {}, False),
        ((0.2, math.nan), {}, False),
        ((0.2,), {}, False),
        ((0.1, 0.2, 0.3), {}, False),
        (0.5, {}, False),
        (("0.1", "0.2"), {}, False),
    ],
)
def test_check_interval_on_each_bound_and_shape(value: object, options: dict[str, bool], ok: bool) -> None:
    if ok:
        check_interval("band", value, 0.0, 1.0, **options)
    else:
        with pytest.raises(ValueError, match=r"band must be \(low, high\)"):
            check_interval("band", value, 0.0, 1.0, **options)


def test_check_interval_with_infinite_bounds_accepts_any_ordered_pair() -> None:
    check_interval("band", (-1e9, 1e9), -math.inf, math.inf)
    with pytest.raises(ValueError, match=r"band must be \(low, high\) in N with low < high, got"):
        check_interval("band", (2.0, 1.0), -math.inf, math.inf, unit="N")


@dataclass(frozen=True)
class Settings:
    rate: float = 0.1
    count: int = 2
    flag: bool = True
    name: str = "x"
    widths: tuple[int, ...] = (8, 8)
    levels: tuple[float, ...] = (0.1, 0.2)


def test_fields_take_an_integer_as_a_number_and_nothing_else_across_kinds() -> None:
    check_fields(Settings(rate=1), sequences=("widths",))
    for field, bad in (
        ("rate", "0.1"),
        ("rate", True),
        ("count", 2.0),
        ("count", False),
        ("flag", 1),
        ("name", 3),
    ):
        with pytest.raises(ValueError, match=rf"Settings\.{field} must be"):
            check_fields(Settings(**{field: bad}), sequences=("widths",))  # type: ignore[arg-type]


def test_grids_refuse_a_repeated_value_a_scalar_a_string_or_a_wrong_item_but_sequences_may_repeat() -> None:
    check_fields(Settings(), sequences=("widths",))
    check_fields(Settings(levels=[0.1, 0.3]), sequences=("widths",))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"widths must not repeat a value, got \(8, 8\) \(8 twice\)"):
        check_fields(Settings())
    with pytest.raises(ValueError, match="levels must not repeat a value"):
        check_fields(Settings(levels=(0.1, 0.2, 0.1)), sequences=("widths",))
    for bad in (0.1, "0.1"):
        with pytest.raises(ValueError, match="levels must be a list or tuple"):
            check_fields(Settings(levels=bad), sequences=("widths",))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"Settings\.levels item must be a number, got '0.3' \(str\)"):
        check_fields(Settings(levels=(0.1, "0.3")), sequences=("widths",))  # type: ignore[arg-type]


@dataclass(frozen=True)
class Constrained:
    noise: Annotated[float, Range(0.0, 1.0)] = 0.0
    seed: Annotated[int, Integer(0)] = 0
    size: Annotated[int, Integer(1, 10)] = 2
    rule: Annotated[str, OneOf({"uniform": 1, "belief": 2})] = "uniform"
    levels: NonEmptyTuple[Annotated[float, Range(0.0, 1.0)]] = (0.1, 0.2)
    rules: tuple[Annotated[str, OneOf(("uniform", "belief"))], ...] = ()

    def __post_init__(self) -> None:
        check_fields(self)


def test_constraints_in_annotations_accept_their_bounds() -> None:
    Constrained(noise=1, seed=3, size=10, rule="belief", levels=[0.0, 1.0], rules=("belief",))  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("given", "message"),
    [
        ({"noise": 1.5}, r"noise must be a finite number in \[0.0, 1.0\], got 1.5"),
        ({"noise": "0.5"}, r"noise must be a finite number in \[0.0, 1.0\], got '0.5'"),
        ({"noise": True}, r"noise must be a finite number in \[0.0, 1.0\], got True"),
        ({"seed": -1}, r"seed must be an integer >= 0, got -1"),
        ({"size": 11}, r"size must be an integer in \[1, 10\], got 11"),
        ({"size": 2.0}, r"size must be an integer in \[1, 10\], got 2.0"),
        ({"rule": "thompson"}, r"rule must be one of \['belief', 'uniform'\], got 'thompson'"),
        ({"rule": 3}, r"rule must be one of \['belief', 'uniform'\], got 3"),
        ({"levels": ()}, r"levels must hold at least one value in \[0.0, 1.0\], got \(\)"),
        ({"levels": ("0.3",)}, r"levels must be a finite number in \[0.0, 1.0\], got '0.3'"),
        ({"levels": (0.3, 1.3)}, r"levels must be a finite number in \[0.0, 1.0\], got 1.3"),
        ({"levels": (0.3, 0.3)}, r"levels must not repeat a value, got \(0.3, 0.3\) \(0.3 twice\)"),
        ({"rules": ("uniform", "x")}, r"rules must be one of \['belief', 'uniform'\], got 'x'"),
        ({"rules": "uniform"}, r"rules must be a list or tuple of values, got 'uniform'"),
    ],
)
def test_constraints_in_annotations_refuse_naming_the_field_the_allowed_values_and_the_value(
    given: dict[str, object], message: str
) -> None:
    with pytest.raises(ValueError, match=message):
        Constrained(**given)  # type: ignore[arg-type]


def test_every_dataclass_of_the_package_resolves_its_annotations() -> None:
    """`check_fields` has nothing to check by where an annotation does not resolve at run time."""
    found = 0
    for info in pkgutil.walk_packages(hipref.__path__, "hipref."):
        if info.name.startswith("hipref.bench"):
            continue
        module = importlib.import_module(info.name)
        for obj in vars(module).values():
            if isinstance(obj, type) and dataclasses.is_dataclass(obj) and obj.__module__ == info.name:
                field_rules(obj)
                found += 1
    assert found >= 40

"""Every config of the package refuses, where it is built, a value of the wrong kind in a number field (a
string that would convert, a bool) and a repeated value in a grid of cells, naming the field."""

from __future__ import annotations

import dataclasses
import importlib
import pkgutil
import typing
from typing import Any

import pytest

import hipref


def package_configs() -> dict[str, type]:
    """Every dataclass named `...Config` defined in the package (the benchmarks aside)."""
    found: dict[str, type] = {}
    for info in pkgutil.walk_packages(hipref.__path__, "hipref."):
        if info.name.startswith("hipref.bench"):
            continue
        module = importlib.import_module(info.name)
        for name, obj in vars(module).items():
            if name.endswith("Config") and dataclasses.is_dataclass(obj) and obj.__module__ == info.name:
                found[f"{info.name}.{name}"] = obj  # type: ignore[assignment]
    return found


CONFIGS = package_configs()


def fields_of(config: type, *kinds: Any) -> list[str]:
    hints = typing.get_type_hints(config)
    return [f.name for f in dataclasses.fields(config) if hints[f.name] in kinds]


def test_the_package_has_its_configs() -> None:
    assert {"hipref.learners.pesi.PESIConfig", "hipref.teach.config.TeachConfig"} <= set(CONFIGS)
    assert len(CONFIGS) >= 20


@pytest.mark.parametrize("qualname", sorted(CONFIGS))
def test_a_number_field_refuses_a_string_and_a_bool_naming_the_field(qualname: str) -> None:
    config = CONFIGS[qualname]
    default = config()
    for name in fields_of(config, float, int):
        for wrong in ("2", True):
            with pytest.raises((ValueError, TypeError), match=name):
                dataclasses.replace(default, **{name: wrong})


def grids(config: type) -> list[str]:
    """The `tuple[X, ...]` fields with values by default, but the ordered values that may repeat (a study's
    `SEQUENCES`, such as a network's layer widths)."""
    hints = typing.get_type_hints(config)
    sequences = getattr(config, "SEQUENCES", ())
    return [
        f.name
        for f in dataclasses.fields(config)
        if typing.get_origin(hints[f.name]) is tuple
        and typing.get_args(hints[f.name])[1:] == (Ellipsis,)
        and f.name not in sequences
        and getattr(config(), f.name)
    ]


@pytest.mark.parametrize("qualname", sorted(q for q, c in CONFIGS.items() if grids(c)))
def test_a_grid_refuses_a_repeated_value_naming_the_field(qualname: str) -> None:
    config = CONFIGS[qualname]
    for name in grids(config):
        value = getattr(config(), name)
        with pytest.raises(ValueError, match=f"{name} must not repeat"):
            dataclasses.replace(config(), **{name: (*value, value[0])})


@pytest.mark.parametrize("qualname", sorted(CONFIGS))
def test_a_field_a_study_redefines_keeps_the_constraints_of_its_base(qualname: str) -> None:
    """A subclass that redefines a field (another default) must repeat its annotation: its own replaces the
    base's, constraints and all (`hipref.validation.check_fields`)."""
    config = CONFIGS[qualname]
    own = typing.get_type_hints(config, include_extras=True)
    for base in config.__mro__[1:]:
        if dataclasses.is_dataclass(base):
            hints = typing.get_type_hints(base, include_extras=True)
            for field in dataclasses.fields(base):
                assert own[field.name] == hints[field.name], f"{field.name} of {base.__name__}"

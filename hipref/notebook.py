"""A notebook's parameters, checked against its config before any compute.

Each notebook's cell tagged `parameters` assigns typed names (`episodes: int = 66  # help`); papermill
injects overrides after it as plain assignments. The first code cell then calls `check_parameters` (or
`config_from_parameters`), which

- refuses any user-level name in the notebook's namespace that the parameters cell does not declare, so a
  misspelt key in a `-f` file or a `-p` fails the run instead of being ignored in favour of the default;
  and any name papermill's injected cell assigns that the parameters cell does not declare, also an
  upper-case or private one (`-p EPISODES 5`, `-p _episodes 5`), whoever ran papermill (`make`, its
  command line, `papermill.execute_notebook`): the kernel's input history holds the injected cell;
- converts each parameter to the type of the config field it sets (the config dataclass is the single
  source of truth for names and types; a notebook-only parameter sets a field of another config through a
  prefix, as notebook 06's `copesi_seeds` sets `R3Config.seeds`), refusing with a ValueError that names
  the parameter, the type and the value a scalar where a list is needed, a string where numbers are, a
  bool where a number is;
- writes the converted values back, so later cells see the checked values.

A notebook's parameters are the names its parameters cell annotates. In a notebook's config a field of
type `tuple[X, ...]` is a `list[X]` parameter, since papermill and YAML give lists.
"""

from __future__ import annotations

import ast
import contextlib
import dataclasses
import difflib
import types
import typing
from collections.abc import Mapping, MutableMapping
from typing import TYPE_CHECKING, Any, TypeVar

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

Config = TypeVar("Config", bound="DataclassInstance")

Source = type | tuple[str, type]
"""Where parameters come from: a config dataclass, or (prefix, config) for parameters named prefix + field."""

PLAIN_DATA: tuple[type, ...] = (bool, int, float, str, list, tuple, dict, type(None))
"""Values a parameter can hold; other names in a namespace (modules, functions, classes, frames of
results, IPython's own objects) are never parameters."""

_SEEN = "_hipref_seen_names"
"""Namespace key recording the names present at the first successful check: names that later cells of an
interactive session define are not parameters and are ignored when the first code cell is run again."""

_IPYTHON = frozenset({"In", "Out", "exit", "quit", "get_ipython", "open"})

_INJECTED = "# Parameters\n"
"""How papermill's injected-parameters cell begins (`papermill.translators.Translator.codify`)."""


def injected_names(namespace: Mapping[str, Any]) -> list[str]:
    """The names papermill's injected-parameters cell assigned, read from IPython's input history `In`
    (every cell the kernel ran, in order); none outside a kernel or without papermill."""
    history = namespace.get("In")
    names: list[str] = []
    for source in history if isinstance(history, list) else []:
        if not (isinstance(source, str) and source.startswith(_INJECTED)):
            continue
        with contextlib.suppress(SyntaxError):
            for node in ast.parse(source).body:
                if isinstance(node, ast.Assign):
                    names += [t.id for t in node.targets if isinstance(t, ast.Name) and t.id not in names]
    return names


def user_names(namespace: Mapping[str, Any]) -> dict[str, Any]:
    """The names of `namespace` that hold plain data and are not private, constants or IPython's own.

    Parameters are lower-case (the config fields they set); an upper-case name is a constant a cell
    imported, such as `DOMAINS` or `PAPER_TABLE3`, never a parameter."""
    return {
        name: value
        for name, value in namespace.items()
        if not name.startswith("_")
        and not name.isupper()
        and name not in _IPYTHON
        and type(value) in PLAIN_DATA
    }


def declared_types(*sources: Source) -> dict[str, Any]:
    """Parameter name -> the type its config field declares, over every field of every source."""
    declared: dict[str, Any] = {}
    for source in sources:
        prefix, config = source if isinstance(source, tuple) else ("", source)
        if not dataclasses.is_dataclass(config):
            raise TypeError(f"a parameter source is a config dataclass, got {config!r}")
        hints = typing.get_type_hints(config)
        for field in dataclasses.fields(config):
            declared.setdefault(prefix + field.name, hints[field.name])
    return declared


def notebook_type(hint: Any) -> Any:
    """The annotation a parameters cell gives a config field of type `hint`: `tuple[X, ...]` is `list[X]`."""
    if typing.get_origin(hint) is tuple:
        return types.GenericAlias(list, typing.get_args(hint)[0])
    return hint


def type_text(hint: Any) -> str:
    """`hint` as written in a parameters cell: `int`, `list[float]`, `str | None`."""
    origin = typing.get_origin(hint)
    if origin in (types.UnionType, typing.Union):
        return " | ".join(type_text(arg) for arg in typing.get_args(hint))
    if origin is not None:
        return f"{origin.__name__}[{', '.join(type_text(arg) for arg in typing.get_args(hint))}]"
    return "None" if hint is type(None) else getattr(hint, "__name__", repr(hint))


def _given(value: Any) -> str:
    return f"{value!r} ({type(value).__name__})"


def _scalar(name: str, value: Any, hint: Any) -> Any:
    # bool is an int in Python, but True for a number of seeds or a noise level is always a mistake.
    if hint is float and isinstance(value, int | float) and not isinstance(value, bool):
        return float(value)
    if hint is int and isinstance(value, int) and not isinstance(value, bool):
        return value
    if hint in (str, bool) and isinstance(value, hint):
        return value
    if hint not in (int, float, str, bool):
        raise TypeError(f"parameter {name} has a config type a notebook cannot set: {type_text(hint)}")
    raise ValueError(f"{name} must be {type_text(hint)}, got {_given(value)}")


def check_value(name: str, value: Any, hint: Any) -> Any:
    """`value` converted to the config type `hint`; ValueError naming the parameter, type and value if it
    does not fit. Lists (and tuples) become tuples for a `tuple[X, ...]` field; ints are floats where
    floats are asked for; a bool is never a number and a string is never a list."""
    origin = typing.get_origin(hint)
    if origin in (types.UnionType, typing.Union):
        arms = typing.get_args(hint)
        if value is None and type(None) in arms:
            return None
        for arm in arms:
            if arm is not type(None):
                try:
                    return check_value(name, value, arm)
                except ValueError:
                    pass
        raise ValueError(f"{name} must be {type_text(hint)}, got {_given(value)}")
    if origin in (tuple, list):
        element = typing.get_args(hint)[0]
        if not isinstance(value, list | tuple):
            raise ValueError(
                f"{name} must be {type_text(notebook_type(hint))}, got {_given(value)}; give a list, "
                f"e.g. papermill -y '{name}: [...]' or a -f YAML file, not -p (which gives one scalar)"
            )
        checked = []
        for i, item in enumerate(value):
            try:
                checked.append(_scalar(name, item, element))
            except ValueError:
                raise ValueError(
                    f"{name} must be {type_text(notebook_type(hint))}, got {_given(value)}: "
                    f"item {i} is {_given(item)}"
                ) from None
        return tuple(checked)
    return _scalar(name, value, hint)


def check_parameters(namespace: MutableMapping[str, Any], *sources: Source) -> dict[str, Any]:
    """Check a notebook's parameters in `namespace` (its `globals()`) and return them converted.

    The parameters are the names the parameters cell annotates; each must be a field of one of `sources`
    (a config, or (prefix, config)), with the annotation the field's type asks for. Raises ValueError
    naming any other plain-data name (a misspelt or unknown parameter, with the notebook's parameters),
    or a parameter whose value does not fit its type. The converted values are written back to
    `namespace` (a list stays a list there; the returned values hold tuples, as the configs do).
    """
    annotations: Mapping[str, Any] = namespace.get("__annotations__", {})
    declared = declared_types(*sources)
    configs = ", ".join(
        f"{s[1].__name__} (as {s[0]}<field>)" if isinstance(s, tuple) else s.__name__ for s in sources
    )
    for name, annotation in annotations.items():
        if name not in declared:
            raise ValueError(f"notebook parameter {name} sets no field of {configs}")
        expected = notebook_type(declared[name])
        if annotation != expected:
            raise ValueError(
                f"notebook parameter {name} is annotated {type_text(annotation)} in the parameters cell, "
                f"but its config field asks for {type_text(expected)}"
            )
    parameters = list(annotations)
    if not parameters:
        raise ValueError("the parameters cell declares no typed parameter (name: type = default  # help)")
    seen = namespace.get(_SEEN)
    unknown = [
        name for name in user_names(namespace) if name not in annotations and (seen is None or name in seen)
    ]
    unknown += [name for name in injected_names(namespace) if name not in annotations and name not in unknown]
    if unknown:
        named = []
        for name in unknown:
            close = difflib.get_close_matches(name.lower().lstrip("_"), parameters, n=1)
            named.append(f"{name} (did you mean {close[0]}?)" if close else name)
        raise ValueError(
            f"unknown parameter(s) {', '.join(named)}: this notebook's parameters are "
            f"{', '.join(parameters)} (see papermill --help-notebook)"
        )
    values = {
        name: check_value(name, namespace[name], declared[name]) for name in parameters if name in namespace
    }
    for name, value in values.items():
        namespace[name] = list(value) if isinstance(value, tuple) else value
    if seen is None:
        namespace[_SEEN] = frozenset(user_names(namespace))
    return values


def config_from(config: type[Config], values: Mapping[str, Any], prefix: str = "", **fixed: Any) -> Config:
    """`config` built from the checked parameters named prefix + field (others are left out) and `fixed`.

    Building the config runs its validation, so a value out of range fails here, before any compute.
    """
    fields = {field.name for field in dataclasses.fields(config)}
    kwargs = {
        name[len(prefix) :]: value
        for name, value in values.items()
        if name.startswith(prefix) and name[len(prefix) :] in fields
    }
    return config(**kwargs, **fixed)


def config_from_parameters(config: type[Config], namespace: MutableMapping[str, Any]) -> Config:
    """The notebook's config: `check_parameters(namespace, config)` then `config_from` on the values."""
    return config_from(config, check_parameters(namespace, config))

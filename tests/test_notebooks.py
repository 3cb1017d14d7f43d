"""The notebooks' contract with papermill and with the two parameter profiles."""

from __future__ import annotations

import ast
import dataclasses
import importlib
import json
import re
import typing
from pathlib import Path
from typing import Any

import papermill
import pytest
import yaml

from hipref.notebook import Source, declared_types, notebook_type, type_text

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("[0-9][0-9]_*.ipynb"))


def parameters_cell(notebook: Path) -> str:
    cells = json.loads(notebook.read_text())["cells"]
    tagged = [c for c in cells if "parameters" in c.get("metadata", {}).get("tags", [])]
    assert len(tagged) == 1, f"{notebook.name}: papermill needs exactly one cell tagged 'parameters'"
    return "".join(tagged[0]["source"])


def defaults(notebook: Path) -> dict[str, object]:
    return {name: default for name, (_, default) in typed_parameters(notebook).items()}


def typed_parameters(notebook: Path) -> dict[str, tuple[str, object]]:
    """Name -> (annotation as written, default) of every parameter; each must be `name: type = literal`."""
    parameters: dict[str, tuple[str, object]] = {}
    for node in ast.parse(parameters_cell(notebook)).body:
        assert isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and node.value, (
            f"{notebook.name}: every line of the parameters cell is 'name: type = default  # help', "
            f"got {ast.unparse(node)!r}"
        )
        parameters[node.target.id] = (ast.unparse(node.annotation), ast.literal_eval(node.value))
    return parameters


def first_code_cell(notebook: Path) -> str:
    cells = json.loads(notebook.read_text())["cells"]
    (at,) = [i for i, c in enumerate(cells) if "parameters" in c.get("metadata", {}).get("tags", [])]
    # papermill puts the overrides of a run in a cell of its own, right after the parameters cell.
    following = [
        c
        for c in cells[at + 1 :]
        if c["cell_type"] == "code" and "injected-parameters" not in c.get("metadata", {}).get("tags", [])
    ]
    return "".join(following[0]["source"])


def parameter_sources(notebook: Path) -> list[Source]:
    """The configs the notebook's first code cell checks its parameters against, resolved through the
    cell's own imports: what `config_from_parameters(Config, globals())` or
    `check_parameters(globals(), Config, ("prefix", Other))` names."""
    tree = ast.parse(first_code_cell(notebook))
    imported = {
        alias.asname or alias.name: (node.module, alias.name)
        for node in ast.walk(tree)
        if isinstance(node, ast.ImportFrom) and node.module
        for alias in node.names
    }

    def resolve(node: ast.expr) -> type:
        assert isinstance(node, ast.Name) and node.id in imported, ast.unparse(node)
        module, name = imported[node.id]
        return getattr(importlib.import_module(module), name)

    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name):
            if node.func.id == "config_from_parameters":
                return [resolve(node.args[0])]
            if node.func.id == "check_parameters":
                return [
                    (ast.literal_eval(arg.elts[0]), resolve(arg.elts[1]))
                    if isinstance(arg, ast.Tuple)
                    else resolve(arg)
                    for arg in node.args[1:]
                ]
    raise AssertionError(f"{notebook.name}: the first code cell does not check the notebook's parameters")


def config_defaults(*sources: Source) -> dict[str, Any]:
    found: dict[str, Any] = {}
    for source in sources:
        prefix, config = source if isinstance(source, tuple) else ("", source)
        for field in dataclasses.fields(config):
            if field.default is not dataclasses.MISSING:
                found.setdefault(prefix + field.name, field.default)
            elif field.default_factory is not dataclasses.MISSING:
                found.setdefault(prefix + field.name, field.default_factory())
    return found


ABSOLUTE_PATH = re.compile(r"(?<![\w.~$:/<>-])/(?:[\w.+@-]+/)+[\w.+@-]*")
"""An absolute POSIX path of two parts or more (`/work/main/results`, `/tmp/x`), not a URL's path, an HTML
closing tag or a ratio (`1/4`, `cell/s`)."""


def output_texts(notebook: Path) -> list[str]:
    """Every text of every output (streams, errors, text data; not the base64 of images)."""
    found: list[str] = []
    for cell in json.loads(notebook.read_text())["cells"]:
        for output in cell.get("outputs", []):
            found.append("".join(output.get("text", "")))
            found.extend([output.get("evalue", ""), *output.get("traceback", [])])
            found.extend(
                "".join(value)
                for media, value in output.get("data", {}).items()
                if media.startswith("text/") or media == "image/svg+xml"
            )
    return found


def test_there_are_notebooks() -> None:
    assert len(NOTEBOOKS) >= 5


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_every_parameter_has_a_help_text(notebook: Path) -> None:
    # papermill --help-notebook shows the trailing comment of each parameter's line.
    for line in parameters_cell(notebook).splitlines():
        if "=" in line and not line.lstrip().startswith("#"):
            assert "  # " in line, f"{notebook.name}: parameter without help text: {line!r}"


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_quick_profile_sets_only_what_differs_from_the_defaults_and_full_names_only_parameters(
    notebook: Path,
) -> None:
    # papermill keeps the parameters cell's default for a parameter the profile leaves out.
    names = defaults(notebook)
    quick = yaml.safe_load((ROOT / "params" / "quick" / f"{notebook.stem}.yaml").read_text()) or {}
    full = yaml.safe_load((ROOT / "params" / "full" / f"{notebook.stem}.yaml").read_text()) or {}
    assert set(full) <= set(names), f"params/full/{notebook.stem}.yaml names unknown parameters"
    for name, value in quick.items():
        assert name in names, f"params/quick/{notebook.stem}.yaml names unknown parameter {name}"
        expected = names[name]
        if isinstance(expected, tuple):
            expected = list(expected)
        assert value != expected, f"{notebook.stem}: quick profile repeats the default {name}={value!r}"


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_is_committed_executed_with_a_checked_cell(notebook: Path) -> None:
    cells = [c for c in json.loads(notebook.read_text())["cells"] if c["cell_type"] == "code"]
    assert any(c.get("outputs") for c in cells), f"{notebook.name} has no outputs"
    assert any("".join(c["source"]).startswith("# NBVAL_CHECK_OUTPUT") for c in cells)


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_help_notebook_gives_every_parameter_a_type_and_a_help_text(notebook: Path) -> None:
    # What `papermill --help-notebook` prints: a line papermill cannot parse is left out entirely.
    inferred = {p["name"]: p for p in papermill.inspect_notebook(str(notebook)).values()}
    assert list(inferred) == list(typed_parameters(notebook)), f"{notebook.name}: papermill misses parameters"
    for name, parameter in inferred.items():
        assert parameter["inferred_type_name"] not in ("None", ""), f"{notebook.name}: {name} has no type"
        assert parameter["help"], f"{notebook.name}: {name} has no help text"


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_parameters_agree_with_the_config_and_the_quick_profile(notebook: Path) -> None:
    sources = parameter_sources(notebook)
    types = declared_types(*sources)
    config_default = config_defaults(*sources)
    parameters = typed_parameters(notebook)
    for name, (annotation, default) in parameters.items():
        assert name in types, f"{notebook.name}: parameter {name} sets no config field"
        expected = type_text(notebook_type(types[name]))
        assert annotation == expected, (
            f"{notebook.name}: {name} is annotated {annotation}, config: {expected}"
        )
        from_config = config_default[name]
        if typing.get_origin(types[name]) is tuple:
            from_config = list(from_config)
        assert default == from_config, (
            f"{notebook.name}: {name} defaults to {default!r}, config {from_config!r}"
        )


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_is_committed_as_a_person_runs_it(notebook: Path) -> None:
    # `make notebooks` removes papermill's cell of injected parameters: in JupyterLab it would override an
    # edit of the parameters cell. The parameters cell's defaults are the quick profile it ran with.
    tags = [c.get("metadata", {}).get("tags", []) for c in json.loads(notebook.read_text())["cells"]]
    injected = [i for i, cell_tags in enumerate(tags) if "injected-parameters" in cell_tags]
    assert not injected, (
        f"{notebook.name} has papermill's injected-parameters cell (cell {injected[0]}); re-execute it with "
        f"`make notebooks NOTEBOOKS={notebook.relative_to(ROOT)}`"
    )


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_names_no_absolute_path(notebook: Path) -> None:
    found = sorted({path for text in output_texts(notebook) for path in ABSOLUTE_PATH.findall(text)})
    assert not found, f"{notebook.name}: outputs name absolute paths of a machine: {found[:5]}"
    recorded = json.loads(notebook.read_text())["metadata"].get("papermill", {})
    for key in ("input_path", "output_path"):
        assert not str(recorded.get(key, "")).startswith("/"), f"{notebook.name}: {key} {recorded[key]!r}"

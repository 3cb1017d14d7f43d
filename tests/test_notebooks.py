"""The notebooks' contract with papermill and with the two parameter profiles."""

from __future__ import annotations

import ast
import json
from pathlib import Path

import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("[0-9][0-9]_*.ipynb"))


def parameters_cell(notebook: Path) -> str:
    cells = json.loads(notebook.read_text())["cells"]
    tagged = [c for c in cells if "parameters" in c.get("metadata", {}).get("tags", [])]
    assert len(tagged) == 1, f"{notebook.name}: papermill needs exactly one cell tagged 'parameters'"
    return "".join(tagged[0]["source"])


def defaults(notebook: Path) -> dict[str, object]:
    tree = ast.parse(parameters_cell(notebook))
    return {
        node.targets[0].id: ast.literal_eval(node.value)
        for node in tree.body
        if isinstance(node, ast.Assign) and isinstance(node.targets[0], ast.Name)
    }


def test_there_are_notebooks() -> None:
    assert len(NOTEBOOKS) >= 5


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_every_parameter_has_a_help_text(notebook: Path) -> None:
    # papermill --help-notebook shows the trailing comment of each parameter's line.
    for line in parameters_cell(notebook).splitlines():
        if "=" in line and not line.lstrip().startswith("#"):
            assert "  # " in line, f"{notebook.name}: parameter without help text: {line!r}"


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_quick_profile_equals_the_defaults_and_full_names_only_parameters(notebook: Path) -> None:
    names = defaults(notebook)
    quick = yaml.safe_load((ROOT / "params" / "quick" / f"{notebook.stem}.yaml").read_text()) or {}
    full = yaml.safe_load((ROOT / "params" / "full" / f"{notebook.stem}.yaml").read_text()) or {}
    assert set(full) <= set(names), f"params/full/{notebook.stem}.yaml names unknown parameters"
    for name, value in quick.items():
        assert name in names, f"params/quick/{notebook.stem}.yaml names unknown parameter {name}"
        expected = names[name]
        if isinstance(expected, tuple):
            expected = list(expected)
        assert value == expected, f"{notebook.stem}: quick profile {name}={value!r}, default {names[name]!r}"


@pytest.mark.parametrize("notebook", NOTEBOOKS, ids=lambda p: p.stem)
def test_notebook_is_committed_executed_with_a_checked_cell(notebook: Path) -> None:
    cells = [c for c in json.loads(notebook.read_text())["cells"] if c["cell_type"] == "code"]
    assert any(c.get("outputs") for c in cells), f"{notebook.name} has no outputs"
    assert any("".join(c["source"]).startswith("# NBVAL_CHECK_OUTPUT") for c in cells)

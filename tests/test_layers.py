"""The package's layers: each imports only from the layers below it (read from the source, imports inside
functions included)."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import hipref

PACKAGE = Path(hipref.__file__).resolve().parent

FORBIDDEN: dict[str, tuple[str, ...]] = {
    "learners": ("mujoco", "hipref.envs", "hipref.sim", "hipref.control", "hipref.experiments"),
    "teachers": ("mujoco", "hipref.envs", "hipref.learners", "hipref.experiments"),
    "control": ("hipref.envs", "hipref.learners", "hipref.teachers", "hipref.experiments"),
    "envs": ("hipref.learners", "hipref.teachers", "hipref.experiments"),
}
"""Per subpackage, the modules it must not import: learners and teachers hold no physics, and nothing
below the studies imports them."""


def imported_modules(source: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(source.read_bytes())):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


@pytest.mark.parametrize("layer", list(FORBIDDEN))
def test_a_layer_imports_nothing_above_it(layer: str) -> None:
    sources = sorted((PACKAGE / layer).glob("*.py"))
    assert sources
    offending = {
        f"{source.name}: {name}"
        for source in sources
        for name in imported_modules(source)
        if any(name == banned or name.startswith(banned + ".") for banned in FORBIDDEN[layer])
    }
    assert not offending, f"hipref/{layer} imports {sorted(offending)}"

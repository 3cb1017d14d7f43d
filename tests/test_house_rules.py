"""Two rules of the package, read from the source of hipref and of the notebooks' code cells:

- a domain and a method are looked up in their registries, never branched on by name elsewhere: no
  comparison of a `domain` or `method` with a string literal (or a tuple of them) outside a row filter, no
  `domain.startswith(...)`, no `isinstance(..., SomeTask)` and no `hasattr(learner, ...)`;
- no module uses another hipref module's private name: no `from hipref.x import _y`, no `x._y` on a name
  imported from another hipref module, and no `obj._y` (obj not self, cls or super()) of a private name only
  another hipref module defines."""

from __future__ import annotations

import ast
import json
from functools import cache
from pathlib import Path

import pytest

import hipref

PACKAGE = Path(hipref.__file__).resolve().parent
NOTEBOOKS = sorted((PACKAGE.parent / "notebooks").glob("[0-9][0-9]_*.ipynb"))

REGISTRIES = {"hipref/experiments/domains.py", "hipref/experiments/si_methods.py"}
"""The registries: the domains' (`DOMAINS`) and the SI methods' (`LEARNERS`)."""
NAMES = {"domain", "method"}
"""What a variable or attribute holding a domain's or a method's name is called."""


@cache
def sources() -> dict[str, str]:
    """Every hipref module's source, by its path from the checkout."""
    return {str(path.relative_to(PACKAGE.parent)): path.read_text() for path in sorted(PACKAGE.rglob("*.py"))}


def notebook_code(path: Path) -> str:
    """A notebook's code cells as one module (IPython's magics and shell lines left out)."""
    cells = json.loads(path.read_text())["cells"]
    lines = [
        line
        for cell in cells
        if cell["cell_type"] == "code"
        for line in "".join(cell["source"]).splitlines()
        if not line.lstrip().startswith(("%", "!"))
    ]
    return "\n".join(lines)


def is_name(node: ast.AST) -> bool:
    return (isinstance(node, ast.Name) and node.id in NAMES) or (
        isinstance(node, ast.Attribute) and node.attr in NAMES
    )


def is_literal(node: ast.AST) -> bool:
    if isinstance(node, ast.Constant):
        return isinstance(node.value, str)
    return (
        isinstance(node, ast.Tuple | ast.List | ast.Set)
        and bool(node.elts)
        and all(map(is_literal, node.elts))
    )


def row_filters(tree: ast.AST) -> set[int]:
    """The nodes of row filters (`rows[rows.domain == "wiping"]`, `(rows.method == m) & ...`,
    `(rows.method == "osi").any()`, `np.where(rows.method == m, ...)`): selecting rows of a results frame,
    not branching."""
    inside: set[int] = set()
    for node in ast.walk(tree):
        parts: list[ast.AST] = []
        if isinstance(node, ast.Subscript):
            parts = [node.slice]
        elif isinstance(node, ast.BinOp) and isinstance(node.op, ast.BitAnd | ast.BitOr):
            parts = [node.left, node.right]
        elif isinstance(node, ast.Attribute) and isinstance(node.value, ast.Compare):
            parts = [node.value]
        elif (
            isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr == "where"
        ):
            parts = node.args[:1]
        inside |= {id(n) for part in parts for n in ast.walk(part)}
    return inside


def branches(source: str) -> list[str]:
    """Each branch on a domain's or a method's name in `source`, as its line and code."""
    tree = ast.parse(source)
    filters = row_filters(tree)
    found = []
    for node in ast.walk(tree):
        hit = False
        if isinstance(node, ast.Compare) and id(node) not in filters:
            operands = [node.left, *node.comparators]
            hit = any(map(is_name, operands)) and any(map(is_literal, operands))
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
            hit = node.func.attr in ("startswith", "endswith") and is_name(node.func.value)
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and len(node.args) == 2:
            first, second = node.args
            if node.func.id == "isinstance":
                classes = second.elts if isinstance(second, ast.Tuple) else [second]
                hit = any(isinstance(c, ast.Name) and c.id.endswith("Task") for c in classes)
            elif node.func.id == "hasattr":
                hit = isinstance(first, ast.Name | ast.Attribute) and "learner" in ast.unparse(first)
        if hit:
            found.append(f"{node.lineno}: {ast.unparse(node)}")
    return found


@pytest.mark.parametrize("path", sorted(set(sources()) - REGISTRIES))
def test_no_branch_on_domain_or_method_in_the_package(path: str) -> None:
    assert branches(sources()[path]) == [], f"{path} branches on a name: look it up in the registry"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda p: p.name)
def test_no_branch_on_domain_or_method_in_the_notebooks(path: Path) -> None:
    assert branches(notebook_code(path)) == [], f"{path.name} branches on a name: read DOMAINS instead"


@pytest.mark.parametrize(
    "code",
    [
        'detail = "force_mean" if domain == "wiping" else "goal_distance"',
        'if cell.method == "osi":\n    pass',
        'ok = method not in ("bayes", "bayes_si")',
        'rows = [m for m in methods if not m.startswith("co_pesi") or method.startswith("co_pesi")]',
        "assert isinstance(task, PushingTask)",
        'if hasattr(learner, "filter_precision_recall"):\n    pass',
        'compliant = cell.method == "admittance"',
    ],
)
def test_each_kind_of_branch_is_found(code: str) -> None:
    assert branches(code), code


def test_row_filters_are_not_branches() -> None:
    code = 'part = rows[(rows.domain == "wiping") & (rows.method == m)]\nx = (rows.method == "osi").any()'
    code += '\ny = np.where(rows.method == "bayes", 4, 1)'
    assert branches(code) == []


def module_of(path: str) -> str:
    parts = Path(path).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


@cache
def defined_privates(source: str) -> frozenset[str]:
    """The private names a module defines: module-level names, functions, methods and `self._x`."""
    names = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef | ast.ClassDef):
            names.add(node.name)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            names.add(node.id)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            names.add(node.attr)
    return frozenset(name for name in names if private(name))


def private_uses(path: str, source: str, others: set[str]) -> list[str]:
    """Each use in `source` of another hipref module's private name; `others`: the private names only
    other hipref modules define."""
    tree = ast.parse(source)
    imported: set[str] = set()
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("hipref"):
            imported |= {alias.asname or alias.name for alias in node.names}
            found += [f"{node.lineno}: import {a.name}" for a in node.names if private(a.name)]
        elif isinstance(node, ast.Import):
            imported |= {
                alias.asname or alias.name for alias in node.names if alias.name.startswith("hipref")
            }
    for node in ast.walk(tree):
        if not (isinstance(node, ast.Attribute) and private(node.attr)):
            continue
        owner = node.value
        if isinstance(owner, ast.Name) and owner.id in ("self", "cls"):
            continue
        if isinstance(owner, ast.Call) and isinstance(owner.func, ast.Name) and owner.func.id == "super":
            continue
        if (isinstance(owner, ast.Name) and owner.id in imported) or node.attr in others:
            found.append(f"{node.lineno}: {ast.unparse(node)}")
    return found


@pytest.mark.parametrize("path", sorted(sources()))
def test_no_private_name_used_across_modules(path: str) -> None:
    texts = sources()
    mine = defined_privates(texts[path])
    others = set().union(*(defined_privates(t) for p, t in texts.items() if p != path)) - mine
    assert private_uses(path, texts[path], others) == [], f"{path} uses another module's private name"


@pytest.mark.parametrize(
    "code",
    [
        "from hipref.sweep.cache import _hidden",
        "from hipref import sweep\nx = sweep._ARTEFACTS",
        "from hipref.learners.coteaching import CoPESILearner\nCoPESILearner._learn(learner)",
        "indices = learner._indices",
    ],
)
def test_each_kind_of_private_use_is_found(code: str) -> None:
    assert private_uses("hipref/x.py", code, {"_indices"}), code


def test_own_and_foreign_privates_pass() -> None:
    code = "import os\nself._indices = []\nsuper()._learn()\nos._exit(0)\nmodel._address"
    assert private_uses("hipref/x.py", code, {"_indices"}) == []

"""The package's floors: each room (a subpackage or a top-level module of hipref) imports only from the
floors below it, read from the source (imports inside functions and under TYPE_CHECKING included), and what
a room reaches through the modules it imports (package `__init__`s included) keeps learners free of physics
and the sweep free of tasks. No module holds more than LONGEST_MODULE lines."""

from __future__ import annotations

import ast
from functools import cache
from pathlib import Path

import pytest

import hipref

PACKAGE = Path(hipref.__file__).resolve().parent

FLOORS: tuple[tuple[str, ...], ...] = (
    ("numerics", "seeds", "validation", "plots", "kernel"),
    ("intervals",),
    ("verdicts",),
    ("results",),
    ("sim", "teachers", "sweep", "notebook", "run_notebook"),
    ("control", "learners"),
    ("envs",),
    ("experiments",),
    ("teach", "readme_format"),
    ("readme_noise", "readme_beyond", "readme_answers"),
    ("readme",),
    ("bench",),
)
"""The rooms of each floor, from the ground up: the foundations (seeds, checks, numerics); the bootstrap
intervals; the verdicts read from them; the results, whose claims carry verdicts; the scene, the teachers,
the sweep and the notebooks' machinery; the controllers and the learners (no physics); the tasks; the
studies that compose them; a person teaching in JupyterLab and the README's formatting; the README's numbers
read from the studies' results, by group; the README itself; the benchmarks. `hipref/__init__.py` is on the
ground floor and imports only from it."""

NEVER: dict[str, tuple[str, ...]] = {
    "learners": ("hipref.envs", "hipref.sim", "hipref.control", "mujoco"),
    "teachers": ("hipref.envs", "hipref.sim", "hipref.control", "mujoco"),
    "sweep": ("hipref.envs", "mujoco"),
    "control": ("hipref.teachers",),
    "envs": ("hipref.teachers", "hipref.learners"),
}
"""Modules a room must not reach, directly or through what it imports, though they are below it: an
algorithm holds no physics, the sweep runs any cell without loading a task, and the physics knows nothing of
who teaches or learns."""


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def room_of(module: str) -> str:
    """`hipref.envs.wiping` -> `envs`; the root package is the room `hipref`."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "hipref"


SOURCES: dict[str, Path] = {module_name(path): path for path in sorted(PACKAGE.rglob("*.py"))}

LONGEST_MODULE = 400
"""Most lines a module of hipref may have: past it, a module holds more than one topic and is split."""


@cache
def direct_imports(module: str) -> frozenset[str]:
    """Every module `module`'s source imports, by its full name, a hipref module resolved to the module
    that holds the name (`from hipref.envs import task` is `hipref.envs.task`)."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(SOURCES[module].read_bytes())):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            assert node.level == 0 and node.module, f"{module}: a relative import"
            names.add(node.module)
            names.update(
                f"{node.module}.{alias.name}"
                for alias in node.names
                if f"{node.module}.{alias.name}" in SOURCES
            )
    return frozenset(names)


def executed(module: str) -> set[str]:
    """The hipref modules Python executes to import `module`: each package on its path, then itself."""
    parts = module.split(".")
    return {".".join(parts[:i]) for i in range(1, len(parts) + 1)} & set(SOURCES)


@cache
def reached(module: str) -> frozenset[str]:
    """Every module (hipref's and others') that importing `module` imports, through every hipref module
    it runs on the way."""
    seen: set[str] = set()
    names: set[str] = set()
    todo = sorted(executed(module))
    while todo:
        current = todo.pop()
        if current in seen:
            continue
        seen.add(current)
        for name in direct_imports(current):
            names.add(name)
            todo += sorted(executed(name) - seen)
    return frozenset(names | seen)


def floor_of(room: str) -> int:
    if room == "hipref":
        return 0
    floors = [level for level, rooms in enumerate(FLOORS) if room in rooms]
    assert floors, f"hipref/{room} is on no floor: add it to FLOORS in {Path(__file__).name}"
    return floors[0]


def test_every_room_is_on_exactly_one_floor() -> None:
    rooms = {room_of(module) for module in SOURCES} - {"hipref"}
    listed = [room for floor in FLOORS for room in floor]
    assert sorted(listed) == sorted(set(listed)), "a room is on two floors"
    assert rooms == set(listed), f"rooms without a floor: {rooms - set(listed)}; gone: {set(listed) - rooms}"


def test_no_room_imports_from_its_own_floor_or_above() -> None:
    offending = sorted(
        f"{module} imports {name} (floor {floor_of(room_of(name))} from floor {floor_of(room_of(module))})"
        for module in SOURCES
        for name in direct_imports(module)
        if name.startswith("hipref.")
        and room_of(name) != room_of(module)
        and room_of(module) != "hipref"
        and floor_of(room_of(name)) >= floor_of(room_of(module))
    )
    assert not offending, "\n".join(offending)


def test_the_root_package_imports_only_the_ground_floor() -> None:
    """`import hipref` runs before any room's own code, so anything it imports every room imports."""
    upstairs = sorted(
        name
        for name in direct_imports("hipref")
        if name.startswith("hipref.") and floor_of(room_of(name)) > 0
    )
    assert not upstairs, f"hipref/__init__.py imports {upstairs}"


@pytest.mark.parametrize("room", list(NEVER))
def test_a_room_never_reaches_what_it_must_not(room: str) -> None:
    offending = sorted(
        f"{module} reaches {name}"
        for module in SOURCES
        if room_of(module) == room
        for name in reached(module)
        if any(name == banned or name.startswith(banned + ".") for banned in NEVER[room])
    )
    assert not offending, "\n".join(offending[:20])


def test_no_module_is_longer_than_the_longest_allowed() -> None:
    lengths = {path: len(path.read_text(encoding="utf-8").splitlines()) for path in SOURCES.values()}
    long = sorted(
        f"{path.relative_to(PACKAGE.parent)}: {lines} lines"
        for path, lines in lengths.items()
        if lines > LONGEST_MODULE
    )
    assert not long, f"modules over {LONGEST_MODULE} lines, to split by topic: {long}"

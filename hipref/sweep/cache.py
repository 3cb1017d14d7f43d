"""The sweep's cache: what a cell or an artefact is keyed by, where its entry lives and when an entry is used.

Each finished cell is pickled under the cache directory with a key hashing the function, the config and
the code the rows depend on (`code_version`), so an interrupted sweep resumes where it stopped and a changed
algorithm never reuses stale rows. `cached_artefact` does the same for expensive shared objects (an SI
pre-training dataset, a pretrained model, demonstrations), and `cached_prefix` for lists of them that
studies of different lengths share (evaluation checkpoints, learning clips); both keep what they built or
loaded in memory for the rest of the process (`forget_artefacts` drops it).

A cache entry is used only if it holds what would be computed: it carries the key it was stored under and
a checksum of its payload, which must match (`hipref.sweep.entries`); a cell's entry must be a DataFrame
with the tidy columns, an artefact's whatever its caller's `expect` says; anything else (a damaged, stale,
moved or foreign pickle) is recomputed with a warning. A cache directory that cannot be written is refused
before any compute.

While a sweep's cell runs (`artefacts_in`), the artefacts it builds without a `cache_dir` of their own are
cached in the sweep's directory. Only the standard library is imported at load time.
"""

from __future__ import annotations

import ast
import contextlib
import dataclasses
import enum
import functools
import hashlib
import json
import os
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, TypeVar

import hipref
from hipref.results import TIDY_COLUMNS, repo_root
from hipref.sweep.entries import check_writable, load_entry, write_entry

if TYPE_CHECKING:
    import pandas as pd

T = TypeVar("T")
CellFn = Callable[[Any], "pd.DataFrame"]
CacheDir = str | os.PathLike[str] | Literal[False] | None

NO_CACHE: Literal[False] = False
"""Pass as `cache_dir` to compute everything afresh and store nothing."""

_ARTEFACTS: dict[str, Any] = {}
"""The artefacts built or loaded in this process, by key: every caller gets the same object."""

_SWEEP_CACHE_DIR: CacheDir = None
"""While a sweep's cell runs in this process, the sweep's cache directory: the artefacts the cell builds
(`cached_artefact` without a `cache_dir`) are cached there too."""

NOT_IN_ROWS: tuple[str, ...] = (
    "bench",
    "notebook.py",
    "plots.py",
    "intervals.py",
    "verdicts.py",
    "readme.py",
    "readme_answers.py",
    "readme_beyond.py",
    "readme_format.py",
    "readme_noise.py",
)
"""The package's modules no row depends on (benchmarks, notebook parameters, figures, intervals, verdicts,
the README's numbers): editing them keeps every cached cell."""


@functools.cache
def code_version() -> str:
    """`hipref.__version__` plus a hash of the code every row may depend on, computed once per process.

    The hash covers each `.py` file of the package but those of NOT_IN_ROWS, as its syntax tree without
    docstrings (comments are not in the tree): editing documentation keeps the cache, while any edit to
    the code invalidates every cached cell, coarse but safe: a cached result can never come from code
    other than the code that would compute it now.
    """
    package = Path(hipref.__file__).resolve().parent
    digest = hashlib.sha256()
    for source in sorted(package.rglob("*.py")):
        relative = source.relative_to(package)
        if relative.parts[0] in NOT_IN_ROWS:
            continue
        digest.update(relative.as_posix().encode() + b"\0")
        digest.update(ast.dump(without_docstrings(ast.parse(source.read_bytes()))).encode() + b"\0")
    return f"{hipref.__version__}+{digest.hexdigest()[:16]}"


def without_docstrings(tree: ast.Module) -> ast.Module:
    """`tree` without its string statements: module, class, function and attribute docstrings."""
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if isinstance(body, list):
            kept = [
                statement
                for statement in body
                if not (
                    isinstance(statement, ast.Expr)
                    and isinstance(statement.value, ast.Constant)
                    and isinstance(statement.value.value, str)
                )
            ]
            body[:] = kept or [ast.Pass()]
    return tree


def default_cache_dir() -> Path:
    """`$HIPREF_CACHE_DIR`, else `<checkout>/.cache/hipref` in a source checkout, else `~/.cache/hipref`."""
    if env := os.environ.get("HIPREF_CACHE_DIR"):
        return Path(env)
    root = repo_root()
    return (root / ".cache" if root is not None else Path.home() / ".cache") / "hipref"


def resolve_cache_dir(cache_dir: CacheDir) -> Path | None:
    if cache_dir is False:
        return None
    return default_cache_dir() if cache_dir is None else Path(cache_dir)


def _jsonable(value: Any) -> Any:
    """Turn what json cannot encode into a stable equivalent; refuse anything without one."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return _describe(value)
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    if hasattr(value, "tolist"):  # numpy scalars and arrays
        return value.tolist()
    raise TypeError(f"cannot hash a config holding {type(value).__name__}: {value!r}")


def _describe(config: Any) -> dict[str, Any]:
    """The identity of a config: its class and its fields (a dataclass) or its value (anything JSON)."""
    if dataclasses.is_dataclass(config) and not isinstance(config, type):
        kind = type(config)
        return {"class": f"{kind.__module__}.{kind.__qualname__}", "fields": dataclasses.asdict(config)}
    return {"class": type(config).__qualname__, "value": config}


def _key(*parts: Any) -> str:
    canonical = json.dumps([*parts, code_version()], sort_keys=True, separators=(",", ":"), default=_jsonable)
    return hashlib.sha256(canonical.encode()).hexdigest()


def cell_key(fn: CellFn, cell: Any) -> str:
    """The cache key of one cell: sha256 of the function's name, the config and `code_version()`.

    The entry lives at `<cache_dir>/cells/<key>.pkl`.
    """
    if not (dataclasses.is_dataclass(cell) and not isinstance(cell, type)):
        raise TypeError(f"a cell must be a dataclass instance (a frozen config), got {type(cell).__name__}")
    return _key(f"{fn.__module__}.{fn.__qualname__}", _describe(cell))


@dataclasses.dataclass(frozen=True)
class Expect:
    """What a cached artefact must be for a copy loaded from disk to be used (see `cached_artefact`)."""

    kind: type | tuple[type, ...]
    """The type (or types) the artefact is an instance of."""
    check: Callable[[Any], bool] | None = None
    """Further test of a value of that type, such as its shapes or length: true for what `build` makes.
    A check that raises counts as failed."""

    def problem(self, value: Any) -> str | None:
        """Why `value` is not such an artefact, or None when it is."""
        if not isinstance(value, self.kind):
            kinds = self.kind if isinstance(self.kind, tuple) else (self.kind,)
            names = " or ".join(kind.__name__ for kind in kinds)
            return f"it holds {type(value).__name__}, expected {names}"
        if self.check is None:
            return None
        name = getattr(self.check, "__qualname__", repr(self.check))
        try:
            ok = self.check(value)
        except Exception as err:
            return f"its check {name} raised {err!r}"
        return None if ok else f"it fails its check {name}"


def _rows_problem(rows: Any) -> str | None:
    """Why `rows` is not a valid cell entry (a DataFrame with the tidy columns), or None when it is."""
    import pandas as pd

    if not isinstance(rows, pd.DataFrame):
        return f"it holds {type(rows).__name__}, expected a pandas DataFrame"
    missing = [column for column in TIDY_COLUMNS if column not in rows.columns]
    return f"its rows lack the tidy column(s) {missing}" if missing else None


def load_cell(directory: Path, key: str) -> tuple[bool, Any]:
    """The rows cached under `key` in `directory`: (True, rows), or (False, None) when there is no valid
    entry."""
    return load_entry(directory / "cells" / f"{key}.pkl", key, _rows_problem)


def store_cell(fn: CellFn, directory: Path, key: str, rows: pd.DataFrame) -> None:
    """Cache a cell's rows under `key` in `directory`, unless they could never be loaded back as a valid
    entry."""
    problem = _rows_problem(rows)
    if problem is not None:
        warnings.warn(
            f"rows of {fn.__module__}.{fn.__qualname__} are not cached, as {problem} and a cell entry "
            f"must hold the tidy columns {list(TIDY_COLUMNS)}",
            stacklevel=3,
        )
        return
    write_entry(directory / "cells" / f"{key}.pkl", key, rows)


@contextlib.contextmanager
def artefacts_in(cache_dir: CacheDir) -> Iterator[None]:
    """Within it, the artefacts built without a `cache_dir` of their own are cached in `cache_dir` (what a
    sweep's cell runs under; `NO_CACHE`: none is stored)."""
    global _SWEEP_CACHE_DIR
    before, _SWEEP_CACHE_DIR = _SWEEP_CACHE_DIR, cache_dir
    try:
        yield
    finally:
        _SWEEP_CACHE_DIR = before


def cached_artefact(
    name: str,
    config: Any,
    build: Callable[[], T],
    *,
    cache_dir: CacheDir = None,
    expect: type | tuple[type, ...] | Expect | None = None,
) -> T:
    """Build an expensive shared object once per (name, config, code version) and reuse it.

    Stored as `<cache_dir>/artefacts/<name>-<key>.pkl` (pickle handles torch modules and tensors) and
    kept in memory for the rest of the process, so every caller gets the same object: do not mutate it.
    `expect` (a type, types, or an `Expect` with a check of shapes and lengths) is what the artefact must
    be: an entry that fails to load or holds anything else is rebuilt, with a warning, and a freshly built
    object that does not meet it raises TypeError.
    """
    if not all(c.isalnum() or c in "_.-" for c in name) or not name:
        raise ValueError(f"artefact name must be letters, digits, '_', '.' or '-', got {name!r}")
    if expect is not None and not isinstance(expect, Expect):
        kinds = expect if isinstance(expect, tuple) else (expect,)
        if not kinds or not all(isinstance(kind, type) for kind in kinds):
            raise ValueError(f"expect must be a type, a tuple of types, an Expect or None, got {expect!r}")
        expect = Expect(expect)
    problem = None if expect is None else expect.problem
    key = _key(name, _describe(config))
    if key in _ARTEFACTS:
        return _ARTEFACTS[key]
    directory = resolve_cache_dir(_SWEEP_CACHE_DIR if cache_dir is None else cache_dir)
    check_writable(directory, "artefacts")
    path = None if directory is None else directory / "artefacts" / f"{name}-{key}.pkl"
    found, value = load_entry(path, key, problem)
    if not found:
        value = build()
        reason = None if problem is None else problem(value)
        if reason is not None:
            raise TypeError(f"artefact {name!r} was built but not cached, as {reason}")
        if path is not None:
            write_entry(path, key, value)
    _ARTEFACTS[key] = value
    return value


def cached_prefix(
    name: str,
    config: Any,
    length: int,
    build: Callable[[int], list[T]],
    *,
    check: Callable[[T], bool] | None = None,
    cache_dir: CacheDir = None,
) -> list[T]:
    """The first `length` items of a list artefact whose items do not depend on how many are built (item
    k of a build of n items is item k of any longer build), such as evaluation checkpoints drawn from the
    children of one SeedSequence: a study that needs fewer items than another reads the other's.

    One entry per (name, config), cached like `cached_artefact`'s, serves every length up to its own; a
    request for more builds `build(length)` and replaces it. `check` is what every item must satisfy for
    an entry to be used (an entry that fails it is rebuilt, with a warning)."""
    if length < 0:
        raise ValueError(f"length must be at least 0, got {length}")
    key = _key(name, _describe(config))
    held: list[T] | None = _ARTEFACTS.get(key)
    if held is None or len(held) < length:
        directory = resolve_cache_dir(_SWEEP_CACHE_DIR if cache_dir is None else cache_dir)
        check_writable(directory, "artefacts")
        path = None if directory is None else directory / "artefacts" / f"{name}-{key}.pkl"

        def problem(value: Any) -> str | None:
            if not isinstance(value, list):
                return f"it holds {type(value).__name__}, expected a list"
            if check is not None and not all(check(item) for item in value):
                return "an item fails its check"
            return None

        found, loaded = load_entry(path, key, problem)
        if found and len(loaded) >= length:
            held = loaded
        else:
            held = build(length)
            reason = problem(held)
            if reason is not None or len(held) != length:
                raise TypeError(f"artefact {name!r} was built but not cached, as {reason or 'its length'}")
            if path is not None:
                write_entry(path, key, held)
        _ARTEFACTS[key] = held
    return held[:length]


def forget_artefacts(matching: Callable[[Any], bool] | None = None) -> None:
    """Drop the in-memory copies of `cached_artefact` and `cached_prefix`, all of them or those for which
    `matching(value)` is true (to free memory, or to build them again; the disk cache stays)."""
    for key, value in list(_ARTEFACTS.items()):
        if matching is None or matching(value):
            del _ARTEFACTS[key]

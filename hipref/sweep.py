"""The study's one way to run a grid of runs: cells in parallel, each cached as soon as it finishes.

A *cell* is a frozen dataclass config that carries its own seed; a *cell function* is a module-level
function `fn(cell) -> pandas.DataFrame` of tidy rows. `run_sweep` runs the cells on local worker
processes (all cores by default) or, given a scheduler address, on a Dask cluster, and returns their
rows in the order of the cells. Because every cell seeds itself and runs on one thread, the rows are
byte-identical whichever backend and however many workers.

Each finished cell is pickled under the cache directory with a key hashing the function, the config and
the code the rows depend on (`code_version`), so an interrupted sweep resumes where it stopped and a changed
algorithm never reuses stale rows. `cached_artefact` does the same for expensive shared objects (an SI
pre-training dataset, a pretrained model, demonstrations), and `cached_prefix` for lists of them that
studies of different lengths share (evaluation checkpoints, learning clips).

A cache entry is used only if it holds what would be computed: it carries the key it was stored under and
a checksum of its payload, which must match; a cell's entry must be a DataFrame with the tidy columns, an
artefact's whatever its caller's `expect` says; anything else (a damaged, stale, moved or foreign pickle) is
recomputed with a warning. A cache directory that cannot be written is refused before any compute.

Local workers never outlive the sweep: an interrupted sweep (KeyboardInterrupt, or the loop over its rows
closed early) terminates the cells still running, and a worker whose parent dies (a notebook kernel
killed with SIGKILL) exits at once.

This module imports only the standard library (and tqdm) at load time: a spawned worker runs
`_init_worker` before numpy or torch are loaded, so their one-thread settings take effect.
"""

from __future__ import annotations

import ast
import collections
import contextlib
import dataclasses
import enum
import functools
import hashlib
import json
import multiprocessing
import multiprocessing.connection
import os
import pickle
import signal
import sys
import threading
import traceback
import warnings
from collections.abc import Callable, Generator, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, TypeVar

from tqdm.auto import tqdm

import hipref
from hipref.numerics import one_thread, warn_overrides
from hipref.results import TIDY_COLUMNS, repo_root, write_bytes

if TYPE_CHECKING:
    import pandas as pd

T = TypeVar("T")
CellFn = Callable[[Any], "pd.DataFrame"]
CacheDir = str | os.PathLike[str] | Literal[False] | None
Outcomes = Generator[tuple[str, bool, Any], None, None]  # (cell key, ok, rows or traceback text)

NO_CACHE: Literal[False] = False
"""Pass as `cache_dir` to compute everything afresh and store nothing."""

_THREAD_ENV = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")
_ARTEFACTS: dict[str, Any] = {}

_SWEEP_CACHE_DIR: CacheDir = None
"""While a sweep's cell runs in this process, the sweep's cache directory: the artefacts the cell builds
(`cached_artefact` without a `cache_dir`) are cached there too."""

_PARENT_POLL_SECONDS = 1.0
"""How often a worker checks that its parent still lives, besides being woken when the parent's end of
its start-up pipe closes."""
_ORPHAN_EXIT_CODE = 70
"""Exit status of a worker that stopped because its parent died."""
_PR_SET_PDEATHSIG = 1
"""prctl option (linux/prctl.h): the signal the kernel sends a process when its parent thread exits."""


class SweepError(RuntimeError):
    """Some cells failed; the others ran to the end (and were cached). `failures`: (cell, traceback text);
    `log`: the file holding every traceback in full (None if it could not be written)."""

    def __init__(self, failures: list[tuple[Any, str]], total: int, log: Path | None = None) -> None:
        self.failures = failures
        self.log = log
        shown = ", ".join(repr(cell) for cell, _ in failures[:_CELLS_SHOWN])
        more = f" and {len(failures) - _CELLS_SHOWN} more" if len(failures) > _CELLS_SHOWN else ""
        first_cell, first = failures[0]
        last_lines = "\n".join(first.rstrip().splitlines()[-_LINES_SHOWN:])
        where = f"every traceback in full: {log}" if log else "(the tracebacks could not be logged)"
        super().__init__(
            f"{len(failures)} of {total} cells failed ({shown}{more}); the others ran to the end and, unless"
            " caching is off, were cached: fix the cause and run the sweep again to compute only these.\n"
            f"The first error (cell {first_cell!r}) ends:\n{last_lines}\n{where}"
        )


_CELLS_SHOWN = 3
"""Failed cells a SweepError's message names; the log names all."""
_LINES_SHOWN = 6
"""Last lines of the first failure's traceback a SweepError's message shows."""


def _failure_log(directory: Path | None, desc: str, failures: list[tuple[Any, str]]) -> Path | None:
    """Write every failed cell and its traceback to a new log file (under the cache directory's `logs/`,
    else the system's temporary directory) and return its path; None if it cannot be written."""
    import tempfile
    import time

    text = "".join(f"--- {cell!r}\n{tb.rstrip()}\n\n" for cell, tb in failures)
    name = "".join(c if c.isalnum() else "-" for c in desc)
    stamp = time.strftime("%Y%m%dT%H%M%S")
    try:
        if directory is not None:
            return write_bytes(text.encode(), directory / "logs" / f"{name}-{stamp}-{os.getpid()}.log")
        fd, path = tempfile.mkstemp(prefix=f"hipref-{name}-{stamp}-", suffix=".log")
        with open(fd, "w") as f:
            f.write(text)
        return Path(path)
    except OSError:
        return None


NOT_IN_ROWS: tuple[str, ...] = ("bench", "notebook.py", "plots.py", "verdicts.py")
"""The package's modules no row depends on (benchmarks, notebook parameters, figures, verdicts): editing
them keeps every cached cell."""


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
        digest.update(ast.dump(_without_docstrings(ast.parse(source.read_bytes()))).encode() + b"\0")
    return f"{hipref.__version__}+{digest.hexdigest()[:16]}"


def _without_docstrings(tree: ast.Module) -> ast.Module:
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
            node.body = kept or [ast.Pass()]  # type: ignore[attr-defined]
    return tree


def default_cache_dir() -> Path:
    """`$HIPREF_CACHE_DIR`, else `<checkout>/.cache/hipref` in a source checkout, else `~/.cache/hipref`."""
    if env := os.environ.get("HIPREF_CACHE_DIR"):
        return Path(env)
    root = repo_root()
    return (root / ".cache" if root is not None else Path.home() / ".cache") / "hipref"


def _resolve_cache_dir(cache_dir: CacheDir) -> Path | None:
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


_ENTRY_FORMAT = "hipref-cache-1"
"""Marks a cache entry: a pickled dict of this format, the key it was stored under, the sha256 of its
payload and the payload (the pickled value)."""


def write_entry(path: Path, key: str, value: Any) -> None:
    """Store `value` at `path` (atomically) as an entry of `key`."""
    payload = pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL)
    entry = {
        "format": _ENTRY_FORMAT,
        "key": key,
        "sha256": hashlib.sha256(payload).hexdigest(),
        "payload": payload,
    }
    write_bytes(pickle.dumps(entry, protocol=pickle.HIGHEST_PROTOCOL), path)


def read_entry(path: Path) -> tuple[str, Any]:
    """(key, value) of the entry at `path`; ValueError when it is no intact entry."""
    with path.open("rb") as f:
        entry = pickle.load(f)
    if not (isinstance(entry, dict) and entry.get("format") == _ENTRY_FORMAT):
        raise ValueError(
            f"it is no cache entry (a bare {type(entry).__name__}, without the key it was stored under)"
        )
    payload = entry["payload"]
    if hashlib.sha256(payload).hexdigest() != entry["sha256"]:
        raise ValueError("its payload does not match its checksum")
    return entry["key"], pickle.loads(payload)


def _load(path: Path, key: str, problem: Callable[[Any], str | None] | None = None) -> tuple[bool, Any]:
    """Read the cache entry of `key`; (False, None) when absent, unreadable, stored under another key or,
    by `problem`, not what it should hold, with a warning in the last three cases."""
    if not path.exists():
        return False, None
    try:
        stored, value = read_entry(path)
    except Exception as err:
        reason: str | None = f"it is unreadable: {err}"
    else:
        if stored != key:
            reason = f"it was stored under the key {stored[:16]}..., not this entry's {key[:16]}..."
        else:
            reason = None if problem is None else problem(value)
    if reason is not None:
        warnings.warn(f"ignoring cache entry {path}: {reason}; recomputing it", stacklevel=3)
        return False, None
    return True, value


def check_writable(cache: Path | None, part: str) -> None:
    """Refuse, before any compute, a cache directory whose `part` (cells, artefacts) cannot take entries:
    not creatable, not a directory, or not writable (a file written and removed in it proves it)."""
    if cache is None:
        return
    directory = cache / part
    try:
        directory.mkdir(parents=True, exist_ok=True)
        probe = directory / f".write-check.{os.getpid()}.tmp"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as err:
        raise PermissionError(
            f"the cache directory {directory} cannot be written ({err.strerror or err}); set "
            "HIPREF_CACHE_DIR (or cache_dir=) to a writable directory, or pass cache_dir=NO_CACHE"
        ) from None


def _init_worker() -> None:
    """Worker initializer: one thread per run, so parallel runs do not oversubscribe the cores and
    floating-point reductions happen in one order whatever the machine; and the worker ends with its
    parent."""
    os.environ.update(dict.fromkeys(_THREAD_ENV, "1"))
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(1)
    _exit_with_parent()


def _exit_with_parent() -> None:
    """Make this worker process exit as soon as the process that started it dies.

    A pool's idle workers wait on a queue that their parent alone would close, and busy ones run their
    cell to the end: after a SIGKILL to the parent (a notebook kernel killed, an out-of-memory kill) they
    would be left running. On Linux the kernel kills the worker when its parent exits (PR_SET_PDEATHSIG:
    strictly, when the parent *thread* that started it exits, which is the thread iterating the sweep,
    alive until the pool has shut down). Elsewhere, and as a second line, a watchdog thread wakes when
    the parent's end of the start-up pipe closes, or notices the parent pid change, and exits; it needs
    the interpreter lock, so compiled code that holds it delays it."""
    parent = multiprocessing.parent_process()
    if parent is None:  # not started by multiprocessing: nothing to watch
        return
    if sys.platform.startswith("linux"):
        import ctypes

        with contextlib.suppress(OSError, AttributeError):
            ctypes.CDLL(None, use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)

    # The watchdog also covers a parent that died before the death signal was armed: its first wait
    # returns at once.
    def watch() -> None:
        while not multiprocessing.connection.wait([parent.sentinel], timeout=_PARENT_POLL_SECONDS):
            if os.getppid() != parent.pid:
                break
        os._exit(_ORPHAN_EXIT_CODE)

    threading.Thread(target=watch, name="hipref-sweep-parent-watch", daemon=True).start()


@contextlib.contextmanager
def _artefacts_in(cache_dir: CacheDir) -> Iterator[None]:
    global _SWEEP_CACHE_DIR
    before, _SWEEP_CACHE_DIR = _SWEEP_CACHE_DIR, cache_dir
    try:
        yield
    finally:
        _SWEEP_CACHE_DIR = before


def _run_cell(fn: CellFn, cell: Any, cache_dir: CacheDir = None) -> tuple[bool, Any]:
    """Run one cell wherever it lands; (True, rows) or (False, the traceback text).

    Failures come back as text rather than exceptions so the remaining cells keep running and the
    report can show where each failing cell broke, even from another machine.
    """
    import pandas as pd

    try:
        with one_thread(), _artefacts_in(cache_dir):
            rows = fn(cell)
        if not isinstance(rows, pd.DataFrame):
            raise TypeError(f"{fn.__qualname__} returned {type(rows).__name__}, not a pandas DataFrame")
    except Exception:
        return False, traceback.format_exc()
    return True, rows


def _run_local(fn: CellFn, cells: dict[str, Any], workers: int, cache_dir: CacheDir) -> Outcomes:
    """Yield (key, ok, result) as cells finish, in-process or on a pool of spawned processes.

    A worker process that dies (killed, out of memory) breaks the pool and loses every cell it had not
    finished; those cells run once more on a fresh pool, and fail only if they are lost again."""
    if workers <= 1 or len(cells) <= 1:
        for key, cell in cells.items():
            yield key, *_run_cell(fn, cell, cache_dir)
        return
    lost = yield from _run_pool(fn, cells, workers, cache_dir)
    if lost:
        warnings.warn(
            f"{len(lost)} cell(s) lost their worker process (killed, out of memory): running them again",
            stacklevel=2,
        )
        lost_again = yield from _run_pool(fn, {key: cells[key] for key in lost}, workers, cache_dir)
        for key, text in lost_again.items():
            yield key, False, text


def _run_pool(
    fn: CellFn, cells: dict[str, Any], workers: int, cache_dir: CacheDir
) -> Generator[tuple[str, bool, Any], None, dict[str, str]]:
    """Yield (key, ok, result) of the cells that finish on one pool; return {key: traceback} of those
    whose worker died."""
    from concurrent.futures.process import BrokenProcessPool

    # "spawn" starts clean interpreters: safe under Jupyter and with torch, where fork can deadlock.
    context = multiprocessing.get_context("spawn")
    pool = ProcessPoolExecutor(min(workers, len(cells)), mp_context=context, initializer=_init_worker)
    finished = False
    lost: dict[str, str] = {}
    try:
        futures = {pool.submit(_run_cell, fn, cell, cache_dir): key for key, cell in cells.items()}
        for future in as_completed(futures):
            try:
                outcome = future.result()
            except BrokenProcessPool:
                lost[futures[future]] = traceback.format_exc()
                continue
            except Exception:  # the cell's rows could not be sent back (e.g. not picklable)
                outcome = (False, traceback.format_exc())
            yield futures[future], *outcome
        finished = True
    finally:
        if not finished:
            # Interrupted (KeyboardInterrupt, or the caller stopped reading): nobody will read the rows of
            # the running cells, so stop them rather than wait for them.
            _terminate_workers(pool)
        pool.shutdown(wait=True, cancel_futures=True)
    return lost


def _terminate_workers(pool: ProcessPoolExecutor) -> None:
    """Terminate a pool's worker processes (Python 3.14 has `terminate_workers`; 3.11 keeps them in
    `_processes`)."""
    terminate = getattr(pool, "terminate_workers", None)
    if terminate is not None:
        terminate()
        return
    for process in list((getattr(pool, "_processes", None) or {}).values()):
        process.terminate()


def _run_dask(fn: CellFn, cells: dict[str, Any], scheduler: str, cache_dir: CacheDir) -> Outcomes:
    """Yield (key, ok, result) as cells finish on a Dask cluster.

    Dask's nanny already starts workers with OMP/MKL/OpenBLAS at one thread; `_run_cell` sets torch's.
    Start workers with `--nthreads 1` so that one worker process runs one cell at a time.
    """
    import distributed

    with distributed.Client(scheduler) as client:
        futures = {
            client.submit(_run_cell, fn, cell, cache_dir, pure=False): key for key, cell in cells.items()
        }
        for future in distributed.as_completed(futures):
            try:
                yield futures[future], *future.result()
            except Exception:  # the task was lost, e.g. its worker died repeatedly
                yield futures[future], False, traceback.format_exc()


def _store_rows(fn: CellFn, path: Path, key: str, rows: pd.DataFrame) -> None:
    """Cache a cell's rows, unless they could never be loaded back as a valid entry."""
    problem = _rows_problem(rows)
    if problem is not None:
        warnings.warn(
            f"rows of {fn.__module__}.{fn.__qualname__} are not cached, as {problem} and a cell entry "
            f"must hold the tidy columns {list(TIDY_COLUMNS)}",
            stacklevel=3,
        )
        return
    write_entry(path, key, rows)


def _check_sweep_input(fn: CellFn, workers: Any) -> None:
    """Refuse, before any compute, a `workers` that is no whole number of at least 1, and an `fn` that
    workers cannot import by name (a lambda or a nested function, which would also share a cache key with
    any other of its name)."""
    if workers is not None and (not isinstance(workers, int) or isinstance(workers, bool) or workers < 1):
        raise ValueError(f"workers must be an integer at least 1 or None, got {workers!r}")
    name = getattr(fn, "__qualname__", None)
    if not callable(fn) or name is None or "<" in name:
        raise ValueError(f"fn must be a module-level function (workers import it by name), got {fn!r}")


def run_sweep(
    fn: CellFn,
    cells: Sequence[Any],
    *,
    cache_dir: CacheDir = None,
    scheduler: str | None = None,
    workers: int | None = None,
    desc: str = "sweep",
) -> pd.DataFrame:
    """Run `fn` on every cell and return all rows, in the order of `cells`, with a fresh index.

    `fn` must be a module-level function (workers import it by name). `cache_dir=None` uses
    `default_cache_dir()`; `NO_CACHE` (False) disables caching. The artefacts the cells build
    (`cached_artefact`) are cached in the same directory. `scheduler` (or `$HIPREF_DASK_SCHEDULER`)
    is a Dask scheduler address such as `tcp://127.0.0.1:8786`; without one the cells run on `workers`
    local processes (default: all cores), or in this process when one worker or one cell remains.
    Cells that fail do not stop the others; `SweepError` lists them once everything else is done.
    """
    import pandas as pd

    _check_sweep_input(fn, workers)
    directory = _resolve_cache_dir(cache_dir)
    check_writable(directory, "cells")
    warn_overrides()
    cells_cache: CacheDir = NO_CACHE if directory is None else directory  # where the cells' artefacts go
    keys = [cell_key(fn, cell) for cell in cells]
    done: dict[str, pd.DataFrame] = {}
    if directory is not None:
        for key in dict.fromkeys(keys):
            found, rows = _load(directory / "cells" / f"{key}.pkl", key, _rows_problem)
            if found:
                done[key] = rows
    # Equal cells share a key and are computed once.
    pending = {key: cell for key, cell in zip(keys, cells, strict=True) if key not in done}
    count = collections.Counter(keys)

    failures: dict[str, str] = {}
    initial = len(cells) - sum(count[key] for key in pending)
    with tqdm(total=len(cells), initial=initial, desc=desc, unit="cell", file=sys.stderr) as bar:
        if pending:
            address = scheduler or os.environ.get("HIPREF_DASK_SCHEDULER")
            if address:
                finished = _run_dask(fn, pending, address, cells_cache)
            else:
                finished = _run_local(fn, pending, workers or os.cpu_count() or 1, cells_cache)
            # closing() shuts the pool or client down at once if this loop is interrupted.
            with contextlib.closing(finished):
                for key, ok, result in finished:
                    if ok:
                        done[key] = result
                        if directory is not None:
                            _store_rows(fn, directory / "cells" / f"{key}.pkl", key, result)
                    else:
                        failures[key] = result
                    bar.update(count[key])
    if failures:
        failed = [(cell, failures[key]) for key, cell in pending.items() if key in failures]
        raise SweepError(failed, len(cells), _failure_log(directory, desc, failed))
    if not cells:
        return pd.DataFrame()
    return pd.concat([done[key] for key in keys], ignore_index=True)


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
    directory = _resolve_cache_dir(_SWEEP_CACHE_DIR if cache_dir is None else cache_dir)
    check_writable(directory, "artefacts")
    path = None if directory is None else directory / "artefacts" / f"{name}-{key}.pkl"
    found, value = (False, None) if path is None else _load(path, key, problem)
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
    held = _ARTEFACTS.get(key)
    if held is None or len(held) < length:
        directory = _resolve_cache_dir(_SWEEP_CACHE_DIR if cache_dir is None else cache_dir)
        check_writable(directory, "artefacts")
        path = None if directory is None else directory / "artefacts" / f"{name}-{key}.pkl"

        def problem(value: Any) -> str | None:
            if not isinstance(value, list):
                return f"it holds {type(value).__name__}, expected a list"
            if check is not None and not all(check(item) for item in value):
                return "an item fails its check"
            return None

        found, held = (False, None) if path is None else _load(path, key, problem)
        if not found or len(held) < length:
            held = build(length)
            reason = problem(held)
            if reason is not None or len(held) != length:
                raise TypeError(f"artefact {name!r} was built but not cached, as {reason or 'its length'}")
            if path is not None:
                write_entry(path, key, held)
        _ARTEFACTS[key] = held
    return held[:length]


def forget_artefacts() -> None:
    """Drop the in-memory copies of `cached_artefact` (to free memory; the disk cache stays)."""
    _ARTEFACTS.clear()

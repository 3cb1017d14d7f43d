"""The study's one way to run a grid of runs: cells in parallel, each cached as soon as it finishes.

A *cell* is a frozen dataclass config that carries its own seed; a *cell function* is a module-level
function `fn(cell) -> pandas.DataFrame` of tidy rows. `run_sweep` runs the cells on local worker
processes (all cores by default) or, given a scheduler address, on a Dask cluster, and returns their
rows in the order of the cells. Because every cell seeds itself and runs on one thread, the rows are
byte-identical whichever backend and however many workers.

Each finished cell is pickled under the cache directory with a key hashing the function, the config and
the package's source (`code_version`), so an interrupted sweep resumes where it stopped and a changed
algorithm never reuses stale rows. `cached_artefact` does the same for expensive shared objects (an SI
pre-training dataset, a pretrained model, demonstrations).

This module imports only the standard library (and tqdm) at load time: a spawned worker runs
`_init_worker` before numpy or torch are loaded, so their one-thread settings take effect.
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import enum
import functools
import hashlib
import json
import multiprocessing
import os
import pickle
import sys
import traceback
import warnings
from collections.abc import Callable, Generator, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, TypeVar

from tqdm.auto import tqdm

import hipref
from hipref.results import repo_root, write_bytes

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


class SweepError(RuntimeError):
    """Some cells failed; the others ran to the end (and were cached). `failures`: (cell, traceback text)."""

    def __init__(self, failures: list[tuple[Any, str]], total: int) -> None:
        self.failures = failures
        parts = [
            f"{len(failures)} of {total} cells failed; the others ran to the end and, unless caching"
            " is off, were cached: fix the cause and run the sweep again to compute only these."
        ]
        parts += [f"\n--- {cell!r}\n{tb.rstrip()}" for cell, tb in failures]
        super().__init__("\n".join(parts))


@functools.cache
def code_version() -> str:
    """`hipref.__version__` plus a hash of every `.py` file of the package, computed once per process.

    Any edit to the package invalidates every cached cell: coarse, but a cached result can never come
    from code other than the code that would compute it now.
    """
    package = Path(hipref.__file__).resolve().parent
    digest = hashlib.sha256()
    for source in sorted(package.rglob("*.py")):
        digest.update(source.relative_to(package).as_posix().encode() + b"\0")
        digest.update(source.read_bytes() + b"\0")
    return f"{hipref.__version__}+{digest.hexdigest()[:16]}"


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


def _load(path: Path, expected: type | None = None) -> tuple[bool, Any]:
    """Read a cache entry; (False, None) when absent or unreadable, with a warning in the second case."""
    if not path.exists():
        return False, None
    try:
        with path.open("rb") as f:
            value = pickle.load(f)
        if expected is not None and not isinstance(value, expected):
            raise TypeError(f"holds {type(value).__name__}, expected {expected.__name__}")
    except Exception as err:
        warnings.warn(f"ignoring unreadable cache entry {path} ({err!r}); recomputing it", stacklevel=3)
        return False, None
    return True, value


def _store(path: Path, value: Any) -> None:
    write_bytes(pickle.dumps(value, protocol=pickle.HIGHEST_PROTOCOL), path)


def _init_worker() -> None:
    """Worker initializer: one thread per run, so parallel runs do not oversubscribe the cores and
    floating-point reductions happen in one order whatever the machine."""
    os.environ.update(dict.fromkeys(_THREAD_ENV, "1"))
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(1)


@contextlib.contextmanager
def _one_torch_thread() -> Iterator[None]:
    """Run torch single-threaded for the duration of a cell and restore the caller's setting after
    (the in-process path runs inside the user's kernel)."""
    torch = sys.modules.get("torch")
    if torch is None:
        yield
        return
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def _run_cell(fn: CellFn, cell: Any) -> tuple[bool, Any]:
    """Run one cell wherever it lands; (True, rows) or (False, the traceback text).

    Failures come back as text rather than exceptions so the remaining cells keep running and the
    report can show where each failing cell broke, even from another machine.
    """
    import pandas as pd

    try:
        with _one_torch_thread():
            rows = fn(cell)
        if not isinstance(rows, pd.DataFrame):
            raise TypeError(f"{fn.__qualname__} returned {type(rows).__name__}, not a pandas DataFrame")
    except Exception:
        return False, traceback.format_exc()
    return True, rows


def _run_local(fn: CellFn, cells: dict[str, Any], workers: int) -> Outcomes:
    """Yield (key, ok, result) as cells finish, in-process or on a pool of spawned processes."""
    if workers <= 1 or len(cells) <= 1:
        for key, cell in cells.items():
            yield key, *_run_cell(fn, cell)
        return
    # "spawn" starts clean interpreters: safe under Jupyter and with torch, where fork can deadlock.
    context = multiprocessing.get_context("spawn")
    pool = ProcessPoolExecutor(min(workers, len(cells)), mp_context=context, initializer=_init_worker)
    try:
        futures = {pool.submit(_run_cell, fn, cell): key for key, cell in cells.items()}
        for future in as_completed(futures):
            try:
                yield futures[future], *future.result()
            except Exception:  # the worker process died (e.g. out of memory)
                yield futures[future], False, traceback.format_exc()
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _run_dask(fn: CellFn, cells: dict[str, Any], scheduler: str) -> Outcomes:
    """Yield (key, ok, result) as cells finish on a Dask cluster.

    Dask's nanny already starts workers with OMP/MKL/OpenBLAS at one thread; `_run_cell` sets torch's.
    Start workers with `--nthreads 1` so that one worker process runs one cell at a time.
    """
    import distributed

    with distributed.Client(scheduler) as client:
        futures = {client.submit(_run_cell, fn, cell, pure=False): key for key, cell in cells.items()}
        for future in distributed.as_completed(futures):
            try:
                yield futures[future], *future.result()
            except Exception:  # the task was lost, e.g. its worker died repeatedly
                yield futures[future], False, traceback.format_exc()


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
    `default_cache_dir()`; `NO_CACHE` (False) disables caching. `scheduler` (or `$HIPREF_DASK_SCHEDULER`)
    is a Dask scheduler address such as `tcp://127.0.0.1:8786`; without one the cells run on `workers`
    local processes (default: all cores), or in this process when one worker or one cell remains.
    Cells that fail do not stop the others; `SweepError` lists them once everything else is done.
    """
    import pandas as pd

    if workers is not None and workers < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    directory = _resolve_cache_dir(cache_dir)
    keys = [cell_key(fn, cell) for cell in cells]
    done: dict[str, pd.DataFrame] = {}
    if directory is not None:
        for key in dict.fromkeys(keys):
            found, rows = _load(directory / "cells" / f"{key}.pkl", pd.DataFrame)
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
                finished = _run_dask(fn, pending, address)
            else:
                finished = _run_local(fn, pending, workers or os.cpu_count() or 1)
            # closing() shuts the pool or client down at once if this loop is interrupted.
            with contextlib.closing(finished):
                for key, ok, result in finished:
                    if ok:
                        done[key] = result
                        if directory is not None:
                            _store(directory / "cells" / f"{key}.pkl", result)
                    else:
                        failures[key] = result
                    bar.update(count[key])
    if failures:
        raise SweepError(
            [(cell, failures[key]) for key, cell in pending.items() if key in failures], len(cells)
        )
    if not cells:
        return pd.DataFrame()
    return pd.concat([done[key] for key in keys], ignore_index=True)


def cached_artefact(name: str, config: Any, build: Callable[[], T], *, cache_dir: CacheDir = None) -> T:
    """Build an expensive shared object once per (name, config, code version) and reuse it.

    Stored as `<cache_dir>/artefacts/<name>-<key>.pkl` (pickle handles torch modules and tensors) and
    kept in memory for the rest of the process, so every caller gets the same object: do not mutate it.
    An entry that fails to load is rebuilt, with a warning.
    """
    if not all(c.isalnum() or c in "_.-" for c in name) or not name:
        raise ValueError(f"artefact name must be letters, digits, '_', '.' or '-', got {name!r}")
    key = _key(name, _describe(config))
    if key in _ARTEFACTS:
        return _ARTEFACTS[key]
    directory = _resolve_cache_dir(cache_dir)
    path = None if directory is None else directory / "artefacts" / f"{name}-{key}.pkl"
    found, value = (False, None) if path is None else _load(path)
    if not found:
        value = build()
        if path is not None:
            _store(path, value)
    _ARTEFACTS[key] = value
    return value


def forget_artefacts() -> None:
    """Drop the in-memory copies of `cached_artefact` (to free memory; the disk cache stays)."""
    _ARTEFACTS.clear()

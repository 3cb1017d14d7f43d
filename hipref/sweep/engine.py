"""The sweep's engine: cells run on local worker processes (all cores by default) or on a Dask cluster.

Local workers never outlive the sweep: an interrupted sweep (KeyboardInterrupt, or the loop over its rows
closed early) terminates the cells still running, and a worker whose parent dies (a notebook kernel
killed with SIGKILL) exits at once. The cells of a worker that dies (killed, out of memory) run once more
on a fresh pool. A sweep whose cells still fail raises a short `SweepError` and logs every traceback.

This module imports only the standard library (and tqdm) at load time: a spawned worker runs
`_init_worker` before the cells load numpy or torch, so their one-thread settings take effect; what the
parent's main module has already loaded in the worker, `_init_worker` limits where it is (threadpoolctl).
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import multiprocessing
import multiprocessing.connection
import os
import signal
import sys
import threading
import traceback
import warnings
from collections.abc import Generator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import TYPE_CHECKING, Any

from hipref.numerics import one_thread, warn_overrides
from hipref.results import repo_root, write_bytes
from hipref.sweep.cache import (
    NO_CACHE,
    CacheDir,
    CellFn,
    artefacts_in,
    cell_key,
    load_cell,
    resolve_cache_dir,
    store_cell,
)
from hipref.sweep.entries import check_writable
from hipref.sweep.progress import progress
from hipref.validation import check_fields

if TYPE_CHECKING:
    import pandas as pd

Outcomes = Generator[tuple[str, bool, Any], None, None]  # (cell key, ok, rows or traceback text)

_THREAD_ENV = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")

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


def _init_worker() -> None:
    """Worker initializer: one thread per run, so parallel runs do not oversubscribe the cores and
    floating-point reductions happen in one order whatever the machine; and the worker ends with its
    parent.

    The environment reaches the libraries loaded after it; a spawned worker has already imported its
    parent's main module (`python -m hipref.bench.held_out_steps` imports numpy), whose BLAS then runs on
    every core, so the libraries already loaded are limited too (threadpoolctl). Left on two threads each,
    two workers on two cores spun against each other: `python -m hipref.bench.held_out_steps --truths 200
    --draw 3 --seed 903` took 193 s, and 72 s limited, its rows the same."""
    os.environ.update(dict.fromkeys(_THREAD_ENV, "1"))
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(1)
    from threadpoolctl import threadpool_limits

    threadpool_limits(1)
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


def _run_cell(fn: CellFn, cell: Any, cache_dir: CacheDir = None) -> tuple[bool, Any]:
    """Run one cell wherever it lands; (True, rows) or (False, the traceback text).

    Failures come back as text rather than exceptions so the remaining cells keep running and the
    report can show where each failing cell broke, even from another machine.
    """
    import pandas as pd

    try:
        with one_thread(), artefacts_in(cache_dir):
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
    main = sys.modules.get("__main__")
    if main is not None and not hasattr(main, "__spec__"):
        main.__spec__ = None  # IPython's %reset deletes it, and spawn reads it to start each worker
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


def _check_sweep_input(fn: CellFn, cells: Sequence[Any], workers: Any) -> None:
    """Refuse, before any compute, a `workers` that is no whole number of at least 1, and an `fn` that
    workers cannot import by name (a lambda or a nested function, which would also share a cache key with
    any other of its name), and a cell whose field does not meet its annotation (`check_fields`)."""
    if workers is not None and (not isinstance(workers, int) or isinstance(workers, bool) or workers < 1):
        raise ValueError(f"workers must be an integer at least 1 or None, got {workers!r}")
    name = getattr(fn, "__qualname__", None)
    if not callable(fn) or name is None or "<" in name:
        raise ValueError(f"fn must be a module-level function (workers import it by name), got {fn!r}")
    for cell in cells:
        if dataclasses.is_dataclass(cell):
            check_fields(cell, getattr(cell, "SEQUENCES", ()))


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

    _check_sweep_input(fn, cells, workers)
    directory = resolve_cache_dir(cache_dir)
    check_writable(directory, "cells")
    root = repo_root()
    warn_overrides(None if root is None else root / "environment.txt")
    cells_cache: CacheDir = NO_CACHE if directory is None else directory  # where the cells' artefacts go
    keys = [cell_key(fn, cell) for cell in cells]
    done: dict[str, pd.DataFrame] = {}
    if directory is not None:
        for key in dict.fromkeys(keys):
            found, rows = load_cell(directory, key)
            if found:
                done[key] = rows
    # Equal cells share a key and are computed once.
    pending = {key: cell for key, cell in zip(keys, cells, strict=True) if key not in done}
    count = collections.Counter(keys)

    failures: dict[str, str] = {}
    initial = len(cells) - sum(count[key] for key in pending)
    bar = progress(len(cells), initial, desc)
    with contextlib.closing(bar):
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
                            store_cell(fn, directory, key, result)
                    else:
                        failures[key] = result
                    bar.update(count[key])
    if failures:
        failed = [(cell, failures[key]) for key, cell in pending.items() if key in failures]
        raise SweepError(failed, len(cells), _failure_log(directory, desc, failed))
    if not cells:
        return pd.DataFrame()
    return pd.concat([done[key] for key in keys], ignore_index=True)

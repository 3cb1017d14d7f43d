"""The sweep's engine: cells run on local worker processes (all cores by default) or on a Dask cluster.

Local workers never outlive the sweep: an interrupted sweep (KeyboardInterrupt, or the loop over its rows
closed early) terminates the cells still running, and a worker whose parent dies (a notebook kernel
killed with SIGKILL) exits at once.

This module imports only the standard library (and tqdm) at load time: a spawned worker runs
`_init_worker` before numpy or torch are loaded, so their one-thread settings take effect.
"""

from __future__ import annotations

import collections
import contextlib
import multiprocessing
import multiprocessing.connection
import os
import signal
import sys
import threading
import traceback
from collections.abc import Generator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from typing import TYPE_CHECKING, Any

from tqdm.auto import tqdm

from hipref.numerics import one_thread
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
    """Some cells failed; the others ran to the end (and were cached). `failures`: (cell, traceback text)."""

    def __init__(self, failures: list[tuple[Any, str]], total: int) -> None:
        self.failures = failures
        parts = [
            f"{len(failures)} of {total} cells failed; the others ran to the end and, unless caching"
            " is off, were cached: fix the cause and run the sweep again to compute only these."
        ]
        parts += [f"\n--- {cell!r}\n{tb.rstrip()}" for cell, tb in failures]
        super().__init__("\n".join(parts))


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
    """Yield (key, ok, result) as cells finish, in-process or on a pool of spawned processes."""
    if workers <= 1 or len(cells) <= 1:
        for key, cell in cells.items():
            yield key, *_run_cell(fn, cell, cache_dir)
        return
    # "spawn" starts clean interpreters: safe under Jupyter and with torch, where fork can deadlock.
    context = multiprocessing.get_context("spawn")
    pool = ProcessPoolExecutor(min(workers, len(cells)), mp_context=context, initializer=_init_worker)
    finished = False
    try:
        futures = {pool.submit(_run_cell, fn, cell, cache_dir): key for key, cell in cells.items()}
        for future in as_completed(futures):
            try:
                yield futures[future], *future.result()
            except Exception:  # the worker process died (e.g. out of memory)
                yield futures[future], False, traceback.format_exc()
        finished = True
    finally:
        if not finished:
            # Interrupted (KeyboardInterrupt, or the caller stopped reading): nobody will read the rows of
            # the running cells, so stop them rather than wait for them.
            _terminate_workers(pool)
        pool.shutdown(wait=True, cancel_futures=True)


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

    if workers is not None and workers < 1:
        raise ValueError(f"workers must be at least 1, got {workers}")
    directory = resolve_cache_dir(cache_dir)
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
                            store_cell(fn, directory, key, result)
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

"""Toy cells for the sweep tests: module-level, so spawned and Dask worker processes can import them.

Every execution of `toy_cell` leaves a marker file in the cell's `log_dir`, named after the seed and the
process, so a test can count exactly which cells ran, and where.

Run as `python -m tests._sweep_cells CACHE_DIR LOG_DIR` it performs the slow sweep that the resume test
kills half-way; as `python -m tests._sweep_cells --stuck LOG_DIR` it runs, on two workers, cells that
would take ten minutes, for the tests that interrupt or kill a sweep; as `python -m tests._sweep_cells
--threads` it prints the BLAS threads of two cells run on two workers.
"""

from __future__ import annotations

import os
import signal
import sys
import time
import uuid
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from hipref.sweep import cached_artefact, run_sweep


@dataclass(frozen=True)
class ToyCell:
    """A stand-in for a study's (seed x noise x method) cell."""

    seed: int
    """Seeds the cell's own generator; no RNG is shared between cells."""
    noise: float = 0.1
    """Fraction of flipped labels, copied into the rows."""
    method: str = "pesi"
    """Method name, copied into the rows."""
    log_dir: str = ""
    """Directory for execution markers; empty for none."""
    sleep: float = 0.0
    """Seconds to wait before computing, to make cells slow (and finish out of order)."""
    fail: bool = False
    """Raise instead of returning rows."""


def toy_cell(cell: ToyCell) -> pd.DataFrame:
    """Tidy rows of a fake learning curve drawn from the cell's seed."""
    if cell.log_dir:
        marker = f"{cell.seed}-{os.getpid()}-{uuid.uuid4().hex}"
        (Path(cell.log_dir) / marker).touch()
    time.sleep(cell.sleep)
    if cell.fail:
        raise RuntimeError(f"toy failure in cell with seed {cell.seed}")
    rng = np.random.default_rng(cell.seed)
    episodes = np.arange(5)
    return pd.DataFrame(
        {
            "domain": "wiping",
            "method": cell.method,
            "noise": cell.noise,
            "seed": cell.seed,
            "episode": episodes,
            "metric": "param_error",
            "value": rng.normal(size=episodes.size) / (1 + episodes),
        }
    )


def artefact_cell(cell: ToyCell) -> pd.DataFrame:
    """`toy_cell`'s rows, shifted by a shared artefact the cell builds (or finds) in the sweep's cache."""
    offset = cached_artefact("toy_offset", cell.seed, lambda: float(cell.seed), expect=float)
    return toy_cell(cell).assign(value=lambda rows: rows.value + offset)


def dying_cell(cell: ToyCell) -> pd.DataFrame:
    """`toy_cell`, but a cell marked `fail` kills the worker process it runs in, every time."""
    if cell.fail:
        os.kill(os.getpid(), signal.SIGKILL)
    return toy_cell(cell)


def executions(log_dir: str | os.PathLike[str], pid: int | None = None) -> list[int]:
    """Seeds of the cells that ran (in process `pid`, or anywhere), sorted."""
    names = [path.name.split("-") for path in Path(log_dir).iterdir()]
    return sorted(int(seed) for seed, proc, _ in names if pid is None or int(proc) == pid)


def executing_pids(log_dir: str | os.PathLike[str]) -> set[int]:
    """Processes that ran cells."""
    return {int(path.name.split("-")[1]) for path in Path(log_dir).iterdir()}


@dataclass(frozen=True)
class ThreadsCell:
    """A cell that reports the thread settings it ran under."""

    seed: int


def threads_cell(cell: ThreadsCell) -> pd.DataFrame:
    """Rows holding torch's thread count, OMP_NUM_THREADS and the most threads of any BLAS loaded (numpy's
    among them) as seen inside the cell."""
    import torch
    from threadpoolctl import threadpool_info

    blas = [library["num_threads"] for library in threadpool_info() if library["user_api"] == "blas"]
    return pd.DataFrame(
        {
            "seed": [cell.seed],
            "torch_threads": [torch.get_num_threads()],
            "omp": [os.environ.get("OMP_NUM_THREADS", "")],
            "blas_threads": [max(blas)],
        }
    )


def resume_cells(log_dir: str) -> list[ToyCell]:
    """Eight slow cells, 0.3 s each, for the interrupted-sweep test."""
    return [ToyCell(seed=seed, log_dir=log_dir, sleep=0.3) for seed in range(8)]


STUCK_WORKERS = 2
"""Worker processes of the stuck sweep."""


def stuck_cells(log_dir: str) -> list[ToyCell]:
    """Four cells of ten minutes each: whatever stops the sweep, it is not their end."""
    return [ToyCell(seed=seed, log_dir=log_dir, sleep=600.0) for seed in range(4)]


if __name__ == "__main__":
    if sys.argv[1] == "--stuck":
        run_sweep(toy_cell, stuck_cells(sys.argv[2]), cache_dir=False, workers=STUCK_WORKERS, desc="stuck")
    elif sys.argv[1] == "--threads":
        # This module imports numpy: a spawned worker imports it too, before its initializer runs.
        rows = run_sweep(threads_cell, [ThreadsCell(seed) for seed in range(2)], cache_dir=False, workers=2)
        print(" ".join(str(threads) for threads in rows["blas_threads"]))
    else:
        cache_dir, log_dir = sys.argv[1:3]
        run_sweep(toy_cell, resume_cells(log_dir), cache_dir=cache_dir, workers=1, desc="resume")

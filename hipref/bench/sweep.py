"""How much faster a sweep runs on two local workers than on one.

`python -m hipref.bench.sweep` times the same CPU-bound sweep (8 cells of about 1.5 s of pure-Python
work, cache disabled) with 1 worker and with 2, takes the median of 3 repeats of each, and prints one JSON
line. The timings include starting the worker processes, as a real sweep pays for them too.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from dataclasses import dataclass

import pandas as pd

from hipref.sweep import NO_CACHE, run_sweep


@dataclass(frozen=True)
class BusyCell:
    """One benchmark cell."""

    seed: int
    """Start of the pseudo-random sequence."""
    iterations: int = 16_000_000
    """Steps of the generator; about 1.5 s of one core."""


def busy_cell(cell: BusyCell) -> pd.DataFrame:
    """Iterate a linear congruential generator: pure Python, so surely single-threaded and CPU-bound."""
    x = cell.seed
    total = 0
    for _ in range(cell.iterations):
        x = (x * 1103515245 + 12345) & 0x7FFFFFFF
        total += x >> 16
    return pd.DataFrame({"seed": [cell.seed], "metric": ["checksum"], "value": [total]})


def time_sweep(cells: list[BusyCell], workers: int, repeats: int) -> float:
    """Median wall time, in seconds, of running `cells` on `workers` processes."""
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        run_sweep(busy_cell, cells, cache_dir=NO_CACHE, workers=workers, desc=f"{workers} worker(s)")
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, default=8)
    parser.add_argument("--iterations", type=int, default=BusyCell.iterations)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()

    cells = [BusyCell(seed, args.iterations) for seed in range(args.cells)]
    # Other processes competing for the cores shrink the speed-up; the load average says how much.
    load_before = os.getloadavg()[0]
    one = time_sweep(cells, 1, args.repeats)
    two = time_sweep(cells, 2, args.repeats)
    report = {
        "bench": "sweep",
        "cells": args.cells,
        "iterations": args.iterations,
        "repeats": args.repeats,
        "cpu_count": os.cpu_count(),
        "loadavg_1min_before": round(load_before, 2),
        "seconds_1_worker": round(one, 3),
        "seconds_2_workers": round(two, 3),
        "speedup": round(one / two, 3),
    }
    print(json.dumps(report))


if __name__ == "__main__":
    main()

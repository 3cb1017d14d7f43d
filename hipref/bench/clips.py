"""What replaying an environment's learning clips saves in a noise sweep (notebook 03's shape).

`python -m hipref.bench.clips` runs PESI in one environment per domain at several noise levels, one run
after another in this process, twice: replaying the clips each environment executes once
(`hipref.experiments.si_clips.learning_clips`, what the studies do) and executing every run's clips itself.
It checks that both give the same rows and prints one JSON line with the median wall time of each over the
repeats and their ratio. Nothing is written to disk; the SI models, the compiled controllers and the
evaluation episodes (the same for both) are built before timing, and the clips are forgotten before each
timed sweep.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from unittest import mock

import pandas as pd

from hipref import sweep
from hipref.envs.task import Clip
from hipref.experiments import si_run
from hipref.experiments.protocol import SIStudy


def noise_sweep(protocol: SIStudy, noise_levels: list[float]) -> pd.DataFrame:
    """PESI at every noise level in each domain's environments, one run after another."""
    cells = [
        protocol.run_cell(domain, "pesi", truth, seed, noise=noise)
        for domain in ("wiping", "pushing")
        for noise in noise_levels
        for truth, seed in protocol.environments(domain)
    ]
    return pd.concat([si_run.run_si(cell) for cell in cells], ignore_index=True)


def forget_clips() -> None:
    """Drop the learning clips held in memory, so that the next sweep executes them afresh."""
    sweep.forget_artefacts(lambda held: isinstance(held, list) and bool(held) and isinstance(held[0], Clip))


def timed_sweep(protocol: SIStudy, noise_levels: list[float], replay: bool) -> tuple[float, pd.DataFrame]:
    """Wall time and rows of one sweep, its clips replayed or every run's executed."""
    forget_clips()
    start = time.perf_counter()
    if replay:
        rows = noise_sweep(protocol, noise_levels)
    else:
        with mock.patch.object(si_run, "learning_clips", lambda *args: None):
            rows = noise_sweep(protocol, noise_levels)
    return time.perf_counter() - start, rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--noise-levels", type=float, nargs="+", default=[0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6])
    parser.add_argument("--episodes", type=int, default=66)
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()

    protocol = SIStudy(heights=(0.7,), masses=(14.0,), episodes=args.episodes, eval_every=33)
    load_before = os.getloadavg()[0]
    with sweep.artefacts_in(sweep.NO_CACHE):
        noise_sweep(protocol, args.noise_levels[:1])  # models, controllers and evaluation episodes
        replayed, executed = [], []
        for _ in range(args.repeats):
            seconds, replay_rows = timed_sweep(protocol, args.noise_levels, replay=True)
            replayed.append(seconds)
            seconds, execute_rows = timed_sweep(protocol, args.noise_levels, replay=False)
            executed.append(seconds)
            pd.testing.assert_frame_equal(replay_rows, execute_rows)
    report = {
        "bench": "clips",
        "noise_levels": args.noise_levels,
        "episodes": args.episodes,
        "repeats": args.repeats,
        "loadavg_1min_before": round(load_before, 2),
        "seconds_replayed": round(statistics.median(replayed), 2),
        "seconds_executed": round(statistics.median(executed), 2),
        "ratio_executed_to_replayed": round(statistics.median(executed) / statistics.median(replayed), 2),
        "rows_equal": True,
    }
    print(json.dumps(report))


if __name__ == "__main__":
    main()

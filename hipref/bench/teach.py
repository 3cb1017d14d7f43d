"""How long a person waits for the next query after answering (notebook 09).

`python -m hipref.bench.teach` answers a session's preference queries through the widgets
(`hipref.teach.app`) as the scripted stand-in does, but waits `--watch` seconds before each answer, as a
person watching the looping clips would, and prints one JSON line per domain: the seconds from each press
until the next pair was on screen (its median and worst), the seconds a query takes to execute and render
when nothing is prepared ahead (its median), and the clips' size. The session is written to a temporary
directory and the SI model pretrained at a small size, so nothing of the study is touched.

`--busy N` runs N other processes beside it for the whole measurement, each keeping one core busy with
numpy (a 400 x 400 matrix product in a loop, on one BLAS thread), as other work on the machine would.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import statistics
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

from hipref.teach import open_session
from hipref.teach.app import PreferenceApp
from hipref.teach.config import TeachConfig
from hipref.teach.preferences import PreferenceTeaching
from hipref.teachers.preference import ScriptedPreferenceTeacher


def measure(domain: str, truth: float, queries: int, watch: float) -> dict[str, object]:
    config = TeachConfig(
        teacher="person",
        domain=domain,
        true_parameter=truth,
        preference_queries=queries,
        n_trajectories=8,
        pretrain_steps=20,
    )
    app = PreferenceApp(PreferenceTeaching(config, open_session(config)))
    teacher = ScriptedPreferenceTeacher(truth, 0.0, np.random.default_rng(0))
    sizes = []
    while (shown := app.teaching.current) is not None:
        sizes.append(sum(map(len, shown.animations or ())))
        time.sleep(watch)
        label = teacher.answer(shown.query)
        app.wait_ready()  # the widget takes presses once the pair has been on screen for SETTLE_SECONDS
        app.press(shown.side_of(0 if label == 1 else 1))  # waits for the next query if it is not ready
    app.teaching.close()
    cold = []
    for number in range(3):  # nothing prepared ahead: the whole cost of a query
        start = time.perf_counter()
        app.teaching.prepare_apart(number)
        cold.append(time.perf_counter() - start)
    return {
        "domain": domain,
        "watch_s": watch,
        "answers": len(app.waits),
        "next_pair_median_s": round(statistics.median(app.waits), 3),
        "next_pair_worst_s": round(max(app.waits), 3),
        "prepare_query_median_s": round(statistics.median(cold), 3),
        "clips_kib_median": round(statistics.median(sizes) / 1024),
    }


def _spin() -> None:
    """Keep one core busy until terminated."""
    from threadpoolctl import threadpool_limits

    a = np.random.default_rng(0).random((400, 400))
    with threadpool_limits(1):
        while True:
            a = a @ a
            a /= np.abs(a).max()


@contextmanager
def busy(processes: int) -> Iterator[None]:
    """`processes` processes each keeping a core busy, stopped on leaving."""
    spinners = [multiprocessing.Process(target=_spin, daemon=True) for _ in range(processes)]
    for spinner in spinners:
        spinner.start()
    try:
        yield
    finally:
        for spinner in spinners:
            spinner.terminate()
            spinner.join()


def main() -> None:
    formatter = argparse.RawDescriptionHelpFormatter
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=formatter)
    parser.add_argument("--queries", type=int, default=10, help="preference queries per domain")
    parser.add_argument("--watch", type=float, default=2.0, help="seconds a person watches before answering")
    parser.add_argument("--busy", type=int, default=0, help="processes keeping a core busy beside it")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as results, tempfile.TemporaryDirectory() as cache, busy(args.busy):
        os.environ["HIPREF_RESULTS_DIR"], os.environ["HIPREF_CACHE_DIR"] = results, cache
        for domain, truth in (("wiping", 0.7), ("pushing", 14.0)):
            print(json.dumps({**measure(domain, truth, args.queries, args.watch), "busy": args.busy}))


if __name__ == "__main__":
    main()

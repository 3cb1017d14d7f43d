"""What the disk cache of the compiled controllers saves each new process (`hipref.control.compiled`).

`python -m hipref.bench.startup` starts fresh interpreters that import the package and execute one wiping
and one pushing rollout, the first thing a sweep worker, a notebook kernel or a test process does: `cold`
with an empty numba cache (the kernels are compiled), `warm` with the cache the cold run left. Each pair
runs in one temporary cache directory (`NUMBA_CACHE_DIR`), so the checkout's cache is neither used nor
touched. Prints one JSON line: the median over the repeats of each, in s, their ratio, and whether both
computed the same features to the bit.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from typing import Any

FIRST_ROLLOUTS = """
import hashlib, json, time
start = time.perf_counter()
import numpy as np
from hipref.envs.pushing import PushingTask
from hipref.envs.wiping import WipingTask
rng = np.random.default_rng(0)
features = b""
for task, truth, estimate in ((WipingTask(), 0.7, 0.72), (PushingTask(), 14.0, 12.0)):
    features += task.rollout(truth, estimate, task.sample_layout(rng)).features.tobytes()
print(json.dumps({"seconds": time.perf_counter() - start, "digest": hashlib.sha256(features).hexdigest()}))
"""


def first_rollouts(cache: str) -> dict[str, Any]:
    """Seconds from a fresh interpreter's first import to the end of its first rollout in each task."""
    env = {**os.environ, "NUMBA_CACHE_DIR": cache}
    out = subprocess.run(
        [sys.executable, "-c", FIRST_ROLLOUTS], env=env, capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="cold/warm pairs (default 3)")
    args = parser.parse_args()
    cold, warm, same = [], [], True
    for _ in range(args.repeats):
        with tempfile.TemporaryDirectory() as cache:
            first, second = first_rollouts(cache), first_rollouts(cache)
        cold.append(float(first["seconds"]))
        warm.append(float(second["seconds"]))
        same = same and first["digest"] == second["digest"]
    cold_s, warm_s = statistics.median(cold), statistics.median(warm)
    print(
        json.dumps(
            {
                "cold_s": round(cold_s, 2),
                "warm_s": round(warm_s, 2),
                "ratio": round(cold_s / warm_s, 1),
                "same_features": same,
                "repeats": args.repeats,
            }
        )
    )


if __name__ == "__main__":
    main()

"""Simulation speed with the controller in the loop, against bare mj_step on the same compiled model.

    python -m hipref.bench

prints one JSON line: for each task, physics steps per second of the task's low-level policy (admittance,
IK and SPD in Python around MuJoCo), of bare `mj_step` from the same states in the same run, and their
ratio. Each figure is the median of `--repeats` timings."""

from __future__ import annotations

import argparse
import json
import statistics
import time
from collections.abc import Callable

import mujoco
import numpy as np

from hipref.envs.pushing import PushingTask
from hipref.envs.wiping import WipingTask


def _rate(run: Callable[[], int], repeats: int) -> float:
    rates = []
    for _ in range(repeats):
        start = time.perf_counter()
        steps = run()
        rates.append(steps / (time.perf_counter() - start))
    return statistics.median(rates)


def _bare(model: mujoco.MjModel, data: mujoco.MjData, steps: int) -> Callable[[], int]:
    """mj_step alone from a copy of the task's state, holding the last torques."""
    snapshot = mujoco.MjData(model)
    mujoco.mj_copyData(snapshot, model, data)

    def run() -> int:
        mujoco.mj_copyData(data, model, snapshot)
        for _ in range(steps):
            mujoco.mj_step(model, data)
        return steps

    return run


def bench_wiping(repeats: int) -> dict[str, float]:
    task = WipingTask()
    steps_per_period = task.config.scene.control_substeps

    def strokes() -> int:
        task.reset(0.7, (-0.2, 0.0))
        task.approach(0.7)
        before = task.scene.data.time
        for goal in ((0.2, 0.0), (0.2, 0.1), (-0.2, 0.1)):
            task.stroke(np.array(goal), 0.7)
        return round((task.scene.data.time - before) / task.scene.model.opt.timestep)

    controlled = _rate(strokes, repeats)
    bare = _rate(_bare(task.scene.model, task.scene.data, 2000 * steps_per_period // 5), repeats)
    return {"controlled_steps_per_s": controlled, "bare_steps_per_s": bare, "ratio": controlled / bare}


def bench_pushing(repeats: int) -> dict[str, float]:
    task = PushingTask()
    layouts = [task.sample_layout(np.random.default_rng(seed)) for seed in range(5)]

    def pushes() -> int:
        steps = 0
        for start, goal in layouts:
            task.reset(14.0, start, goal)
            task.push(14.0)
            steps += round(task.scene.data.time / task.scene.model.opt.timestep)
        return steps

    controlled = _rate(pushes, repeats)
    start, goal = layouts[0]
    task.reset(14.0, start, goal)
    bare = _rate(_bare(task.scene.model, task.scene.data, 2000), repeats)
    return {"controlled_steps_per_s": controlled, "bare_steps_per_s": bare, "ratio": controlled / bare}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="timings per figure; the median is printed")
    args = parser.parse_args()
    result = {
        "wiping": bench_wiping(args.repeats),
        "pushing": bench_pushing(args.repeats),
        "mujoco": mujoco.__version__,
    }
    rounded = {
        k: {n: round(x, 3 if n == "ratio" else 0) for n, x in v.items()} if isinstance(v, dict) else v
        for k, v in result.items()
    }
    print(json.dumps(rounded))


if __name__ == "__main__":
    main()

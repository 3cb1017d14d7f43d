"""Simulation speed with the controller in the loop, against bare mj_step on the same compiled model.

    python -m hipref.bench.physics

prints one JSON line: for each task, physics steps per second of the task's low-level policy (admittance,
IK and SPD compiled around MuJoCo's C API, hipref.control.compiled), of bare `mj_step` called from Python
on the same model, and their ratio; each figure is the median of `--repeats` timings, after one untimed
run that compiles the controllers. Bare stepping starts from a state of the task and holds its last
torques: for wiping the sponge pressing on the desk, for pushing the cube at rest before a push, which
steps faster than a push's own contacts (the constraint solver iterates while the paddle drives the cube).
`physics_share` is therefore also given: the fraction of the controlled runs' time spent inside MuJoCo's
timed stages of those very steps (position, velocity, actuation, constraint, integration; the
acceleration stage is not timed by MuJoCo, so the share is a lower bound)."""

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

_PHYSICS_STAGES = tuple(
    int(stage)
    for stage in (
        mujoco.mjtTimer.mjTIMER_POSITION,
        mujoco.mjtTimer.mjTIMER_VELOCITY,
        mujoco.mjtTimer.mjTIMER_ACTUATION,
        mujoco.mjtTimer.mjTIMER_CONSTRAINT,
        mujoco.mjtTimer.mjTIMER_ADVANCE,
    )
)


def _rate(run: Callable[[], int], repeats: int) -> float:
    rates = []
    for _ in range(repeats):
        start = time.perf_counter()
        steps = run()
        rates.append(steps / (time.perf_counter() - start))
    return statistics.median(rates)


def _physics_seconds(data: mujoco.MjData) -> float:
    """Time spent in MuJoCo's timed stages since the last mj_resetData (which clears the timers)."""
    return sum(data.timer[stage].duration for stage in _PHYSICS_STAGES)


def _controlled(run: Callable[[], tuple[int, float]], repeats: int) -> tuple[float, float]:
    """Median steps per second of `run`, which returns its steps and its seconds of physics, after one
    untimed run that compiles the controllers; and the share of the timed runs spent in physics."""
    run()
    rates, physics, total = [], 0.0, 0.0
    for _ in range(repeats):
        start = time.perf_counter()
        steps, seconds = run()
        elapsed = time.perf_counter() - start
        rates.append(steps / elapsed)
        physics += seconds
        total += elapsed
    return statistics.median(rates), physics / total


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

    def strokes() -> tuple[int, float]:
        task.reset(0.7, (-0.2, 0.0))
        task.approach(0.7)
        before = task.scene.data.time
        for goal in ((0.2, 0.0), (0.2, 0.1), (-0.2, 0.1)):
            task.stroke(np.array(goal), 0.7)
        steps = round((task.scene.data.time - before) / task.scene.model.opt.timestep)
        return steps, _physics_seconds(task.scene.data)

    controlled, share = _controlled(strokes, repeats)
    bare = _rate(_bare(task.scene.model, task.scene.data, 2000 * steps_per_period // 5), repeats)
    return {
        "controlled_steps_per_s": controlled,
        "bare_steps_per_s": bare,
        "ratio": controlled / bare,
        "physics_share": share,
    }


def bench_pushing(repeats: int) -> dict[str, float]:
    task = PushingTask()
    layouts = [task.sample_layout(np.random.default_rng(seed)) for seed in range(5)]

    def pushes() -> tuple[int, float]:
        steps, physics = 0, 0.0
        for start, goal in layouts:
            task.reset(14.0, start, goal)
            task.push(14.0)
            steps += round(task.scene.data.time / task.scene.model.opt.timestep)
            physics += _physics_seconds(task.scene.data)
        return steps, physics

    controlled, share = _controlled(pushes, repeats)
    start, goal = layouts[0]
    task.reset(14.0, start, goal)
    bare = _rate(_bare(task.scene.model, task.scene.data, 2000), repeats)
    return {
        "controlled_steps_per_s": controlled,
        "bare_steps_per_s": bare,
        "ratio": controlled / bare,
        "physics_share": share,
    }


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
        k: {n: round(x, 0 if n.endswith("_per_s") else 3) for n, x in v.items()} if isinstance(v, dict) else v
        for k, v in result.items()
    }
    print(json.dumps(rounded))


if __name__ == "__main__":
    main()

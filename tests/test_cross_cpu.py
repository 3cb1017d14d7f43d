"""Rows do not depend on the CPU: this machine computes the same rows as a CPU with AVX2 and no AVX-512.

torch chooses its kernels by the CPU it runs on, and `hipref.numerics` pins that choice. Small cells of the
SI studies (both domains) and of pretrained COACH run in two fresh interpreters, side by side: one as this
machine runs them, the other with every library that dispatches on the CPU told to compute as an AVX2 CPU
would. MKL's AVX2 kernels run only on Intel processors, so there MKL takes its COMPATIBLE branch, the one
every x86-64 processor runs; without the pin MKL runs other kernels here, and the rows differ. Each
interpreter has its own cache directory, so nothing computed under one setting is reused under the other.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import hipref

DISPATCH_KNOBS: tuple[str, ...] = (
    "ATEN_CPU_CAPABILITY",
    "MKL_CBWR",
    "MKL_ENABLE_INSTRUCTIONS",
    "NPY_DISABLE_CPU_FEATURES",
    "NPY_ENABLE_CPU_FEATURES",
    "NUMBA_CPU_NAME",
    "NUMBA_CPU_FEATURES",
    "ONEDNN_MAX_CPU_ISA",
    "DNNL_MAX_CPU_ISA",
    "OPENBLAS_CORETYPE",
)
"""Environment variables by which torch, MKL, numpy, numba, oneDNN and OpenBLAS choose kernels."""

AVX2_CPU: dict[str, str] = {
    "ATEN_CPU_CAPABILITY": "avx2",
    "MKL_CBWR": "COMPATIBLE",
    "MKL_ENABLE_INSTRUCTIONS": "AVX2",
    "NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR",
    "NUMBA_CPU_NAME": "haswell",
    "ONEDNN_MAX_CPU_ISA": "AVX2",
    "OPENBLAS_CORETYPE": "Haswell",
}
"""What each library would choose on a CPU with AVX2 and without AVX-512 (MKL: see the module docstring)."""

CELLS = r"""
import json

import numpy as np
import pandas as pd

from hipref.envs.flat_wiping import DIRECTIONS, collect_demonstrations, low_level_expert
from hipref.envs.gridworld import WipingGrid
from hipref.envs.wiping import WipingTask
from hipref.experiments.r1_feedback import R1Cell, R1Config, run_cell
from hipref.experiments.si_pretraining import PretrainData
from hipref.experiments.si_run import SIRun, run_si
from hipref.learners.pretrained_coach import PretrainedCoach, PretrainedCoachConfig, behaviour_cloning
from hipref.teachers.feedback import ScriptedFeedbackTeacher

rows = {}
data = PretrainData(n_trajectories=2, trajectory_steps=20, pretrain_steps=30)
for domain, truth in (("wiping", 0.62), ("pushing", 12.0)):
    cell = SIRun(domain, "pesi", ground_truth=truth, episodes=4, eval_every=4, eval_episodes=2, data=data)
    rows["si_" + domain] = run_si(cell).to_csv(index=False)

config = R1Config(episodes=1, max_steps=4, seeds=1, demos=4, demo_goals=2, bc_epochs=5)
cell_rows = run_cell(R1Cell(config, "pretrained_coach", 7)).to_csv(index=False)
# The cell's rows count wiped cells, which a last-bit change of the policy rarely alters in so short a
# run; the policy itself, behaviour-cloned and then moved by Eq. 1 steps, shows every bit.
task = WipingTask()
grid = WipingGrid(task.config.area_x, task.config.area_y)
observations, actions = collect_demonstrations(4, 2, config.desk_height, config.chunk_periods, 0)
coach_config = PretrainedCoachConfig(bc_epochs=5)
policy = behaviour_cloning(observations, actions, len(DIRECTIONS), coach_config, 7)
learner = PretrainedCoach(policy, coach_config)
teacher = ScriptedFeedbackTeacher(low_level_expert(grid))
rng = np.random.default_rng(7)
for state in observations[:20]:
    query = learner.ask(state, learner.act(state, rng))
    learner.tell(query, teacher.answer(query))
policy = pd.DataFrame(np.stack([learner.probabilities(state) for state in observations]))
rows["pretrained_coach"] = cell_rows + policy.to_csv(index=False)
print(json.dumps(rows))
"""


def _start(extra: dict[str, str], cache: Path) -> subprocess.Popen[str]:
    env = {name: value for name, value in os.environ.items() if name not in DISPATCH_KNOBS}
    env.update(extra, HIPREF_CACHE_DIR=str(cache / "cache"), HIPREF_RESULTS_DIR=str(cache / "results"))
    # From the checkout under test, whatever the working directory of pytest.
    root = Path(hipref.__file__).resolve().parents[1]
    return subprocess.Popen(
        [sys.executable, "-c", CELLS],
        cwd=root,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _rows(process: subprocess.Popen[str]) -> dict[str, str]:
    stdout, stderr = process.communicate(timeout=600)
    assert process.returncode == 0, stderr[-4000:]
    return json.loads(stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def both_cpus(tmp_path_factory: pytest.TempPathFactory) -> tuple[dict[str, str], dict[str, str]]:
    """The rows of this machine and those of an AVX2 CPU, computed in parallel."""
    this = _start({}, tmp_path_factory.mktemp("this_cpu"))
    avx2 = _start(AVX2_CPU, tmp_path_factory.mktemp("avx2_cpu"))
    try:
        return _rows(this), _rows(avx2)
    finally:
        for process in (this, avx2):
            if process.poll() is None:
                process.kill()
                process.wait()


@pytest.mark.slow
@pytest.mark.parametrize("study", ["si_wiping", "si_pushing", "pretrained_coach"])
def test_rows_are_byte_identical_on_an_avx2_cpu(
    both_cpus: tuple[dict[str, str], dict[str, str]], study: str
) -> None:
    this, avx2 = both_cpus
    assert this[study] == avx2[study]
    assert this[study].count("\n") > 1  # a header and at least one row

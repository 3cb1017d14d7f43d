"""Adam's update does not depend on which of MKL's code paths the process runs (`hipref.numerics.adam`).

MKL's float32 square root, which torch's default Adam update calls, is not correctly rounded, and which
rounding it makes depends on the processor even in MKL's COMPATIBLE branch: the rows of the SI studies
differed between an AVX-512 and an AVX2 machine through it alone. Here MKL is told to take two different
branches on this one machine (COMPATIBLE and AVX2, whose square roots round differently); the same Adam
steps on the same gradients must give the same weights under both.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

STEPS = r"""
import hashlib
import json

import numpy as np
import torch

from hipref.numerics import adam, one_thread


def digest(optimiser_of):
    rng = np.random.default_rng(0)
    weights = torch.nn.Parameter(torch.from_numpy(rng.normal(size=100_000).astype(np.float32)))
    optimiser = optimiser_of([weights])
    with one_thread():
        for _ in range(20):
            weights.grad = torch.from_numpy(rng.normal(size=100_000).astype(np.float32))
            optimiser.step()
    return hashlib.sha256(weights.detach().numpy().tobytes()).hexdigest()


print(json.dumps({
    "study": digest(lambda params: adam(params, 1e-3)),
    "default": digest(lambda params: torch.optim.Adam(params, lr=1e-3)),
}))
"""


def intel() -> bool:
    """Whether this is an Intel processor, the only kind MKL's AVX2 branch runs on (elsewhere MKL falls back
    to another branch, and the two branches compared here may be one)."""
    try:
        with open("/proc/cpuinfo") as cpuinfo:
            return "GenuineIntel" in cpuinfo.read()
    except OSError:
        return False


def adam_digests(mkl_branch: str) -> dict[str, str]:
    """The weights' digest after the study's Adam steps and after torch's default ones, in one interpreter
    running MKL's `mkl_branch`."""
    env = {**os.environ, "MKL_CBWR": mkl_branch}
    done = subprocess.run([sys.executable, "-c", STEPS], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def branches() -> dict[str, dict[str, str]]:
    """Both optimisers' digests under each of MKL's two branches (one interpreter per branch)."""
    return {branch: adam_digests(branch) for branch in ("COMPATIBLE", "AVX2")}


@pytest.mark.slow
@pytest.mark.skipif(sys.platform != "linux", reason="MKL's branches are those of x86-64 Linux")
def test_the_studys_adam_steps_are_the_same_whichever_branch_of_mkl_runs(
    branches: dict[str, dict[str, str]],
) -> None:
    assert branches["COMPATIBLE"]["study"] == branches["AVX2"]["study"]


@pytest.mark.slow
@pytest.mark.skipif(not intel(), reason="MKL's AVX2 branch runs on Intel processors only")
def test_torchs_default_adam_steps_would_differ_between_the_branches(
    branches: dict[str, dict[str, str]],
) -> None:
    """What the test above guards against: torch's default Adam rounds its square root as MKL's branch does
    (if a torch release stops calling MKL there, this test fails and the fused update is no longer needed)."""
    assert branches["COMPATIBLE"]["default"] != branches["AVX2"]["default"]

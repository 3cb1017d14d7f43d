"""Adam's update does not depend on which of MKL's code paths the process runs (`hipref.numerics.adam`).

MKL's float32 square root, which torch's default Adam update calls, is not correctly rounded, and which
rounding it makes depends on the processor even in MKL's COMPATIBLE branch: the rows of the SI studies
differed between an AVX-512 and an AVX2 machine through it alone. Here MKL is told to take two different
branches on this one machine (COMPATIBLE and AVX2, whose square roots round differently); the same Adam
steps on the same gradients must give the same weights under both.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

STEPS = r"""
import hashlib
import sys

import numpy as np
import torch

from hipref.numerics import adam, one_thread

rng = np.random.default_rng(0)
weights = torch.nn.Parameter(torch.from_numpy(rng.normal(size=100_000).astype(np.float32)))
optimiser = adam([weights], 1e-3) if sys.argv[1] == "study" else torch.optim.Adam([weights], lr=1e-3)
with one_thread():
    for _ in range(20):
        weights.grad = torch.from_numpy(rng.normal(size=100_000).astype(np.float32))
        optimiser.step()
print(hashlib.sha256(weights.detach().numpy().tobytes()).hexdigest())
"""


def intel() -> bool:
    """Whether this is an Intel processor, the only kind MKL's AVX2 branch runs on (elsewhere MKL falls back
    to another branch, and the two branches compared here may be one)."""
    try:
        with open("/proc/cpuinfo") as cpuinfo:
            return "GenuineIntel" in cpuinfo.read()
    except OSError:
        return False


def adam_digest(optimiser: str, mkl_branch: str) -> str:
    env = {**os.environ, "MKL_CBWR": mkl_branch}
    command = [sys.executable, "-c", STEPS, optimiser]
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip()


@pytest.mark.skipif(sys.platform != "linux", reason="MKL's branches are those of x86-64 Linux")
def test_the_studys_adam_steps_are_the_same_whichever_branch_of_mkl_runs() -> None:
    assert adam_digest("study", "COMPATIBLE") == adam_digest("study", "AVX2")


@pytest.mark.skipif(not intel(), reason="MKL's AVX2 branch runs on Intel processors only")
def test_torchs_default_adam_steps_would_differ_between_the_branches() -> None:
    """What the test above guards against: torch's default Adam rounds its square root as MKL's branch does
    (if a torch release stops calling MKL there, this test fails and the fused update is no longer needed)."""
    assert adam_digest("default", "COMPATIBLE") != adam_digest("default", "AVX2")

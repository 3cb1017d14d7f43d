"""Small symmetric positive-definite solves through MuJoCo's Cholesky routines.

The controllers solve a 6x6 system at every physics step; MuJoCo's C routines do it without numpy's
per-call overhead, which would otherwise cost more than the physics step itself."""

from __future__ import annotations

import mujoco
import numpy as np


class SPDSolver:
    """Solve A x = b for symmetric positive-definite A of a fixed size, reusing its buffers."""

    def __init__(self, size: int) -> None:
        self.factor = np.zeros((size, size))
        self.solution = np.zeros(size)

    def solve(self, matrix: np.ndarray, rhs: np.ndarray) -> np.ndarray:
        """x with matrix @ x = rhs; the returned array is reused by the next call."""
        self.factor[:] = matrix
        mujoco.mju_cholFactor(self.factor, 1e-12)
        mujoco.mju_cholSolve(self.solution, self.factor, rhs)
        return self.solution

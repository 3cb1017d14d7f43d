"""The small symmetric positive-definite solve both controllers need at every physics step: SPD's
(M + k_d dt) q'' = r of Eq. 6 and the damped least-squares step of inverse kinematics, both 6 x 6."""

from __future__ import annotations

import math

import numpy as np

from hipref.control.compiled import subroutine


@subroutine
def cholesky_solve(matrix: np.ndarray, rhs: np.ndarray, factor: np.ndarray, solution: np.ndarray) -> None:
    """solution = matrix^-1 rhs by Cholesky, matrix = L L^T (matrix symmetric positive definite).

    Only the lower triangle of `matrix` is read; `factor` (same shape) is scratch space for L."""
    n = rhs.shape[0]
    for j in range(n):
        diagonal = matrix[j, j]
        for k in range(j):
            diagonal -= factor[j, k] * factor[j, k]
        pivot = math.sqrt(diagonal)
        factor[j, j] = pivot
        for i in range(j + 1, n):
            entry = matrix[i, j]
            for k in range(j):
                entry -= factor[i, k] * factor[j, k]
            factor[i, j] = entry / pivot
    # L y = rhs, then L^T x = y, in place.
    for i in range(n):
        entry = rhs[i]
        for k in range(i):
            entry -= factor[i, k] * solution[k]
        solution[i] = entry / factor[i, i]
    for i in range(n - 1, -1, -1):
        entry = solution[i]
        for k in range(i + 1, n):
            entry -= factor[k, i] * solution[k]
        solution[i] = entry / factor[i, i]

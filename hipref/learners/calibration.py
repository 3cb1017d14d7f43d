"""Is Pr(phi | tau) a posterior? Probability integral transform (PIT) and credible-interval coverage.

SI's output is a distribution over the candidates Phi. Read as a density, each candidate's mass is spread
evenly over its cell (the candidate +- half the resolution), so the cumulative distribution is piecewise
linear and a true parameter between candidates has a definite PIT, F(truth). If the truths are drawn from
the distributions themselves, the PITs are uniform on [0, 1] and a central credible interval of level L,
[F^-1((1 - L) / 2), F^-1((1 + L) / 2)], holds the truth a fraction L of the time.
"""

from __future__ import annotations

import numpy as np

from hipref.learners.sysid import CandidateSet
from hipref.validation import check_range


def pit(probabilities: np.ndarray, candidates: CandidateSet, truths: np.ndarray) -> np.ndarray:
    """F(truth) for each row of `probabilities` (n, |Phi|) and its truth (n,), in [0, 1]."""
    probabilities = np.asarray(probabilities, dtype=np.float64)
    truths = np.asarray(truths, dtype=np.float64).reshape(-1)
    if probabilities.ndim != 2 or probabilities.shape != (len(truths), candidates.size):
        raise ValueError(
            f"probabilities must be (n, {candidates.size}) with one truth per row, got {probabilities.shape} "
            f"and {len(truths)} truths"
        )
    if np.any(probabilities < 0) or not np.allclose(probabilities.sum(axis=1), 1.0, atol=1e-4):
        raise ValueError("probabilities must be non-negative rows summing to 1")
    # Position of the truth in cells: cell k spans [k - 1/2, k + 1/2] in units of the resolution.
    position = np.clip(candidates.normalise(truths) * (candidates.size - 1) + 0.5, 0.0, candidates.size)
    cell = np.minimum(np.floor(position).astype(np.int64), candidates.size - 1)
    below = np.cumsum(probabilities, axis=1) - probabilities
    rows = np.arange(len(truths))
    return np.clip(below[rows, cell] + (position - cell) * probabilities[rows, cell], 0.0, 1.0)


def coverage(pits: np.ndarray, level: float) -> float:
    """The fraction of truths inside the central credible interval of `level`: |PIT - 1/2| <= level / 2."""
    check_range("level", level, 0.0, 1.0)
    values = np.asarray(pits, dtype=np.float64).reshape(-1)
    if values.size == 0:
        raise ValueError("pits must hold at least one value, got none")
    return float(np.mean(np.abs(values - 0.5) <= level / 2.0))

"""The constant guess: the estimate a learner must beat to show that it reads anything from the world.

Two constants, answered whatever the slice shows: the middle of the domain's range (what one says knowing
only the range, Table 2) and the best constant for the truths at hand (their median, which minimises the
mean absolute error: an oracle that knows the grid, so a floor no constant can go under). Their rows sit
beside OSI's, on the same truths, seeds and checkpoints, so every SI comparison can be made paired.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from hipref.experiments.domains import domain_spec

CONSTANT_MIDDLE = "constant_middle"
"""Method name of the range's middle, answered always."""
CONSTANT_BEST = "constant_best"
"""Method name of the best constant for the truths (their median), answered always."""


def range_middle(domain: str) -> float:
    """The middle of `domain`'s randomisation range, in parameter units."""
    candidates = domain_spec(domain).candidates
    return (candidates.low + candidates.high) / 2.0


def best_constant(truths: np.ndarray | list[float]) -> float:
    """The constant of least mean absolute error on `truths`: their median."""
    values = np.asarray(truths, dtype=np.float64).reshape(-1)
    if values.size == 0 or not np.all(np.isfinite(values)):
        raise ValueError(f"truths must be a non-empty array of finite numbers, got {values[:5].tolist()}")
    return float(np.median(values))


def constant_guess_rows(data: pd.DataFrame, like: str = "osi") -> pd.DataFrame:
    """Rows of both constant guesses, one for each `like` row of an error metric (`param_error*`).

    Each copies the `like` row (its domain, truth, seed, episode, variant, ...) with the method renamed and
    the value replaced by |truth - constant|; the best constant is the median of the domain's distinct
    (truth, seed) environments among those rows, so every environment counts once.
    """
    missing = {"domain", "method", "metric", "ground_truth", "value"} - set(data.columns)
    if missing:
        raise ValueError(f"data must have columns {sorted(missing)} to place the constant guess beside it")
    template = data[(data.method == like) & data.metric.str.startswith("param_error")]
    if template.empty:
        raise ValueError(f"data has no '{like}' rows of a param_error metric to set a constant guess beside")
    parts = []
    for domain, rows in template.groupby("domain", sort=False):
        environments = rows.drop_duplicates([c for c in ("ground_truth", "seed") if c in rows.columns])
        for method, constant in (
            (CONSTANT_MIDDLE, range_middle(str(domain))),
            (CONSTANT_BEST, best_constant(environments.ground_truth.to_numpy())),
        ):
            parts.append(rows.assign(method=method, value=(rows.ground_truth - constant).abs()))
    return pd.concat(parts, ignore_index=True)


def with_constant_guess(data: pd.DataFrame, like: str = "osi") -> pd.DataFrame:
    """`data` with `constant_guess_rows` appended."""
    return pd.concat([data, constant_guess_rows(data, like)], ignore_index=True)

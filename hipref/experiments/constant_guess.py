"""The constant guess: the estimate a learner must beat to show that it reads anything from the world.

Two constants, answered whatever the slice shows: the middle of the domain's range (what one says knowing
only the range, Table 2) and the best constant for the truths at hand (their median, which minimises the
mean absolute error: an oracle that knows the grid, so a floor no constant can go under). Their rows sit
beside OSI's, on the same truths, seeds and checkpoints, so every SI comparison can be made paired.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from hipref import verdicts
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


def against_constant_guess(
    data: pd.DataFrame,
    methods: list[str] | tuple[str, ...],
    by: tuple[str, ...] = ("domain",),
    like: str | None = None,
    metric: str = "param_error",
) -> pd.DataFrame:
    """Each of `methods` beside both constant guesses at its last checkpoint, per group of `by` columns.

    One row per group and method: its mean `metric`, the two constants' on the same environments, and the
    paired difference method - range middle with its 95 % interval and verdict (`hipref.verdicts`). The
    constants do not depend on noise, teacher or variant, so each environment's constant row is paired
    with the method's rows of every group. `like`: whose rows the constants copy (`constant_guess_rows`;
    None: OSI's if present, else the first method's).
    """
    if like is None:
        like = "osi" if (data.method == "osi").any() else methods[0]
    constants = constant_guess_rows(data, like).drop_duplicates(
        ["domain", "ground_truth", "seed", "episode", "metric", "method"]
    )
    records = []
    rows = data[(data.metric == metric) & data.method.isin(methods)]
    for group, part in rows.groupby(list(by), sort=False):
        domain = part.domain.iloc[0]
        mine = constants[constants.domain == domain]
        for method in [m for m in methods if (part.method == m).any()]:
            frame = pd.concat([part[part.method == method], mine], ignore_index=True)
            middle = verdicts.paired_difference(frame, metric=metric, method=method, baseline=CONSTANT_MIDDLE)
            best = verdicts.paired_difference(frame, metric=metric, method=method, baseline=CONSTANT_BEST)
            last = int(part[part.method == method].episode.max())
            at = frame[(frame.episode == last) & (frame.metric == metric)]
            means = at.groupby("method").value.mean()
            records.append(
                {
                    **dict(zip(by, group if isinstance(group, tuple) else (group,), strict=True)),
                    "method": method,
                    "episode": last,
                    "error": means[method],
                    "middle_error": means[CONSTANT_MIDDLE],
                    "best_constant_error": means[CONSTANT_BEST],
                    "minus_middle": middle.mean,
                    "minus_middle_low": middle.low,
                    "minus_middle_high": middle.high,
                    "minus_best_constant": best.mean,
                    "n": middle.n,
                    "beats_middle": verdicts.better(middle, lower_is_better=True),
                }
            )
    return pd.DataFrame(records)


def constant_guess_claims(
    table: pd.DataFrame, context: tuple[str, ...] = ()
) -> list[tuple[str, str, str, str]]:
    """Claims rows (`hipref.results.claims_table`) 'method beats the constant guess' from an
    `against_constant_guess` table, one per row, naming the `context` columns (noise, teacher, ...)."""
    claims = []
    for row in table.itertuples(index=False):
        unit = domain_spec(row.domain).unit
        interval = f"[{row.minus_middle_low:+.3g}, {row.minus_middle_high:+.3g}]"
        where = ", ".join([row.domain, *(f"{c} {getattr(row, c)}" for c in context)])
        claims.append(
            (
                f"{row.method} beats the constant guess (the range's middle), {where}",
                "(not in the paper) SI reads the parameter from tau",
                f"{row.method} − middle at episode {row.episode}: {row.minus_middle:+.3g} {unit} {interval} "
                f"({row.n} pairs); the middle errs by {row.middle_error:.3g} {unit}, the best constant for "
                f"the truths by {row.best_constant_error:.3g}",
                row.beats_middle,
            )
        )
    return claims

"""The one place that decides whether a claim holds, in one vocabulary.

Every verdict in `results/claims.md` is one of `VERDICTS`, read by a rule below from an interval of
`hipref.intervals` (re-exported here, so a notebook needs only this module):

- "yes": the whole 95% interval lies on the side the claim says;
- "no": the whole interval lies on the other side (the claim is contradicted);
- "no difference detected": the interval holds zero (or, for an "about X" claim, straddles the band's
  edge): the data cannot tell, whatever side the mean leans to;
- "too few environments to decide": fewer than `MIN_ENVIRONMENTS` independent environments (pairs, units,
  datasets), over which no interval is drawn.

A claim of change at every step ("falls at every checkpoint", "grows with each noise level") is tested step
by step (`monotone` on `hipref.intervals.steps`); a claim of a trend ("grows with the noise") by the slope's
interval (`increases`, `decreases`), which says nothing of every step.

A claim on a learning curve, for instance "CO-PESI has a lower error than PESI at 20% noise":

    final = rows[(rows.domain == "pushing") & (rows.noise == 0.2)]
    error = paired_difference(final, metric="param_error", method="co_pesi", baseline="pesi")
    holds = better(error, lower_is_better=True)

and a trend, "the error grows with the noise" (one unit per environment, all noise levels in each):

    pesi = rows[(rows.domain == "pushing") & (rows.metric == "param_error") & (rows.method == "pesi")]
    last = pesi[pesi.episode == pesi.episode.max()]
    holds = increases(trend(last, x="noise", units=("ground_truth", "seed")))
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from hipref.intervals import (
    CONFIDENCE,
    MIN_ENVIRONMENTS,
    PAIR_KEYS,
    ROUNDING,
    Difference,
    Trend,
    bootstrap_mean,
    paired_difference,
    paired_differences_by_episode,
    steps,
    trend,
)

__all__ = [
    "CONFIDENCE",
    "MIN_ENVIRONMENTS",
    "PAIR_KEYS",
    "ROUNDING",
    "VERDICTS",
    "Difference",
    "Trend",
    "any_of",
    "at_most",
    "better",
    "better_on_both",
    "bootstrap_mean",
    "combine",
    "decreases",
    "holds_in_all",
    "increases",
    "monotone",
    "no_difference",
    "paired_difference",
    "paired_differences_by_episode",
    "steps",
    "trend",
    "within",
]

YES = "yes"
NO = "no"
NO_DIFFERENCE = "no difference detected"
TOO_FEW = "too few environments to decide"

VERDICTS: tuple[str, ...] = (YES, NO, NO_DIFFERENCE, TOO_FEW)
"""Every verdict a claim can get in `results/claims.md`."""


def _side(low: float, high: float, n: int, *, positive: bool) -> str:
    """The verdict of an interval [low, high] over `n` environments for a claim that it lies above zero
    (`positive`) or below it."""
    if n < MIN_ENVIRONMENTS:
        return TOO_FEW
    if (low > 0) if positive else (high < 0):
        return YES
    if (high < 0) if positive else (low > 0):
        return NO
    return NO_DIFFERENCE


def better(difference: Difference, lower_is_better: bool) -> str:
    """A method better than its baseline: 'yes' if the whole interval of method - baseline lies strictly on
    the better side of zero, 'no' if strictly on the worse side, else 'no difference detected'."""
    return _side(difference.low, difference.high, difference.n, positive=not lower_is_better)


def better_on_both(error: Difference, success: Difference) -> str:
    """A method better on the error (lower) and on the success rate (higher) at once: `combine` of the two
    `better` verdicts, so a mean that merely leans the better way supports nothing."""
    return combine([better(error, lower_is_better=True), better(success, lower_is_better=False)])


def no_difference(difference: Difference) -> str:
    """A claim of no difference: 'yes' if the interval contains zero, 'no' otherwise."""
    if difference.n < MIN_ENVIRONMENTS:
        return TOO_FEW
    return YES if difference.low <= 0 <= difference.high else NO


def increases(result: Trend) -> str:
    """A rising trend: 'yes' if the whole interval of the slope is strictly above zero, 'no' if strictly
    below, else 'no difference detected' (equal values give a slope of exactly zero)."""
    return _side(result.low, result.high, result.n, positive=True)


def decreases(result: Trend) -> str:
    """A falling trend: `increases` mirrored."""
    return _side(result.low, result.high, result.n, positive=False)


def monotone(table: pd.DataFrame, *, increasing: bool) -> str:
    """A change at every step (a table of `steps`: columns low, high, n per step): 'yes' if every step's
    interval lies strictly on the claimed side of zero, 'no' if any lies strictly on the other, else 'no
    difference detected'; 'too few environments to decide' if any step rests on too few."""
    missing = [c for c in ("low", "high", "n") if c not in table.columns]
    if missing or table.empty:
        raise ValueError(f"monotone needs a non-empty table of steps with low, high and n; lacks {missing}")
    rows = table[["low", "high", "n"]].itertuples()
    return combine([_side(r.low, r.high, int(r.n), positive=increasing) for r in rows])


def within(difference: Difference, low: float, high: float) -> str:
    """An 'about X' claim: 'yes' if the whole interval lies in [low, high], 'no' if it lies wholly outside,
    else (it straddles an edge) 'no difference detected' from the band."""
    if not low <= high:
        raise ValueError(f"low must not exceed high, got low={low!r}, high={high!r}")
    if difference.n < MIN_ENVIRONMENTS:
        return TOO_FEW
    if low <= difference.low and difference.high <= high:
        return YES
    return NO if difference.high < low or difference.low > high else NO_DIFFERENCE


def at_most(count: Difference, limit: float) -> str:
    """A count read off all environments at once (answers needed in 90 % of them), with its 95 % interval
    over `count.n` resampled units (the truths, each with all its seeds): 'yes' if the whole interval is at
    most `limit`, 'no' if it lies wholly above (a bound never reached, NaN, counts as infinite), else 'no
    difference detected'."""
    if count.n < MIN_ENVIRONMENTS:
        return TOO_FEW
    low, high = (np.inf if np.isnan(v) else v for v in (count.low, count.high))
    if high <= limit:
        return YES
    return NO if low > limit else NO_DIFFERENCE


def holds_in_all(condition: bool, *, environments: int) -> str:
    """A claim checked in each of `environments` without an interval (a deterministic measurement at every
    setting): 'yes' if `condition` holds in all of them, 'no' otherwise."""
    if environments < MIN_ENVIRONMENTS:
        return TOO_FEW
    return YES if condition else NO


def combine(verdicts: Sequence[str]) -> str:
    """One verdict for a claim made of parts that must all hold: 'too few environments to decide' if any
    part is, else 'yes' if every part holds, 'no' if any part is contradicted, else 'no difference
    detected'."""
    if not verdicts:
        raise ValueError("verdicts must hold at least one verdict, got none")
    for held in verdicts:
        if held not in VERDICTS:
            raise ValueError(f"each verdict must be one of {VERDICTS}, got {held!r}")
    for verdict in (TOO_FEW, NO, NO_DIFFERENCE):
        if verdict in verdicts:
            return verdict
    return YES


def any_of(verdicts: Sequence[str]) -> str:
    """One verdict for a claim that one of several settings shows ("a robust learner beats PESI"): 'yes'
    if any part holds, else 'too few environments to decide' if any part is, 'no' if every part is
    contradicted, else 'no difference detected'."""
    combine(verdicts)  # refuses an empty list or a word outside the vocabulary
    if YES in verdicts:
        return YES
    if TOO_FEW in verdicts:
        return TOO_FEW
    return NO if all(held == NO for held in verdicts) else NO_DIFFERENCE

"""Two estimators of the flip rate e of a preference dataset beside Algorithm 5 (`noise_estimation`).

Both rest on the scripted teacher's model: one true parameter phi* explains every clean preference ('a
preferred over b' when a is nearer phi* than b), and each answer is flipped independently with probability
e.

- `likelihood_noise`, the maximum marginal likelihood: with phi* unknown and uniform over the range,

      L(e) = integral over phi* of  prod_i (1 - e)^[y_i agrees with phi*] e^[y_i disagrees],

  maximised over e in [0, 1/2]. The integrand is constant between consecutive midpoints (a_i + b_i) / 2 of
  the dataset's pairs, so the integral is a sum over those intervals weighted by their lengths (exact, no
  grid of truths). Above 1/2 a flip rate cannot be told from its complement (every label reversed), so
  the estimate is confined to [0, 1/2].
- `repeated_pair_noise`, from pairs asked more than once: two answers to the same pair disagree with
  probability d = 2 e (1 - e), so e = (1 - sqrt(1 - 2 d)) / 2, with d the disagreeing share of all pairs of
  answers to one pair. It needs no model of phi* at all, only repeated pairs (NaN without any).

A preference learner (`hipref.learners.pesi.PESILearner`) takes its flip rate e from one source: `Told`
(the teacher's rate, or 0 for a learner that trusts every label), `Algorithm5` (A.9's estimate under a
reading of a conflict) or `Likelihood` (`likelihood_noise`), the last two on the buffer D so far.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated, Protocol

import numpy as np

from hipref.learners.noise_estimation import CONFLICTS, DEFAULT_CONFLICT, PreferenceSet, estimate_noise
from hipref.validation import OneOf, Range, check_fields, check_int, check_range


def likelihood_noise(preferences: PreferenceSet, low: float, high: float, resolution: int = 1000) -> float:
    """The flip rate in [0, 1/2] that maximises the marginal likelihood of `preferences` (module docstring),
    the true parameter uniform over [low, high]; searched on `resolution` + 1 evenly spaced rates."""
    check_range("low", low, -np.inf, np.inf)
    check_range("high", high, low, np.inf)
    check_int("resolution", resolution, 2)
    if len(preferences) == 0:
        raise ValueError("preferences must hold at least one preference, got an empty set")
    first, second, label = preferences.first, preferences.second, preferences.label
    midpoints = np.unique(np.clip((first + second) / 2.0, low, high))
    edges = np.unique(np.concatenate([[low], midpoints, [high]]))
    centres, widths = (edges[:-1] + edges[1:]) / 2.0, np.diff(edges)
    # Per interval of phi* (rows) and preference (columns): does the answer agree with phi*?
    clean = np.where(np.abs(first - centres[:, None]) < np.abs(second - centres[:, None]), 1.0, -1.0)
    violations = np.count_nonzero(clean != label, axis=1)
    agreements = len(label) - violations
    rates = np.linspace(0.0, 0.5, resolution + 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        log_terms = (
            np.log(widths)[:, None]
            + agreements[:, None] * np.log1p(-rates)[None, :]
            + np.where(violations[:, None] > 0, violations[:, None] * np.log(rates)[None, :], 0.0)
        )
    peak = log_terms.max(axis=0)
    # log-sum-exp over the intervals; a rate no interval allows (e = 0 with every interval violated) is -inf
    finite = np.isfinite(peak)
    log_likelihood = np.full(len(rates), -np.inf)
    log_likelihood[finite] = peak[finite] + np.log(np.exp(log_terms[:, finite] - peak[finite]).sum(axis=0))
    return float(rates[np.argmax(log_likelihood)])


def repeated_pair_noise(preferences: PreferenceSet) -> float:
    """The flip rate from the disagreement between answers to the same pair (module docstring); NaN when
    no pair was asked twice."""
    lower = np.minimum(preferences.first, preferences.second)
    higher = np.maximum(preferences.first, preferences.second)
    chose_lower = np.where(preferences.label == 1, preferences.first, preferences.second) == lower
    # Values equal in exact arithmetic can differ in the last bit: pairs are keyed on rounded values.
    _, pair = np.unique(np.round(np.stack([lower, higher], axis=1), 9), axis=0, return_inverse=True)
    pair = pair.reshape(-1)
    asked = np.bincount(pair)
    lower_chosen = np.bincount(pair, weights=chose_lower)
    pairs_of_answers = (asked * (asked - 1) / 2.0).sum()
    if pairs_of_answers == 0:
        return float("nan")
    disagreement = float((lower_chosen * (asked - lower_chosen)).sum() / pairs_of_answers)
    return float((1.0 - np.sqrt(max(0.0, 1.0 - 2.0 * disagreement))) / 2.0)


class FlipRate(Protocol):
    """Where a learner's flip rate e comes from: `rate` of its buffer D (`preferences()`, built only when
    read), Phi being [low, high]."""

    @property
    def estimated(self) -> bool:
        """Whether the rate is estimated from D (the learner keeps a history of its estimates)."""
        ...

    def rate(self, preferences: Callable[[], PreferenceSet], low: float, high: float) -> float: ...


@dataclass(frozen=True)
class Told:
    """The flip rate the learner is told: the teacher's true one (co_pesi), or 0 (a learner that trusts
    every label)."""

    value: Annotated[float, Range(0.0, 1.0)] = 0.0
    """e, in [0, 1]."""
    estimated = False

    def __post_init__(self) -> None:
        check_fields(self)

    def rate(self, preferences: Callable[[], PreferenceSet], low: float, high: float) -> float:
        return self.value


@dataclass(frozen=True)
class Algorithm5:
    """Algorithm 5's estimate on D (A.9, co_pesi_estimated), a conflict read as `conflict`; with no
    conflict at all it is 1.0, taken as written."""

    conflict: Annotated[str, OneOf(CONFLICTS)] = DEFAULT_CONFLICT
    """One of `hipref.learners.noise_estimation.CONFLICTS`."""
    estimated = True

    def __post_init__(self) -> None:
        check_fields(self)

    def rate(self, preferences: Callable[[], PreferenceSet], low: float, high: float) -> float:
        return estimate_noise(preferences(), self.conflict)


@dataclass(frozen=True)
class Likelihood:
    """The maximum marginal likelihood flip rate of D (`likelihood_noise`), at most `cap`."""

    cap: Annotated[float, Range(0.0, 0.5)] = 0.5
    """The largest rate given, in [0, 0.5] (the unbiased loss divides by 1 - 2 e, so its learners cap
    lower)."""
    estimated = True

    def __post_init__(self) -> None:
        check_fields(self)

    def rate(self, preferences: Callable[[], PreferenceSet], low: float, high: float) -> float:
        return min(self.cap, likelihood_noise(preferences(), low, high))

"""Algorithm 5 (A.9): estimate the fraction of noisy preferences from conflicts among them.

Algorithm 5 counts, for each preference D_i, the preferences it "is conflicting with" (l.4), but the paper
never defines a conflict. Its only example: "a conflict occurs when there's two preferences A and B, where
A suggests 0.5m is a better parameter candidate than 0.6m while B suggests vice versa". Two readings fit:

- "same_pair" (the example taken literally): A and B compare the same two candidates and prefer different
  ones, whatever order each was shown in. Two preferences about different pairs never conflict.
- "no_common_parameter" (the example generalised): 'a preferred over b' says the true parameter is nearer
  a than b, i.e. it lies strictly on a's side of the midpoint m = (a + b) / 2: below m if a < b, above m if
  a > b. Two preferences conflict when no parameter satisfies both. Two 'below' (or two 'above') half-lines
  always overlap, so a conflict needs one 'below m_u' and one 'above m_l' with m_l >= m_u; the example is
  the special case m_l = m_u. The half-lines are open because a strict preference excludes the midpoint
  itself. Every midpoint of two distinct candidates lies strictly inside the candidate range, so
  intersecting the half-lines within the range gives the same answer as on the whole line.

Every same-pair conflict is also a no-common-parameter conflict, never the reverse, so the second reading
counts at least as many conflicts. On Table 3's datasets of 5 candidates 0.1 m apart (the example's spacing)
the same-pair reading comes closer to the paper's numbers (`hipref.experiments.noise_estimation`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hipref.validation import check_choice

CONFLICTS: tuple[str, ...] = ("same_pair", "no_common_parameter")
"""The readings of 'D_i is conflicting with D_j' (Alg. 5 l.4); see the module docstring."""

DEFAULT_CONFLICT = "no_common_parameter"
"""The reading `conflict_counts` and `estimate_noise` use unless told otherwise."""


@dataclass(frozen=True, eq=False)
class PreferenceSet:
    """A dataset D of pairwise preferences, as parallel arrays."""

    first: np.ndarray
    """phi_0 of each preference, in parameter units."""
    second: np.ndarray
    """phi_1 of each preference; never equal to phi_0."""
    label: np.ndarray
    """y in {-1, 1}: 1 means phi_0 was preferred (Eq. 2)."""

    def __post_init__(self) -> None:
        first, second, label = (
            np.asarray(a, dtype=np.float64).reshape(-1) for a in (self.first, self.second, self.label)
        )
        if not len(first) == len(second) == len(label):
            raise ValueError(
                "first, second and label must have equal length, "
                f"got {len(first)}, {len(second)}, {len(label)}"
            )
        if not (np.all(np.isfinite(first)) and np.all(np.isfinite(second))):
            raise ValueError("first and second must be finite numbers")
        if np.any(first == second):
            raise ValueError(
                "each preference must compare two different values, "
                f"got equal ones at {np.flatnonzero(first == second).tolist()}"
            )
        if not np.all((label == 1) | (label == -1)):
            raise ValueError(f"label must contain only -1 and 1, got {np.unique(label).tolist()}")
        for name, value in (("first", first), ("second", second), ("label", label)):
            object.__setattr__(self, name, value)

    def __len__(self) -> int:
        return len(self.label)


def conflict_counts(preferences: PreferenceSet, conflict: str = DEFAULT_CONFLICT) -> np.ndarray:
    """Alg. 5 l.1-13: C[i] = the number of preferences D_i conflicts with, under the reading `conflict`.

    `conflict`: "same_pair" (the same two candidates, opposite answers: A.9's "A suggests 0.5m is a better
    parameter candidate than 0.6m while B suggests vice versa") or "no_common_parameter" (no parameter
    value is nearer both preferred candidates than their rivals). Both count in O(|D| log |D|) instead of
    the pseudo-code's double loop; each conflicting pair still adds one to both C[i] and C[j].
    """
    check_choice("conflict", conflict, CONFLICTS)
    preferred = np.where(preferences.label == 1, preferences.first, preferences.second)
    other = np.where(preferences.label == 1, preferences.second, preferences.first)
    if conflict == "same_pair":
        return _same_pair_counts(preferred, other)
    return _no_common_parameter_counts(preferred, other)


def _same_pair_counts(preferred: np.ndarray, other: np.ndarray) -> np.ndarray:
    """Per preference, how many preferences about the same two candidates chose the other one."""
    n = len(preferred)
    if n == 0:
        return np.zeros(0, dtype=np.int64)
    prefers_lower = preferred < other
    # Values equal in exact arithmetic can differ in the last bit; count them as equal (the same pair).
    tolerance = 1e-9 * max(1.0, float(np.abs(preferred).max()), float(np.abs(other).max()))
    # One integer per distinct value (values within `tolerance` of their neighbour share it), so that
    # a pair shown as (0.5, 0.6) and as (0.6, 0.5) gets one key.
    values = np.concatenate([np.minimum(preferred, other), np.maximum(preferred, other)])
    order = np.argsort(values, kind="stable")
    sorted_ids = np.concatenate([[0], np.cumsum(np.diff(values[order]) > tolerance)])
    ids = np.empty(2 * n, dtype=np.int64)
    ids[order] = sorted_ids
    _, pair = np.unique(ids[:n] * (sorted_ids[-1] + 1) + ids[n:], return_inverse=True)
    chose_lower = np.bincount(pair, weights=prefers_lower).astype(np.int64)
    chose_higher = np.bincount(pair, weights=~prefers_lower).astype(np.int64)
    return np.where(prefers_lower, chose_higher[pair], chose_lower[pair])


def _no_common_parameter_counts(preferred: np.ndarray, other: np.ndarray) -> np.ndarray:
    """Per preference, how many preferences no parameter value satisfies together with it."""
    midpoint = (preferred + other) / 2.0
    below = preferred < other  # says: true parameter < midpoint; otherwise > midpoint
    # Midpoints equal in exact arithmetic can differ in the last bit; count them as equal (a conflict).
    tolerance = 1e-9 * max(1.0, float(np.abs(midpoint).max(initial=0.0)))
    upper_bounds, lower_bounds = np.sort(midpoint[below]), np.sort(midpoint[~below])
    counts = np.empty(len(preferred), dtype=np.int64)
    # A 'below m_i' conflicts with every 'above m_j' having m_j >= m_i, and vice versa.
    counts[below] = len(lower_bounds) - np.searchsorted(
        lower_bounds, midpoint[below] - tolerance, side="left"
    )
    counts[~below] = np.searchsorted(upper_bounds, midpoint[~below] + tolerance, side="right")
    return counts


def estimate_noise(preferences: PreferenceSet, conflict: str = DEFAULT_CONFLICT) -> float:
    """Algorithm 5: the fraction of preferences with at least the mean number of conflicts.

    `conflict` is the reading of a conflict (`CONFLICTS`, see `conflict_counts`); it is checked before
    anything is counted. As written, data without conflicts has C = 0 everywhere, so mu = 0, every
    C[i] >= mu, and the estimate is 1.0: the algorithm cannot tell 'no conflicts' from 'all suspect'. We
    implement it as written.
    """
    check_choice("conflict", conflict, CONFLICTS)
    if len(preferences) == 0:
        raise ValueError("preferences must hold at least one preference, got an empty set")
    counts = conflict_counts(preferences, conflict)
    # Alg. 5 l.14: the mean mu of C
    mu = counts.mean()
    # Alg. 5 l.16-21: N = #{i : C[i] >= mu}
    n_suspect = int(np.count_nonzero(counts >= mu))
    return n_suspect / len(preferences)

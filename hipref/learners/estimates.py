"""The estimate the controller is given from a posterior over phi (beyond the paper; the Bayesian learner's,
`hipref.learners.bayes`): the value most probably within one step of the truth ('within_step', the
default), the posterior's median or mean, or ('expected_success') the value maximising the expected success
under a measured success-against-error curve (notebook 05).

The posterior's median is a poor estimate when the models disagree: the kinds that explain the same
answers differently (a graded model reading a flip as a truth near the pair's midpoint) place phi
differently, and the median of their blend can lie where none of them puts much mass. The default
estimate is instead the value with the most posterior mass within one step of Phi around it: the Bayes
decision for notebook 12's criterion, an estimate within one step of the truth. On two grids of 40
environments (8 truths x 5 seeds per domain, none of notebook 12's; information gain, 200 answers), the
learner told nothing needed more than 1.25 times the answers of the learner told the model under 13 of
24 settings (per grid, the 12 of notebook 12's claim but the myopic teacher's, where neither gets within
one step) with the median of the most probable kind, and under 7 with this estimate read as points (below).
Scoring queries on every model rather than the heaviest six left 3 of 12 over on one grid, as this estimate
alone did, at twice the time.

A cell's weight stands for a stretch of Phi (`Stretches`): at refine 4 a cell between two pair midpoints
stands for the whole interval between them (half a step), where the flip model's posterior is constant, so a
value one step from its centre has only half of it within one step (under the graded models the likelihood
varies inside the interval, and spreading the weight evenly approximates it). Read as points, the cells let
the estimate sit one step from the posterior's bulk, gathering a tail on its other side, and miss a truth in
the bulk's far half: in notebook 12 (full profile) the learner told the stochastic teacher's model needed 130
answers to be within one step in 90 % of the wiping environments read so, and 55 read by stretches. On the two
grids above, with the pairs within the belief's central 99.8 %, the learner told nothing is over 1.25 times
the answers of the learner told the model under 6 of 24 settings read by stretches (4 of 24 with the pairs
within its central half, `hipref.learners.queries`).
"""

from __future__ import annotations

import numpy as np

from hipref.validation import check_choice

ESTIMATES: tuple[str, ...] = ("within_step", "median", "mean", "expected_success")
"""What the controller is given from Pr(phi | answers) (module docstring): the value with the most mass
within one step of Phi around it (the estimate most probably within one step of the truth), the median (of
least expected absolute error), the mean, or the value of highest expected success."""

SuccessCurve = tuple[np.ndarray, np.ndarray]
"""(signed estimate errors, success rates) measured at them, errors increasing (notebook 05)."""

Stretches = tuple[np.ndarray, np.ndarray]
"""Per cell of a posterior, (low, high): the stretch of Phi its weight is spread over, uniformly; a cell
with low == high is a point (`hipref.learners.bayes.PreferencePosterior.stretches`)."""


def cell_stretches(cells: np.ndarray, half: int) -> Stretches:
    """(low, high) per cell: every `half`-th cell (a pair midpoint or an end of the range) a point, the
    `half` - 1 cells between two of them tiling the interval between them, the first and last reaching its
    ends. Each end is a neighbouring cell or the midpoint of two, so consecutive stretches meet exactly."""
    inside = np.arange(cells.size) % half
    before = np.concatenate([cells[:1], cells[:-1]])
    after = np.concatenate([cells[1:], cells[-1:]])
    low = np.where(inside == 1, before, (before + cells) / 2)
    high = np.where(inside == half - 1, after, (cells + after) / 2)
    return np.where(inside == 0, cells, low), np.where(inside == 0, cells, high)


def check_success_curve(success: SuccessCurve) -> None:
    """Refuse a success curve whose errors are not strictly increasing, whose arrays differ in length, or
    whose rates lie outside [0, 1]."""
    errors, rates = (np.asarray(a, dtype=np.float64) for a in success)
    if errors.ndim != 1 or errors.shape != rates.shape or errors.size < 2:
        raise ValueError(
            f"success_curve must be two 1-d arrays of one length >= 2, got {errors.shape} and {rates.shape}"
        )
    if not np.all(np.diff(errors) > 0):
        raise ValueError(f"success_curve's errors must be strictly increasing, got {errors.tolist()}")
    if not np.all((rates >= 0) & (rates <= 1)):
        raise ValueError(f"success_curve's rates must lie in [0, 1], got {rates.tolist()}")


def read_estimate(
    reading: str,
    cells: np.ndarray,
    weights: np.ndarray,
    step: float,
    success: SuccessCurve | None = None,
    stretches: Stretches | None = None,
) -> float:
    """The estimate `reading` (one of ESTIMATES) of the posterior `weights` over `cells`; `step` is Phi's
    resolution, `success` the curve 'expected_success' needs, `stretches` what each cell stands for (None:
    every cell a point; 'median' and 'mean' read the cells themselves)."""
    check_choice("reading", reading, ESTIMATES)
    if reading == "median":
        return float(cells[min(int(np.searchsorted(np.cumsum(weights), 0.5)), cells.size - 1)])
    if reading == "mean":
        return float(weights @ cells)
    if reading == "within_step":
        return most_within(cells, weights, step, stretches)
    if success is None:
        raise ValueError("estimate 'expected_success' needs a success_curve (errors, success rates)")
    check_success_curve(success)
    return most_expected(cells, weights, success, stretches)


def most_expected(
    cells: np.ndarray, weights: np.ndarray, success: SuccessCurve, stretches: Stretches | None = None
) -> float:
    """The cell with the highest `expected_success`; of several equally good, the middle one (a flat
    posterior is estimated by its centre)."""
    return _middle_best(cells, expected_success(cells, weights, success, stretches))


def expected_success(
    cells: np.ndarray, weights: np.ndarray, success: SuccessCurve, stretches: Stretches | None = None
) -> np.ndarray:
    """Per cell x, sum_c Pr(c) S(x - phi), S the curve interpolated and zero beyond it, averaged over phi in
    the stretch cell c stands for (None: cells are points)."""
    errors, rates = (np.asarray(a, dtype=np.float64) for a in success)
    at_points = np.interp(cells[:, None] - cells[None, :], errors, rates, left=0.0, right=0.0)
    if stretches is None:
        return np.asarray(at_points @ weights)
    low, high = stretches
    width = high - low
    spread = width > 0
    # The mean of S(x - phi) over phi in [low, high]: (F(x - low) - F(x - high)) / width, F' = S.
    area = _integral(errors, rates, cells[:, None] - low[None, :]) - _integral(
        errors, rates, cells[:, None] - high[None, :]
    )
    per_cell = np.where(spread[None, :], area / np.where(spread, width, 1.0)[None, :], at_points)
    return np.asarray(per_cell @ weights)


def most_within(
    cells: np.ndarray, weights: np.ndarray, step: float, stretches: Stretches | None = None
) -> float:
    """The cell x with the most mass within `step` of it (`most_expected` with S one on [-step, step]), from
    the posterior's distribution function; of several equally good, the middle one."""
    step = step * (1 + 1e-9)  # cells a step apart by rounding count as within it
    low, high = (cells, cells) if stretches is None else stretches
    return _middle_best(
        cells, _mass_below(cells + step, low, high, weights) - _mass_below(cells - step, low, high, weights)
    )


def _mass_below(t: np.ndarray, low: np.ndarray, high: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """The posterior's mass at or below each t, each cell's weight spread over its stretch [low, high]
    (stretches in order, not overlapping)."""
    cumulative = np.concatenate([[0.0], np.cumsum(weights)])
    below = np.searchsorted(high, t, side="right")  # cells wholly at or below t
    inside = np.minimum(below, weights.size - 1)
    width = high[inside] - low[inside]
    share = np.where(width > 0, np.clip((t - low[inside]) / np.where(width > 0, width, 1.0), 0.0, 1.0), 0.0)
    return cumulative[below] + np.where(below < weights.size, weights[inside] * share, 0.0)


def _integral(errors: np.ndarray, rates: np.ndarray, t: np.ndarray) -> np.ndarray:
    """F(t), the integral from -inf to t of the curve (errors, rates) interpolated and zero beyond it."""
    lengths = np.diff(errors)
    areas = np.concatenate([[0.0], np.cumsum(0.5 * (rates[:-1] + rates[1:]) * lengths)])
    k = np.clip(np.searchsorted(errors, t, side="right") - 1, 0, errors.size - 2)
    u = np.clip(t, errors[0], errors[-1]) - errors[k]
    slope = (rates[k + 1] - rates[k]) / lengths[k]
    return areas[k] + rates[k] * u + 0.5 * slope * u**2


def _middle_best(cells: np.ndarray, scores: np.ndarray) -> float:
    best = np.flatnonzero(scores >= scores.max() * (1 - 1e-9))
    return float(cells[best[best.size // 2]])

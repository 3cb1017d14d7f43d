"""One place that decides whether a claim of the paper holds: paired differences, trends and their verdicts.

Every verdict in `results/claims.md` ("yes", "no" or "partly", `hipref.results.HOLDS`) comes from an
interval computed here and one of the rules below, so that two notebooks testing the same kind of claim
cannot disagree on what "better" or "grows" means.

- Comparisons are paired: a method and its baseline are matched on the same keys (by default the domain,
  the true parameter and the seed, which fix the environment, the teacher's draws and the evaluation
  episodes), and the interval is a bootstrap over the pairs (`paired_difference`).
- Trends ("the error grows with the noise") are the least-squares slope of the values on x, with a bootstrap
  over whole units (seeds, datasets), each unit keeping all its x values (`trend`).
- Intervals are 95% percentile intervals from a fixed-seed bootstrap, so the same rows always give the same
  verdict.

Rules, each strict so that equal values can never pass (a mean or slope within rounding error of zero is
zero, `_ROUNDING`):

- `better`: "yes" if the whole interval lies strictly on the better side of zero, "partly" if only the mean
  does, "no" otherwise (a zero mean included).
- `no_difference`: "yes" if the interval contains zero, "no" otherwise.
- `increases` / `decreases`: "yes" only if the whole interval of the slope lies strictly above (below)
  zero, "no" otherwise.
- `within`: "yes" if the whole interval lies inside [low, high], "partly" if only the mean does, else "no".
- `combine`: "yes" if every part holds, "no" if none does, "partly" otherwise.

A claim on a learning curve, for instance "CO-PESI has a lower error than PESI at 20% noise":

    final = rows[(rows.domain == "pushing") & (rows.noise == 0.2)]
    error = paired_difference(final, metric="param_error", method="co_pesi", baseline="pesi")
    holds = better(error, lower_is_better=True)

and a trend, "the error grows with the noise" (one unit per seed, all noise levels in each):

    pesi = rows[(rows.domain == "pushing") & (rows.metric == "param_error") & (rows.method == "pesi")]
    last = pesi[pesi.episode == pesi.episode.max()]
    holds = increases(trend(last, x="noise", units=("ground_truth", "seed")))
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from hipref.results import HOLDS
from hipref.validation import check_int

CONFIDENCE = 0.95
"""Coverage of every interval: the 2.5% and 97.5% quantiles of the bootstrap distribution."""

PAIR_KEYS: tuple[str, ...] = ("domain", "ground_truth", "seed")
"""What makes two runs a pair: the same domain, true parameter and seed, hence the same evaluation data."""

_BLOCK = 1000
"""Bootstrap resamples drawn at a time, which bounds the memory of a resampling over many units."""

_ROUNDING = 1e-9
"""Results below this fraction of the data's largest magnitude are rounding error and read as zero: the
mean of differences that cancel (-0.2 and 0.8 - 0.6) or the least-squares slope of equal values is rarely
exactly 0.0 in floating point, and must not pass as a small effect. For a slope the measure is its change
over the whole x range, against the largest |y|."""


@dataclass(frozen=True)
class Difference:
    """A mean with its 95% bootstrap interval: low <= mean <= high up to resampling noise."""

    mean: float
    """The point estimate: the mean over all pairs (or values)."""
    low: float
    """2.5% quantile of the bootstrap means."""
    high: float
    """97.5% quantile of the bootstrap means."""
    n: int
    """How many pairs (or values) the mean is over; with one, low == mean == high."""


@dataclass(frozen=True)
class Trend:
    """A least-squares slope of y on x with its 95% bootstrap interval over resampled units."""

    slope: float
    """The slope over all rows, in units of y per unit of x."""
    low: float
    """2.5% quantile of the bootstrap slopes."""
    high: float
    """97.5% quantile of the bootstrap slopes."""
    n: int
    """How many units (seeds, datasets) were resampled."""


def bootstrap_mean(
    values: Sequence[float] | np.ndarray,
    *,
    strata: Sequence[object] | np.ndarray | None = None,
    resamples: int = 5000,
    seed: int = 0,
) -> Difference:
    """The mean of `values` with a 95% bootstrap interval (values resampled with replacement).

    `strata`: one label per value; values are then resampled within their stratum, which keeps each
    stratum's size (for levels fixed by the design, such as Table 3's noise levels). The draws depend only
    on `seed` and the order of `values`. With one value the interval is the value itself. A mean or bound
    within rounding error of zero (`_ROUNDING`) is 0.0.
    """
    check_int("resamples", resamples, 1)
    check_int("seed", seed, 0)
    data = np.asarray(values, dtype=np.float64).reshape(-1)
    if data.size == 0:
        raise ValueError("values must hold at least one number, got none")
    if not np.all(np.isfinite(data)):
        raise ValueError(f"values must be finite numbers, got {data[~np.isfinite(data)][:3].tolist()}")
    floor = _ROUNDING * float(np.abs(data).max())
    mean = _snap(float(data.mean()), floor)
    if data.size == 1:
        return Difference(mean, mean, mean, 1)
    groups = _strata_indices(strata, data.size)
    rng = np.random.default_rng(seed)
    means = np.empty(resamples)
    for start in range(0, resamples, _BLOCK):
        size = min(_BLOCK, resamples - start)
        total = np.zeros(size)
        for index in groups:
            total += data[index[rng.integers(index.size, size=(size, index.size))]].sum(axis=1)
        means[start : start + size] = total / data.size
    low, high = np.quantile(means, [(1 - CONFIDENCE) / 2, (1 + CONFIDENCE) / 2])
    return Difference(mean, _snap(float(low), floor), _snap(float(high), floor), int(data.size))


def paired_difference(
    frame: pd.DataFrame,
    *,
    metric: str,
    method: str,
    baseline: str,
    keys: Sequence[str] = PAIR_KEYS,
    episode: int | None = None,
    resamples: int = 5000,
    seed: int = 0,
    strata: Sequence[str] = (),
) -> Difference:
    """`method` minus `baseline` on `metric`, paired on `keys`, at one episode.

    `frame` holds tidy rows (at least method, metric, episode, value and every column of `keys`). A pair
    is one row of each method with equal keys; the difference is averaged over the pairs and its 95%
    interval comes from resampling the pairs with replacement (`bootstrap_mean`, seeded by `seed`, within
    the groups of the `strata` columns if given). Pairs are sorted by their keys first, so the order of
    the rows changes nothing.

    `episode`: the checkpoint compared; None takes the last episode present in either method's rows.

    A row without a partner (one method's run missing) is dropped: `n` counts the pairs actually formed.
    Refused with ValueError: a missing column, a method or metric absent from the frame, no pair at all,
    two rows of one method with the same keys (the frame mixes, e.g., noise levels; select one first), or
    a value that is not finite.
    """
    missing = [c for c in ("method", "metric", "episode", "value", *keys, *strata) if c not in frame.columns]
    if missing:
        raise ValueError(f"frame lacks column(s) {missing} needed to pair on keys={tuple(keys)!r}")
    if not keys:
        raise ValueError("keys must name at least one column to pair on, got ()")
    rows = frame[frame["metric"] == metric]
    if rows.empty:
        raise ValueError(f"no rows of metric={metric!r}; metrics present: {sorted(frame['metric'].unique())}")
    for role, name in (("method", method), ("baseline", baseline)):
        if not (rows["method"] == name).any():
            raise ValueError(
                f"{role}={name!r} has no rows of metric {metric!r}; methods present: "
                f"{sorted(rows['method'].unique())}"
            )
    if episode is None:
        episode = int(rows.loc[rows["method"].isin([method, baseline]), "episode"].max())
    at = rows[rows["episode"] == episode]
    columns = [*keys, *[s for s in strata if s not in keys]]
    sides = []
    for name in (method, baseline):
        side = at[at["method"] == name]
        _check_unique(side, keys, name, episode)
        sides.append(side[[*columns, "value"]])
    pairs = sides[0].merge(sides[1], on=columns, suffixes=("_method", "_baseline"))
    if pairs.empty:
        raise ValueError(
            f"no pairs of {method!r} and {baseline!r} on keys {tuple(keys)!r} for metric {metric!r} at "
            f"episode {episode}: {len(sides[0])} and {len(sides[1])} rows there share no keys"
        )
    pairs = pairs.sort_values(list(columns), kind="stable")
    difference = (pairs["value_method"] - pairs["value_baseline"]).to_numpy(dtype=np.float64)
    if not np.all(np.isfinite(difference)):
        raise ValueError(f"values of {method!r} or {baseline!r} for metric {metric!r} are not finite")
    labels = _labels(pairs, strata) if strata else None
    return bootstrap_mean(difference, strata=labels, resamples=resamples, seed=seed)


def paired_differences_by_episode(
    frame: pd.DataFrame,
    *,
    metric: str,
    method: str,
    baseline: str,
    keys: Sequence[str] = PAIR_KEYS,
    resamples: int = 5000,
    seed: int = 0,
    strata: Sequence[str] = (),
) -> pd.DataFrame:
    """`paired_difference` at every checkpoint both methods have: columns episode, mean, low, high, n."""
    if "episode" not in frame.columns or "method" not in frame.columns or "metric" not in frame.columns:
        raise ValueError("frame must have the columns method, metric and episode")
    rows = frame[frame["metric"] == metric]
    episodes = sorted(
        set(rows.loc[rows["method"] == method, "episode"])
        & set(rows.loc[rows["method"] == baseline, "episode"])
    )
    if not episodes:
        raise ValueError(f"{method!r} and {baseline!r} share no episode of metric {metric!r}")
    out = []
    for episode in episodes:
        d = paired_difference(
            frame,
            metric=metric,
            method=method,
            baseline=baseline,
            keys=keys,
            episode=int(episode),
            resamples=resamples,
            seed=seed,
            strata=strata,
        )
        out.append({"episode": int(episode), "mean": d.mean, "low": d.low, "high": d.high, "n": d.n})
    return pd.DataFrame(out, columns=["episode", "mean", "low", "high", "n"])


def trend(
    frame: pd.DataFrame,
    *,
    x: str,
    y: str = "value",
    units: Sequence[str] = ("seed",),
    strata: Sequence[str] = (),
    resamples: int = 5000,
    seed: int = 0,
) -> Trend:
    """The least-squares slope of `y` on `x` over all rows, with a 95% bootstrap interval.

    A resample draws whole units (the rows sharing the `units` columns, e.g. one seed at every noise level)
    with replacement, within the groups of the `strata` columns if given (e.g. one group per noise level
    when each unit is a dataset at one level, so that every resample keeps every level), and refits the
    slope. Units are sorted first, so the order of the rows changes nothing. A resample in which x does not
    vary has no slope and is left out. Slopes that are rounding error (`_ROUNDING`) count as zero, so
    equal values give a slope of exactly 0.0 and an interval [0, 0].
    """
    check_int("resamples", resamples, 1)
    check_int("seed", seed, 0)
    missing = [c for c in (x, y, *units, *strata) if c not in frame.columns]
    if missing:
        raise ValueError(f"frame lacks column(s) {missing} needed for the trend of {y!r} on {x!r}")
    if not units:
        raise ValueError("units must name at least one column, got ()")
    columns = list(dict.fromkeys([*strata, *units]))
    # x may itself tell units apart (one dataset per noise level): each column once.
    order = list(dict.fromkeys([*columns, x, y]))
    data = frame[order].sort_values(order, kind="stable")
    xs, ys = data[x].to_numpy(dtype=np.float64), data[y].to_numpy(dtype=np.float64)
    if not (np.all(np.isfinite(xs)) and np.all(np.isfinite(ys))):
        raise ValueError(f"{x!r} and {y!r} must be finite numbers")
    if xs.size == 0 or np.ptp(xs) == 0:
        raise ValueError(f"a trend needs at least two distinct values of {x!r}, got {np.unique(xs).tolist()}")
    # Centring changes no slope and keeps the sums below well conditioned.
    xc, yc = xs - xs.mean(), ys - ys.mean()
    unit = data.groupby(columns, sort=True, observed=True, dropna=False).ngroup().to_numpy()
    # Per unit: (count, sum x, sum y, sum x^2, sum xy); a resample's fit needs only their totals.
    stats = np.zeros((unit.max() + 1, 5))
    for column, weight in enumerate((np.ones_like(xc), xc, yc, xc * xc, xc * yc)):
        stats[:, column] = np.bincount(unit, weights=weight)
    floor = _ROUNDING * float(np.abs(ys).max()) / float(np.ptp(xs))
    point = _slopes(stats.sum(axis=0, keepdims=True), floor)[0]
    n_units = stats.shape[0]
    if n_units == 1:
        return Trend(float(point), float(point), float(point), 1)
    unit_strata = data.groupby(columns, sort=True, observed=True, dropna=False).head(1)
    groups = _strata_indices(_labels(unit_strata, strata) if strata else None, n_units)
    rng = np.random.default_rng(seed)
    slopes = np.empty(resamples)
    for start in range(0, resamples, _BLOCK):
        size = min(_BLOCK, resamples - start)
        totals = np.zeros((size, 5))
        for index in groups:
            totals += stats[index[rng.integers(index.size, size=(size, index.size))]].sum(axis=1)
        slopes[start : start + size] = _slopes(totals, floor)
    slopes = slopes[np.isfinite(slopes)]
    if slopes.size == 0:
        raise ValueError(f"no resample of the units varies {x!r}; give strata that hold several x values")
    low, high = np.quantile(slopes, [(1 - CONFIDENCE) / 2, (1 + CONFIDENCE) / 2])
    return Trend(float(point), float(low), float(high), int(n_units))


def better(difference: Difference, lower_is_better: bool) -> str:
    """'yes' if the whole interval is strictly on the better side of zero, 'partly' if only the mean is."""
    sign = -1.0 if lower_is_better else 1.0
    if sign * difference.mean <= 0:
        return "no"
    wholly = difference.high < 0 if lower_is_better else difference.low > 0
    return "yes" if wholly else "partly"


def no_difference(difference: Difference) -> str:
    """'yes' if the interval contains zero (no difference can be measured), else 'no'."""
    return "yes" if difference.low <= 0 <= difference.high else "no"


def increases(result: Trend) -> str:
    """'yes' only if the whole interval of the slope is strictly above zero: equal values give 'no'."""
    return "yes" if result.low > 0 else "no"


def decreases(result: Trend) -> str:
    """'yes' only if the whole interval of the slope is strictly below zero: equal values give 'no'."""
    return "yes" if result.high < 0 else "no"


def within(difference: Difference, low: float, high: float) -> str:
    """For 'about X' claims: 'yes' if the whole interval is in [low, high], 'partly' if only the mean is."""
    if not low <= high:
        raise ValueError(f"low must not exceed high, got low={low!r}, high={high!r}")
    if low <= difference.low and difference.high <= high:
        return "yes"
    return "partly" if low <= difference.mean <= high else "no"


def at_most(value: float, limit: float) -> str:
    """For counts read off every environment at once (answers needed in 90 % of them): 'yes' if `value`
    is at most `limit`, 'no' otherwise or when it was never reached (NaN)."""
    return "yes" if np.isfinite(value) and value <= limit else "no"


def combine(verdicts: Sequence[str]) -> str:
    """One verdict for a claim tested several ways: 'yes' if all hold, 'no' if none does, else 'partly'."""
    if not verdicts:
        raise ValueError("verdicts must hold at least one verdict, got none")
    for held in verdicts:
        if held not in HOLDS:
            raise ValueError(f"each verdict must be one of {HOLDS}, got {held!r}")
    if all(held == "yes" for held in verdicts):
        return "yes"
    return "no" if all(held == "no" for held in verdicts) else "partly"


def _snap(value: float, floor: float) -> float:
    """`value`, or 0.0 if it is rounding error (`_ROUNDING`)."""
    return 0.0 if abs(value) <= floor else value


def _slopes(totals: np.ndarray, floor: float) -> np.ndarray:
    """Least-squares slopes from rows of (count, sum x, sum y, sum x^2, sum xy); NaN where x is constant."""
    count, sx, sy, sxx, sxy = totals.T
    denominator = count * sxx - sx * sx
    numerator = count * sxy - sx * sy
    # With x centred, the denominator is count * sum((x - mean x)^2): rounding-sized when x is constant.
    varies = denominator > 1e-9 * count * sxx
    with np.errstate(divide="ignore", invalid="ignore"):
        slope = np.where(varies, numerator / denominator, np.nan)
    slope[np.abs(slope) <= floor] = 0.0
    return slope


def _labels(frame: pd.DataFrame, columns: Sequence[str]) -> np.ndarray:
    """One integer per distinct combination of `columns`, row by row."""
    return frame.groupby(list(columns), sort=True, observed=True, dropna=False).ngroup().to_numpy()


def _strata_indices(strata: Sequence[object] | np.ndarray | None, size: int) -> list[np.ndarray]:
    """Positions of each stratum (all positions when there are no strata), in sorted label order."""
    if strata is None:
        return [np.arange(size)]
    labels = np.asarray(strata)
    if labels.shape != (size,):
        raise ValueError(f"strata must hold one label per value ({size}), got shape {labels.shape}")
    _, inverse = np.unique(labels, return_inverse=True)
    return [np.flatnonzero(inverse == k) for k in range(inverse.max() + 1)]


def _check_unique(side: pd.DataFrame, keys: Sequence[str], method: str, episode: int) -> None:
    """Refuse two rows of one method with the same keys, naming the columns that tell them apart."""
    duplicated = side.duplicated(list(keys), keep=False).to_numpy()
    if not duplicated.any():
        return
    clash = side[duplicated]
    ignore = {*keys, "value", "metric", "method", "episode"}
    varying = [
        c for c in clash.columns if c not in ignore and clash.groupby(list(keys))[c].nunique().gt(1).any()
    ]
    raise ValueError(
        f"{int(duplicated.sum())} rows of method {method!r} at episode {episode} share their keys "
        f"{tuple(keys)!r}; they differ in {varying or 'no other column'}: select one value of those first"
    )

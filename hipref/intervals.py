"""Paired differences, trends and steps with their bootstrap intervals: what every verdict is read from.

`hipref.verdicts` turns these into the study's verdicts; this module only measures.

- Comparisons are paired: a method and its baseline are matched on the same keys (by default the domain,
  the true parameter and the seed, which fix the environment, the teacher's draws and the evaluation
  episodes), and the interval is a bootstrap over the pairs (`paired_difference`).
- Trends ("the error grows with the noise") are the least-squares slope of the values on x, with a bootstrap
  over whole units (seeds, datasets), each unit keeping all its x values (`trend`); steps ("it falls at
  every checkpoint") are the paired change between each x and the next, unit by unit (`steps`).
- Intervals are 95% percentile intervals from a fixed-seed bootstrap, so the same rows always give the same
  verdict. Over fewer than `MIN_ENVIRONMENTS` independent units no interval is drawn: its bounds are NaN.
- A mean, bound or slope within rounding error of zero (`ROUNDING`) is 0.0, so equal values never pass as a
  small effect.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from hipref.validation import check_int

CONFIDENCE = 0.95
"""Coverage of every interval: the 2.5% and 97.5% quantiles of the bootstrap distribution."""

PAIR_KEYS: tuple[str, ...] = ("domain", "ground_truth", "seed")
"""What makes two runs a pair: the same domain, true parameter and seed, hence the same evaluation data."""

_BLOCK = 1000
"""Bootstrap resamples drawn at a time, which bounds the memory of a resampling over many units."""

MIN_ENVIRONMENTS = 5
"""The fewest independent units (environments, seeds, datasets) a bootstrap interval is drawn over: with
fewer, resampling a handful of values gives intervals as narrow as [+60.0, +60.0] from two seeds, which
look like certainty; below it the bounds are NaN and every verdict is "too few environments to decide"."""

ROUNDING = 1e-6
"""Results below this fraction of the largest magnitude involved are rounding error and read as zero. SI
computes in float32 (relative resolution 1.2e-7): two runs whose updates differ only in the order of a sum
end a few units of the last place apart, and the mean of differences that cancel (-0.2 and 0.8 - 0.6) or the
slope of equal values is rarely exactly 0.0 in floating point; neither may pass as a small effect. For a
paired difference the magnitude is that of the values compared, for a slope its change over the whole x
range against the largest |y|."""


@dataclass(frozen=True)
class Difference:
    """A mean with its 95% bootstrap interval: low <= mean <= high up to resampling noise; low and high are
    NaN over fewer than `MIN_ENVIRONMENTS` values."""

    mean: float
    """The point estimate: the mean over all pairs (or values)."""
    low: float
    """2.5% quantile of the bootstrap means."""
    high: float
    """97.5% quantile of the bootstrap means."""
    n: int
    """How many pairs (or values) the mean is over."""


@dataclass(frozen=True)
class Trend:
    """A least-squares slope of y on x with its 95% bootstrap interval over resampled units (NaN bounds over
    fewer than `MIN_ENVIRONMENTS` units)."""

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
    scale: float = 0.0,
) -> Difference:
    """The mean of `values` with a 95% bootstrap interval (values resampled with replacement).

    `strata`: one label per value; values are then resampled within their stratum, which keeps each
    stratum's size (for levels fixed by the design, such as Table 3's noise levels). The draws depend only
    on `seed` and the order of `values`. Over fewer than `MIN_ENVIRONMENTS` values the bounds are NaN. A
    mean or bound within rounding error (`ROUNDING`) of the larger of the values' magnitude and `scale` (the
    magnitude of the quantities the values are differences of) is 0.0.
    """
    check_int("resamples", resamples, 1)
    check_int("seed", seed, 0)
    data = np.asarray(values, dtype=np.float64).reshape(-1)
    if data.size == 0:
        raise ValueError("values must hold at least one number, got none")
    if not np.all(np.isfinite(data)):
        raise ValueError(f"values must be finite numbers, got {data[~np.isfinite(data)][:3].tolist()}")
    if not np.isfinite(scale) or scale < 0:
        raise ValueError(f"scale must be a finite magnitude >= 0, got {scale!r}")
    floor = ROUNDING * max(float(np.abs(data).max()), scale)
    mean = _snap(float(data.mean()), floor)
    if data.size < MIN_ENVIRONMENTS:
        return Difference(mean, np.nan, np.nan, int(data.size))
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
    scale = float(np.abs(pairs[["value_method", "value_baseline"]].to_numpy(dtype=np.float64)).max())
    return bootstrap_mean(difference, strata=labels, resamples=resamples, seed=seed, scale=scale)


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
    vary has no slope and is left out. Slopes that are rounding error (`ROUNDING`) count as zero, so
    equal values give a slope of exactly 0.0 and an interval [0, 0]. Over fewer than `MIN_ENVIRONMENTS`
    units the bounds are NaN.
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
    floor = ROUNDING * float(np.abs(ys).max()) / float(np.ptp(xs))
    point = _slopes(stats.sum(axis=0, keepdims=True), floor)[0]
    n_units = stats.shape[0]
    if n_units < MIN_ENVIRONMENTS:
        return Trend(float(point), np.nan, np.nan, int(n_units))
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


def steps(
    frame: pd.DataFrame,
    *,
    x: str,
    y: str = "value",
    units: Sequence[str] = ("seed",),
    resamples: int = 5000,
    seed: int = 0,
) -> pd.DataFrame:
    """The change of `y` from each value of `x` to the next, paired within units, with 95% intervals.

    For a claim of a change at every step ("the difference falls at every checkpoint"), where a slope
    would pass a series that rises in places. Each unit (the rows sharing the `units` columns) gives one
    change per step: its y at the next x minus its y at this x; a unit without both is left out of that
    step. Returns one row per step: x_from, x_to, mean, low, high, n (`bootstrap_mean` of the changes).
    """
    missing = [c for c in (x, y, *units) if c not in frame.columns]
    if missing:
        raise ValueError(f"frame lacks column(s) {missing} needed for the steps of {y!r} along {x!r}")
    if not units:
        raise ValueError("units must name at least one column, got ()")
    if frame.duplicated([*units, x]).any():
        raise ValueError(f"each unit {tuple(units)!r} must have one row per {x!r}: select the rest first")
    wide = frame.pivot_table(index=list(units), columns=x, values=y, aggfunc="first").sort_index()
    xs = sorted(wide.columns)
    if len(xs) < 2:
        raise ValueError(f"steps need at least two distinct values of {x!r}, got {xs}")
    out = []
    for before, after in itertools.pairwise(xs):
        change = (wide[after] - wide[before]).dropna().to_numpy(dtype=np.float64)
        if change.size == 0:
            raise ValueError(f"no unit has {y!r} at both {x}={before!r} and {x}={after!r}")
        scale = float(np.nanmax(np.abs(wide[[before, after]].to_numpy(dtype=np.float64))))
        d = bootstrap_mean(change, resamples=resamples, seed=seed, scale=scale)
        out.append({"x_from": before, "x_to": after, "mean": d.mean, "low": d.low, "high": d.high, "n": d.n})
    return pd.DataFrame(out, columns=["x_from", "x_to", "mean", "low", "high", "n"])


def _snap(value: float, floor: float) -> float:
    """`value`, or 0.0 if it is rounding error (`ROUNDING`)."""
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

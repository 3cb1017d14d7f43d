"""Whether a learned pi^l uses its phi as its expert does (notebook 10, issue 29): the outcome of the same
episodes against the estimate error, learned beside expert.

Both low levels execute each episode (a truth, a layout: a seed) at every estimate error, so the slope of an
outcome (pushing: where the cube rests along the push; wiping: the contact force) on the error is measured
for each, and their difference is the slope of the per-episode difference learned - expert, whose interval
resamples whole episodes (`hipref.verdicts.trend`, units the seed). pi^l uses phi as the expert does when
that difference is within `TOLERANCE` of the expert's own slope: 'yes' if its whole interval is, 'partly'
if only its value is (`hipref.verdicts.within`). A pi^l that ignores phi has a slope near 0 and a difference
near minus the expert's slope: 'no'.
"""

from __future__ import annotations

from typing import NamedTuple

import pandas as pd

from hipref import verdicts

TOLERANCE = 0.25
"""How far, as a fraction of the expert's slope, the learned slope may be from it (issue 29: 25 %)."""


class Conditioning(NamedTuple):
    """The slopes of one outcome on the estimate error, and their paired difference."""

    expert: verdicts.Trend
    learned: verdicts.Trend
    difference: verdicts.Trend
    """learned - expert, paired on the episodes."""
    verdict: str
    """'yes', 'partly' or 'no': the difference within TOLERANCE x |expert slope|."""


def conditioning(frame: pd.DataFrame, metric: str, learned: str, expert: str = "admittance") -> Conditioning:
    """The slopes of `metric` on `estimate_error` of the low levels named `learned` and `expert` in the
    `method` column of `frame` (one row per seed, error, method and metric), paired on the seed; episodes
    executed by only one of them are left out."""
    missing = [c for c in ("method", "metric", "seed", "estimate_error", "value") if c not in frame.columns]
    if missing:
        raise ValueError(f"frame lacks column(s) {missing}")
    rows = frame[frame.metric == metric]
    sides = {name: rows[rows.method == name] for name in (expert, learned)}
    for name, side in sides.items():
        if side.empty:
            raise ValueError(f"no rows of method {name!r} and metric {metric!r}")
        if side.duplicated(["seed", "estimate_error"]).any():
            raise ValueError(f"method {name!r} has two rows of one seed and error for {metric!r}")
    keys = ["seed", "estimate_error"]
    pairs = sides[learned][[*keys, "value"]].merge(
        sides[expert][[*keys, "value"]], on=keys, suffixes=("", "_e")
    )
    if pairs.empty:
        raise ValueError(f"{learned!r} and {expert!r} share no episode")
    pairs = pairs.assign(difference=pairs.value - pairs.value_e)
    slope_expert = verdicts.trend(pairs.assign(value=pairs.value_e), x="estimate_error")
    slope_learned = verdicts.trend(pairs, x="estimate_error")
    difference = verdicts.trend(pairs, x="estimate_error", y="difference")
    bound = TOLERANCE * abs(slope_expert.slope)
    as_difference = verdicts.Difference(difference.slope, difference.low, difference.high, difference.n)
    return Conditioning(
        slope_expert, slope_learned, difference, verdicts.within(as_difference, -bound, bound)
    )

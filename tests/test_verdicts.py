"""The verdict rules: paired differences that really pair, trends over whole units, strict verdicts."""

from collections.abc import Callable

import numpy as np
import pandas as pd
import pytest

from hipref.verdicts import (
    Difference,
    better,
    bootstrap_mean,
    combine,
    decreases,
    increases,
    no_difference,
    paired_difference,
    paired_differences_by_episode,
    trend,
    within,
)

TRUTHS = (0.6, 0.8)
SEEDS = range(6)


def _runs(
    effect: float, *, spread: float = 1.0, episodes: tuple[int, ...] = (0, 33), seed: int = 0
) -> pd.DataFrame:
    """Tidy rows of 'base' and 'new' in every (truth, seed) environment; seeds repeat across truths, as in
    the SI studies. An environment's level varies a lot (`spread`), 'new' is `effect` away from 'base' in
    the same environment at the last episode (and equal before), plus a little noise."""
    rng = np.random.default_rng(seed)
    rows = []
    for truth in TRUTHS:
        for s in SEEDS:
            level = rng.normal(0.0, spread)
            for episode in episodes:
                shift = effect if episode == episodes[-1] else 0.0
                for method, value in (("base", level), ("new", level + shift + rng.normal(0.0, 0.01))):
                    rows.append(
                        {
                            "domain": "pushing",
                            "method": method,
                            "noise": 0.2,
                            "seed": s,
                            "episode": episode,
                            "metric": "param_error",
                            "value": value,
                            "ground_truth": truth,
                        }
                    )
    return pd.DataFrame(rows)


def _difference(frame: pd.DataFrame, **kwargs: object) -> Difference:
    return paired_difference(frame, metric="param_error", method="new", baseline="base", **kwargs)


def test_equal_values_are_never_better_and_never_increase() -> None:
    frame = _runs(0.0)
    frame.loc[frame["method"] == "new", "value"] = frame.loc[frame["method"] == "base", "value"].to_numpy()
    difference = _difference(frame)
    assert (difference.mean, difference.low, difference.high) == (0.0, 0.0, 0.0)
    assert better(difference, lower_is_better=True) == "no"
    assert better(difference, lower_is_better=False) == "no"
    assert no_difference(difference) == "yes"
    # Equal at every x, with and without a level of its own per unit: the slope is exactly zero.
    for values in (np.full(30, 0.1), np.repeat(np.random.default_rng(1).normal(size=10), 3)):
        flat = pd.DataFrame({"seed": np.repeat(np.arange(10), 3), "noise": np.tile([0.0, 0.2, 0.4], 10)})
        result = trend(flat.assign(value=values), x="noise")
        assert (result.slope, result.low, result.high) == (0.0, 0.0, 0.0)
        assert increases(result) == "no" and decreases(result) == "no"


def test_differences_that_cancel_up_to_rounding_are_no_difference() -> None:
    cancelling = bootstrap_mean([-0.2, 0.8 - 0.6, 0.3, 0.1 - 0.4])
    assert 0.8 - 0.6 != 0.2 and cancelling.mean == 0.0
    assert better(cancelling, lower_is_better=True) == better(cancelling, lower_is_better=False) == "no"


def test_a_clear_paired_improvement_is_better_although_environments_differ_widely() -> None:
    # Environments differ by about 10 (spread), the effect is 0.2: only pairing can see it.
    difference = _difference(_runs(-0.2, spread=10.0))
    assert difference.n == len(TRUTHS) * len(SEEDS)
    assert difference.mean == pytest.approx(-0.2, abs=0.01)
    assert -0.25 < difference.low < difference.high < -0.15
    assert better(difference, lower_is_better=True) == "yes"
    assert better(difference, lower_is_better=False) == "no"
    assert no_difference(difference) == "no"


def test_a_better_mean_with_an_interval_across_zero_is_partly() -> None:
    assert better(bootstrap_mean([-5.0, 1.0, 1.0, 1.0, 1.0]), lower_is_better=True) == "partly"
    assert better(bootstrap_mean([5.0, -1.0, -1.0, -1.0, -1.0]), lower_is_better=False) == "partly"


def test_shuffling_the_rows_changes_nothing() -> None:
    frame = _runs(-0.1, spread=3.0)
    shuffled = frame.sample(frac=1.0, random_state=7).reset_index(drop=True)
    assert _difference(shuffled) == _difference(frame)
    units = pd.DataFrame({"seed": np.repeat(np.arange(8), 3), "noise": np.tile([0.0, 0.2, 0.4], 8)})
    units["value"] = np.random.default_rng(2).normal(size=len(units)) + units["noise"]
    assert trend(units.sample(frac=1.0, random_state=3), x="noise") == trend(units, x="noise")


def test_pairs_are_matched_on_truth_and_seed_not_on_row_order() -> None:
    frame = _runs(-0.3, spread=5.0)
    # Pair by hand, then scramble the partner values among the environments: the result must change.
    by_hand = _difference(frame)
    wide = frame[frame["episode"] == 33].pivot_table(
        index=["ground_truth", "seed"], columns="method", values="value"
    )
    assert by_hand.mean == pytest.approx((wide["new"] - wide["base"]).mean(), abs=1e-12)
    scrambled = frame.copy()
    new = (scrambled["method"] == "new") & (scrambled["episode"] == 33)
    scrambled.loc[new, "value"] = scrambled.loc[new, "value"].to_numpy()[::-1]
    assert _difference(scrambled).high - _difference(scrambled).low > 10 * (by_hand.high - by_hand.low)


def test_pairing_on_too_few_keys_is_refused_naming_what_tells_rows_apart() -> None:
    # Seeds repeat across truths, so seed alone matches each run with two partners.
    with pytest.raises(ValueError, match=r"share their keys.*ground_truth"):
        _difference(_runs(-0.1), keys=("domain", "seed"))


def test_a_run_without_partner_is_dropped_and_no_partner_at_all_is_refused() -> None:
    frame = _runs(-0.2, spread=2.0)
    lone = (frame["method"] == "new") & (frame["seed"] == 0) & (frame["ground_truth"] == 0.6)
    dropped = _difference(frame[~lone])
    assert dropped.n == len(TRUTHS) * len(SEEDS) - 1
    kept = frame[~((frame["seed"] == 0) & (frame["ground_truth"] == 0.6))]
    assert dropped == _difference(kept)
    apart = frame.copy()
    apart.loc[apart["method"] == "new", "seed"] += 100
    with pytest.raises(ValueError, match="no pairs"):
        _difference(apart)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda f: f.drop(columns="ground_truth"), "ground_truth"),
        (lambda f: f[f["method"] == "base"], "method='new'"),
        (lambda f: f.assign(metric="success_rate"), "param_error"),
    ],
)
def test_what_is_missing_is_named(change: Callable[[pd.DataFrame], pd.DataFrame], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        _difference(change(_runs(-0.1)))


def test_the_default_episode_is_the_last_and_every_checkpoint_gets_a_row() -> None:
    frame = _runs(-0.2, spread=2.0, episodes=(0, 33, 66))
    assert _difference(frame) == _difference(frame, episode=66)
    assert abs(_difference(frame, episode=0).mean) < 0.01
    curve = paired_differences_by_episode(frame, metric="param_error", method="new", baseline="base")
    assert list(curve.columns) == ["episode", "mean", "low", "high", "n"]
    assert curve["episode"].tolist() == [0, 33, 66]
    assert curve["n"].tolist() == [len(TRUTHS) * len(SEEDS)] * 3
    last = curve.iloc[-1]
    assert Difference(last["mean"], last["low"], last["high"], int(last["n"])) == _difference(frame)


def test_the_bootstrap_is_fixed_by_its_seed_and_one_pair_is_its_own_interval() -> None:
    values = np.random.default_rng(4).normal(size=30)
    assert bootstrap_mean(values, seed=5) == bootstrap_mean(values, seed=5)
    assert bootstrap_mean(values, seed=5) != bootstrap_mean(values, seed=6)
    assert bootstrap_mean([0.3]) == Difference(0.3, 0.3, 0.3, 1)
    one = _runs(-0.2)
    one = one[(one["seed"] == 2) & (one["ground_truth"] == 0.8)]
    single = _difference(one)
    assert single.n == 1 and single.low == single.mean == single.high


def test_strata_keep_their_sizes_in_every_resample() -> None:
    # Two strata of constants: resampling within each leaves the mean fixed; across them it does not.
    values = np.r_[np.zeros(10), np.ones(10)]
    stratified = bootstrap_mean(values, strata=np.repeat(["a", "b"], 10))
    assert stratified.low == stratified.high == 0.5
    pooled = bootstrap_mean(values)
    assert pooled.low < 0.4 and pooled.high > 0.6


def test_a_trend_resamples_whole_units() -> None:
    # Every unit lies exactly on a line of slope 2 but at its own level: any resample of whole units has
    # slope 2, whereas resampling single rows would unbalance the levels across x.
    x = np.tile([0.0, 0.1, 0.2, 0.3], 12)
    unit = np.repeat(np.arange(12), 4)
    level = np.random.default_rng(5).normal(0.0, 5.0, 12)
    frame = pd.DataFrame({"seed": unit, "noise": x, "value": level[unit] + 2.0 * x})
    result = trend(frame, x="noise")
    assert result.n == 12
    assert result.slope == pytest.approx(2.0) and result.high - result.low < 1e-9
    assert increases(result) == "yes" and decreases(result) == "no"
    noisy = frame.assign(value=frame["value"] + np.random.default_rng(6).normal(0.0, 1.0, len(frame)))
    wide = trend(noisy, x="noise")
    assert wide.low < 0 < wide.high and increases(wide) == "no"


def test_a_trend_needs_two_x_values() -> None:
    with pytest.raises(ValueError, match="two distinct values of 'noise'"):
        trend(pd.DataFrame({"seed": [0, 1], "noise": [0.2, 0.2], "value": [1.0, 2.0]}), x="noise")


def test_within_and_combine() -> None:
    assert within(Difference(0.06, 0.05, 0.07, 10), 0.04, 0.08) == "yes"
    assert within(Difference(0.07, 0.05, 0.09, 10), 0.04, 0.08) == "partly"
    assert within(Difference(0.098, 0.094, 0.102, 10), 0.04, 0.08) == "no"
    with pytest.raises(ValueError, match="low"):
        within(Difference(0.0, 0.0, 0.0, 1), 0.1, 0.0)
    assert combine(["yes", "yes"]) == "yes"
    assert combine(["no", "no"]) == "no"
    assert combine(["yes", "no"]) == combine(["partly", "partly"]) == "partly"
    with pytest.raises(ValueError, match="maybe"):
        combine(["yes", "maybe"])

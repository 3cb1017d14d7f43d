"""The verdict rules: paired differences that really pair, trends over whole units, steps, strict verdicts
in one vocabulary, and no interval over fewer than five environments."""

from collections.abc import Callable

import numpy as np
import pandas as pd
import pytest

from hipref.verdicts import (
    MIN_ENVIRONMENTS,
    VERDICTS,
    Difference,
    any_of,
    at_most,
    better,
    better_on_both,
    bootstrap_mean,
    combine,
    decreases,
    holds_in_all,
    increases,
    monotone,
    no_difference,
    paired_difference,
    paired_differences_by_episode,
    steps,
    trend,
    within,
)

NONE = "no difference detected"
TOO_FEW = "too few environments to decide"

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
    assert better(difference, lower_is_better=True) == NONE
    assert better(difference, lower_is_better=False) == NONE
    assert no_difference(difference) == "yes"
    # Equal at every x, with and without a level of its own per unit: the slope is exactly zero.
    for values in (np.full(30, 0.1), np.repeat(np.random.default_rng(1).normal(size=10), 3)):
        flat = pd.DataFrame({"seed": np.repeat(np.arange(10), 3), "noise": np.tile([0.0, 0.2, 0.4], 10)})
        result = trend(flat.assign(value=values), x="noise")
        assert (result.slope, result.low, result.high) == (0.0, 0.0, 0.0)
        assert increases(result) == NONE and decreases(result) == NONE


def test_differences_that_cancel_up_to_rounding_are_no_difference() -> None:
    cancelling = bootstrap_mean([-0.2, 0.8 - 0.6, 0.3, 0.1 - 0.4, 0.0])
    assert 0.8 - 0.6 != 0.2 and cancelling.mean == 0.0
    assert better(cancelling, lower_is_better=True) == better(cancelling, lower_is_better=False) == NONE


def test_a_clear_paired_improvement_is_better_although_environments_differ_widely() -> None:
    # Environments differ by about 10 (spread), the effect is 0.2: only pairing can see it.
    difference = _difference(_runs(-0.2, spread=10.0))
    assert difference.n == len(TRUTHS) * len(SEEDS)
    assert difference.mean == pytest.approx(-0.2, abs=0.01)
    assert -0.25 < difference.low < difference.high < -0.15
    assert better(difference, lower_is_better=True) == "yes"
    assert better(difference, lower_is_better=False) == "no"
    assert no_difference(difference) == "no"


def test_a_mean_leaning_either_way_with_an_interval_across_zero_is_no_difference_detected() -> None:
    assert better(bootstrap_mean([-5.0, 1.0, 1.0, 1.0, 1.0]), lower_is_better=True) == NONE
    assert better(bootstrap_mean([5.0, -1.0, -1.0, -1.0, -1.0]), lower_is_better=True) == NONE
    assert better(bootstrap_mean([5.0, 1.0, 1.0, 2.0, 1.0]), lower_is_better=True) == "no"


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


def test_the_bootstrap_is_fixed_by_its_seed() -> None:
    values = np.random.default_rng(4).normal(size=30)
    assert bootstrap_mean(values, seed=5) == bootstrap_mean(values, seed=5)
    assert bootstrap_mean(values, seed=5) != bootstrap_mean(values, seed=6)


def test_below_five_environments_there_is_no_interval_and_every_rule_says_too_few() -> None:
    assert MIN_ENVIRONMENTS == 5
    one = _runs(-0.2)
    one = one[(one["seed"] == 2) & (one["ground_truth"] == 0.8)]
    single = _difference(one)
    assert single.n == 1 and single.mean == pytest.approx(-0.2, abs=0.05)
    assert np.isnan(single.low) and np.isnan(single.high)
    # Two seeds of a large, constant gap (Fig. 2c's case): no interval [+60, +60], and no verdict.
    two = bootstrap_mean([60.0, 60.0])
    assert (two.mean, two.n) == (60.0, 2) and np.isnan(two.low)
    four = bootstrap_mean([1.0, 1.1, 0.9, 1.0])
    for verdict in (
        better(single, lower_is_better=True),
        better(two, lower_is_better=False),
        no_difference(four),
        within(four, 0.0, 2.0),
        better_on_both(four, two),
        at_most(Difference(3.0, 2.0, 4.0, 4), 10.0),
        holds_in_all(True, environments=1),
    ):
        assert verdict == TOO_FEW
    few = pd.DataFrame({"seed": np.repeat(np.arange(4), 3), "noise": np.tile([0.0, 0.2, 0.4], 4)})
    rising = trend(few.assign(value=few["noise"] * 10 + few["seed"] * 0.01), x="noise")
    assert rising.n == 4 and np.isnan(rising.low) and increases(rising) == decreases(rising) == TOO_FEW
    assert bootstrap_mean([1.0, 1.1, 0.9, 1.0, 1.05]).low > 0


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
    assert increases(result) == "yes"
    noisy = frame.assign(value=frame["value"] + np.random.default_rng(6).normal(0.0, 1.0, len(frame)))
    wide = trend(noisy, x="noise")
    assert wide.low < 0 < wide.high and increases(wide) == NONE
    assert decreases(result) == "no"


def test_a_trend_needs_two_x_values() -> None:
    with pytest.raises(ValueError, match="two distinct values of 'noise'"):
        trend(pd.DataFrame({"seed": [0, 1], "noise": [0.2, 0.2], "value": [1.0, 2.0]}), x="noise")


def test_at_most_reads_the_whole_interval_of_a_count() -> None:
    assert at_most(Difference(20.0, 15.0, 29.0, 10), 30.0) == "yes"
    assert at_most(Difference(25.0, 15.0, 45.0, 10), 30.0) == NONE  # the point below, the interval across
    assert at_most(Difference(40.0, 31.0, 50.0, 10), 30.0) == "no"
    # Never reached in any resample: infinite, so contradicted; reached in some: undecided.
    assert at_most(Difference(np.nan, np.nan, np.nan, 10), 30.0) == "no"
    assert at_most(Difference(np.nan, 20.0, np.inf, 10), 30.0) == NONE


def test_within_and_combine() -> None:
    assert within(Difference(0.06, 0.05, 0.07, 10), 0.04, 0.08) == "yes"
    assert within(Difference(0.07, 0.05, 0.09, 10), 0.04, 0.08) == NONE
    assert within(Difference(0.098, 0.094, 0.102, 10), 0.04, 0.08) == "no"
    with pytest.raises(ValueError, match="low"):
        within(Difference(0.0, 0.0, 0.0, 10), 0.1, 0.0)
    assert combine(["yes", "yes"]) == "yes"
    assert combine(["no", "no"]) == combine(["yes", "no"]) == combine([NONE, "no"]) == "no"
    assert combine(["yes", NONE]) == NONE
    assert combine(["yes", "no", TOO_FEW]) == TOO_FEW
    with pytest.raises(ValueError, match="maybe"):
        combine(["yes", "maybe"])
    with pytest.raises(ValueError, match="partly"):
        combine(["partly"])
    assert set(VERDICTS) == {"yes", "no", NONE, TOO_FEW}
    assert any_of(["no", "yes", NONE]) == "yes" and any_of(["no", "no"]) == "no"
    assert any_of(["no", NONE]) == NONE and any_of(["no", TOO_FEW]) == TOO_FEW


def test_better_on_both_needs_both_and_is_contradicted_by_either() -> None:
    lower, higher, flat = Difference(-1, -2, -0.5, 6), Difference(1, 0.5, 2, 6), Difference(0, -1, 1, 6)
    assert better_on_both(lower, higher) == "yes"
    assert better_on_both(lower, flat) == NONE
    assert better_on_both(lower, lower) == "no"


def _series(changes: list[float], units: int = 8) -> pd.DataFrame:
    """A difference at checkpoints 0, 33, ...: each unit follows the cumulative `changes` plus its own
    level and a little noise."""
    rng = np.random.default_rng(3)
    path = np.r_[0.0, np.cumsum(changes)]
    return pd.DataFrame(
        [
            {"seed": u, "episode": 33 * i, "difference": level + p + rng.normal(0.0, 0.01)}
            for u, level in enumerate(rng.normal(0.0, 5.0, units))
            for i, p in enumerate(path)
        ]
    )


def test_a_monotone_claim_is_tested_at_every_step_not_by_the_slope() -> None:
    falling = _series([-0.3, -0.2, -0.4])
    table = steps(falling, x="episode", y="difference")
    assert table[["x_from", "x_to"]].values.tolist() == [[0, 33], [33, 66], [66, 99]]
    assert table["n"].tolist() == [8, 8, 8] and table["mean"].tolist() == pytest.approx(
        [-0.3, -0.2, -0.4], abs=0.02
    )
    assert monotone(table, increasing=False) == "yes" and monotone(table, increasing=True) == "no"
    # Falling overall (a clearly negative slope), but rising at one step: not falling at every step.
    mostly = _series([-0.5, +0.2, -0.6])
    assert decreases(trend(mostly, x="episode", y="difference")) == "yes"
    assert monotone(steps(mostly, x="episode", y="difference"), increasing=False) == "no"
    flat_step = _series([-0.5, 0.0, -0.6])
    assert monotone(steps(flat_step, x="episode", y="difference"), increasing=False) == NONE
    assert (
        monotone(steps(_series([-0.5, -0.5], units=3), x="episode", y="difference"), increasing=False)
        == TOO_FEW
    )
    with pytest.raises(ValueError, match="two distinct values"):
        steps(falling[falling.episode == 0], x="episode", y="difference")

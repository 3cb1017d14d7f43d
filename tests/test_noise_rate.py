"""The flip-rate estimators beside Algorithm 5: their defining properties, and the bias the study claims."""

from __future__ import annotations

import numpy as np
import pytest

from hipref.experiments.noise_estimation import (
    ESTIMATORS,
    NoiseEstimationConfig,
    accuracy,
    dataset_rng,
    random_preferences,
    run,
)
from hipref.learners.noise_estimation import PreferenceSet
from hipref.learners.noise_rate import likelihood_noise, repeated_pair_noise

GRID = NoiseEstimationConfig().candidates  # A.9's 5 heights, 0.1 m apart


@pytest.mark.parametrize("true_noise", [0.0, 0.1, 0.25, 0.45])
def test_the_marginal_likelihood_estimate_is_unbiased_within_0_02(true_noise: float) -> None:
    estimates = [
        likelihood_noise(random_preferences(256, true_noise, GRID, dataset_rng(11, true_noise, r)), 0.5, 0.9)
        for r in range(60)
    ]
    assert abs(np.mean(estimates) - true_noise) < 0.02


def test_preferences_one_truth_explains_give_zero_from_both_estimators() -> None:
    clean = random_preferences(200, 0.0, GRID, np.random.default_rng(2))
    assert likelihood_noise(clean, GRID.low, GRID.high) == 0.0
    assert repeated_pair_noise(clean) == 0.0


def test_the_marginal_likelihood_counts_the_answers_no_truth_explains() -> None:
    # 0.5 over 0.9 (truth below 0.7) nine times, and the opposite once: the best truth violates one of ten.
    first = np.array([0.5] * 10)
    second = np.array([0.9] * 10)
    label = np.array([1] * 9 + [-1])
    estimate = likelihood_noise(PreferenceSet(first, second, label), 0.5, 0.9, resolution=1000)
    assert estimate == pytest.approx(0.1, abs=1e-3)


def test_repeated_pairs_disagree_with_probability_2e_1_minus_e() -> None:
    # One pair asked four times, chosen (lower, lower, higher, lower) in either order of display: 3 of the 6
    # pairs of answers disagree, d = 1/2, so e = 1/2.
    first = np.array([0.5, 0.6, 0.5, 0.6])
    second = np.array([0.6, 0.5, 0.6, 0.5])
    label = np.array([1, -1, -1, -1])
    assert repeated_pair_noise(PreferenceSet(first, second, label)) == pytest.approx(0.5)
    no_repeats = PreferenceSet(np.array([0.5, 0.6]), np.array([0.7, 0.8]), np.array([1, 1]))
    assert np.isnan(repeated_pair_noise(no_repeats))


def test_the_study_reports_each_estimators_bias_and_rmse_per_level() -> None:
    rows = run(NoiseEstimationConfig(repetitions=6, noise_levels=(0.1, 0.3)))
    table = accuracy(rows, resamples=200)
    assert set(table.method) == {"algorithm5_same_pair", "algorithm5_no_common_parameter", *ESTIMATORS}
    assert sorted(table.true_noise.unique()) == [0.1, 0.3]
    assert (table.bias_low <= table.bias).all() and (table.bias <= table.bias_high).all()
    # Each figure recomputed by hand from the rows: per dataset, the estimate minus the true noise it was
    # drawn with (the row's `noise`); the bias is their mean, the RMSE the root of their mean square.
    estimates = rows[rows.metric == "estimated_noise"].dropna(subset=["value"])
    for (method, noise), group in estimates.groupby(["method", "noise"]):
        error = [value - noise for value in group.value]
        row = table[(table.method == method) & (table.true_noise == noise)].iloc[0]
        assert row.bias == pytest.approx(sum(error) / len(error), abs=1e-12)
        assert row.rmse == pytest.approx((sum(e * e for e in error) / len(error)) ** 0.5, abs=1e-12)
        assert row.datasets == len(error)

"""What SI is measured against: the constant guess, strong regressors on the same slices, calibration."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
import torch

from hipref.experiments.constant_guess import CONSTANT_BEST, CONSTANT_MIDDLE, constant_guess_rows
from hipref.experiments.si_pretraining import PretrainData, collect_trajectories, cut_slices
from hipref.experiments.what_tau_tells import TauConfig, regressor_estimates, select_slices
from hipref.learners.calibration import coverage, pit
from hipref.learners.sysid import CUBE_MASS, PretrainConfig, SIModel, pretrain


def test_the_constant_guess_errs_by_the_mean_distance_from_the_middle_and_the_median():
    truths = [9.0, 10.0, 19.0]
    osi = pd.DataFrame(
        {
            "domain": "pushing",
            "method": "osi",
            "metric": "param_error",
            "ground_truth": truths,
            "seed": 0,
            "episode": 0,
            "value": 0.5,
        }
    )
    rows = constant_guess_rows(osi)
    middle = rows[rows.method == CONSTANT_MIDDLE].value
    best = rows[rows.method == CONSTANT_BEST].value
    assert middle.mean() == pytest.approx(np.mean(np.abs(np.array(truths) - 14.0)))  # 14 kg: middle of 8-20
    assert best.tolist() == pytest.approx([1.0, 0.0, 9.0])  # the median, 10 kg
    assert best.mean() < middle.mean()


def test_a_calibrated_posterior_has_nominal_coverage_and_an_overconfident_one_does_not():
    rng = np.random.default_rng(0)
    n = 20_000
    centres = rng.uniform(9.0, 19.0, size=n)
    widths = rng.uniform(0.5, 3.0, size=n)
    values = CUBE_MASS.values
    probabilities = np.exp(-0.5 * ((values[None, :] - centres[:, None]) / widths[:, None]) ** 2)
    probabilities /= probabilities.sum(axis=1, keepdims=True)
    # The truth drawn from each distribution read as a density: a candidate, then uniformly within its cell.
    cells = (probabilities.cumsum(axis=1) < rng.uniform(size=(n, 1))).sum(axis=1)
    truths = values[cells] + CUBE_MASS.resolution * rng.uniform(-0.5, 0.5, size=n)
    pits = pit(probabilities, CUBE_MASS, truths)
    assert coverage(pits, 0.5) == pytest.approx(0.5, abs=0.015)
    assert coverage(pits, 0.9) == pytest.approx(0.9, abs=0.01)
    shifted = pit(probabilities, CUBE_MASS, np.clip(truths + 2.0 * widths, 8.0, 20.0))
    assert coverage(shifted, 0.9) < 0.8


def test_a_regressor_given_the_parameter_column_finds_it_on_held_out_environments():
    train = collect_trajectories("pushing", 60, PretrainData(trajectory_steps=6))
    test = collect_trajectories("pushing", 6, PretrainData(trajectory_steps=6, seed=1))
    (x, y, _), (x_test, y_test, _) = (select_slices(t, 3, "anywhere", None, 1, 0) for t in (train, test))
    with_phi = regressor_estimates("gbt", (np.c_[x, y], y), np.c_[x_test, y_test], 8.0, 20.0, 0)
    # Near zero: a few per cent of the 12 kg range, against about 3 kg for the range's middle.
    assert np.abs(with_phi - y_test).mean() < 0.03 * 12.0


def test_smaller_collections_are_the_first_trajectories_of_larger_ones():
    data = PretrainData(trajectory_steps=12, seed=5)
    small, large = collect_trajectories("pushing", 2, data), collect_trajectories("pushing", 3, data)
    np.testing.assert_array_equal(small.features, large.features[:2])
    features, parameters, index, phase = cut_slices(large, 3)
    assert features.shape == (3 * 10, 3 * 21) and np.all((phase >= 0) & (phase < 1))
    np.testing.assert_array_equal(features[11, 21:42], large.features[1, 2])
    assert parameters[11] == large.parameters[index[11]] == large.parameters[1]


def test_a_held_out_collection_must_have_its_own_seed():
    with pytest.raises(ValueError, match="test_seed"):
        TauConfig(seed=3, test_seed=3)


def test_nll_pretraining_reads_an_informative_feature_and_covers_the_truth():
    rng = np.random.default_rng(0)
    phi = rng.uniform(8.0, 20.0, size=2000)
    features = np.c_[phi + rng.normal(0.0, 1.0, size=phi.size), rng.normal(size=(phi.size, 3))]
    model = SIModel(4, CUBE_MASS, hidden_sizes=(32,), seed=0)
    pretrain(model, features[:1500], phi[:1500], PretrainConfig(1e-2, n_steps=600, loss="nll"), 0)
    held_out = torch.as_tensor(features[1500:], dtype=torch.float32)
    with torch.no_grad():
        probabilities = model.distribution(held_out).double().numpy()
    error = np.abs(probabilities @ CUBE_MASS.values - phi[1500:]).mean()
    assert error < 0.5 * np.abs(14.0 - phi[1500:]).mean()
    # The feature's noise is 1 kg: a posterior of about that width holds the truth about 90 % of the time.
    probabilities /= probabilities.sum(axis=1, keepdims=True)
    assert 0.8 <= coverage(pit(probabilities, CUBE_MASS, phi[1500:]), 0.9) <= 0.97

"""The system-identification model: candidate set, normalisation, expected-value estimate, Algorithm 4."""

import numpy as np
import pytest
import torch

from hipref.learners.sysid import (
    CUBE_MASS,
    DESK_HEIGHT,
    CandidateSet,
    Normaliser,
    PretrainConfig,
    SIModel,
    pretrain,
    target_distribution,
)


def _synthetic_dataset(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Features whose projection on a hidden direction fixes the height, plus 1 cm of noise."""
    features = rng.normal(loc=3.0, scale=[1.0, 5.0, 0.1, 2.0, 1.0, 1.0], size=(n, 6))
    direction = np.array([1.0, 0.2, 5.0, -0.5, 0.0, 0.0])
    latent = 1.0 / (1.0 + np.exp(-(features - 3.0) @ direction / 2.0))
    heights = DESK_HEIGHT.denormalise(latent) + rng.normal(0.0, 0.01, size=n)
    return features, np.clip(heights, DESK_HEIGHT.low, DESK_HEIGHT.high)


def test_paper_candidate_sets() -> None:
    assert DESK_HEIGHT.size == 41 and CUBE_MASS.size == 49
    assert DESK_HEIGHT.values[0] == 0.5 and DESK_HEIGHT.values[-1] == 0.9
    assert np.allclose(np.diff(CUBE_MASS.values), 0.25)
    assert CUBE_MASS.normalise(14.0) == pytest.approx(0.5)
    assert CUBE_MASS.denormalise(CUBE_MASS.normalise(9.75)) == pytest.approx(9.75)
    assert DESK_HEIGHT.index_of(0.73) == 23
    with pytest.raises(ValueError, match="candidate"):
        DESK_HEIGHT.index_of(0.735)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"low": 1.0, "high": 0.5, "resolution": 0.1}, "high must be greater than low"),
        ({"low": 0.5, "high": 0.9, "resolution": 0.0}, "resolution"),
        ({"low": 0.5, "high": 0.9, "resolution": 0.03}, "whole steps"),
    ],
)
def test_invalid_candidate_sets_are_refused(kwargs: dict[str, float], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        CandidateSet(**kwargs)


def test_estimate_is_the_expectation_over_candidates_and_stays_in_range() -> None:
    model = SIModel(input_dim=6, candidates=DESK_HEIGHT, hidden_sizes=(16,), seed=1)
    x = torch.randn(10, 6) * 50
    probs = model.distribution(x)
    torch.testing.assert_close(
        model.estimate(x), probs @ torch.as_tensor(DESK_HEIGHT.values, dtype=torch.float32)
    )
    assert torch.all((model.estimate(x) >= 0.5) & (model.estimate(x) <= 0.9))
    torch.testing.assert_close(model.estimate(x, normalised=True), (model.estimate(x) - 0.5) / 0.4)


def test_same_seed_gives_the_same_model_and_training() -> None:
    features, heights = _synthetic_dataset(200, np.random.default_rng(0))
    config = PretrainConfig(batch_size=32, n_steps=20)
    runs = []
    for _ in range(2):
        model = SIModel(6, DESK_HEIGHT, hidden_sizes=(16, 8), seed=3)
        runs.append((pretrain(model, features, heights, config, seed=4), model.predict(features)))
    np.testing.assert_array_equal(runs[0][0], runs[1][0])
    np.testing.assert_array_equal(runs[0][1], runs[1][1])


def test_pretraining_beats_predicting_the_range_midpoint_on_held_out_data() -> None:
    features, heights = _synthetic_dataset(1200, np.random.default_rng(5))
    model = SIModel(6, DESK_HEIGHT, hidden_sizes=(32, 16), seed=0)
    losses = pretrain(
        model, features[:1000], heights[:1000], PretrainConfig(batch_size=64, n_steps=300), seed=0
    )
    held_out_error = np.mean((model.predict(features[1000:]) - heights[1000:]) ** 2)
    midpoint_error = np.mean((0.7 - heights[1000:]) ** 2)
    assert held_out_error < 0.25 * midpoint_error
    assert losses[-20:].mean() < losses[:20].mean()


def test_normaliser_is_fitted_and_travels_in_the_state_dict() -> None:
    features, heights = _synthetic_dataset(100, np.random.default_rng(6))
    model = SIModel(6, DESK_HEIGHT, hidden_sizes=(8,), seed=0)
    pretrain(model, features, heights, PretrainConfig(batch_size=16, n_steps=1), seed=0)
    normaliser = Normaliser.fit(features)
    np.testing.assert_allclose(model.feature_mean.numpy(), normaliser.mean, rtol=1e-6)
    copy = SIModel(6, DESK_HEIGHT, hidden_sizes=(8,), seed=99)
    copy.load_state_dict(model.state_dict())
    np.testing.assert_array_equal(copy.predict(features), model.predict(features))
    assert np.allclose(normaliser(features).mean(axis=0), 0.0, atol=1e-9)


def test_invalid_pretraining_input_is_refused() -> None:
    model = SIModel(6, DESK_HEIGHT, hidden_sizes=(8,), seed=0)
    with pytest.raises(ValueError, match="features must be"):
        pretrain(model, np.zeros((5, 4)), np.zeros(5), PretrainConfig(), seed=0)
    with pytest.raises(ValueError, match=r"batch_size .*0"):
        PretrainConfig(batch_size=0)


@pytest.mark.parametrize("candidates", [DESK_HEIGHT, CUBE_MASS])
def test_an_estimate_collapsed_on_the_end_of_the_range_stays_inside_it(candidates) -> None:
    # Summed in float32, such a distribution's expectation rounded to 0.90000004 m in a full-profile run.
    model = SIModel(input_dim=4, candidates=candidates, hidden_sizes=(8,), seed=0)
    rng = np.random.default_rng(0)
    last = model.net[-1]
    for _ in range(300):
        logits = torch.full((candidates.size,), -30.0)
        logits[-1], logits[-2], logits[0] = 0.0, float(rng.uniform(-20, 0)), float(rng.uniform(-40, -10))
        with torch.no_grad():
            last.weight.zero_()
            last.bias.copy_(logits)
        assert candidates.low <= float(model.predict(np.zeros(4))) <= candidates.high


@pytest.mark.parametrize("height", [0.5, 0.503, 0.62, 0.7049, 0.9])
def test_the_brier_target_puts_its_mass_on_the_neighbouring_candidates_with_the_truth_as_mean(height) -> None:
    target = target_distribution(DESK_HEIGHT, np.array([height]))[0]
    assert target.sum() == pytest.approx(1.0)
    assert target @ DESK_HEIGHT.values == pytest.approx(height)
    assert np.count_nonzero(target) <= 2
    assert np.all(np.abs(DESK_HEIGHT.values[target > 0] - height) < DESK_HEIGHT.resolution + 1e-9)


def test_brier_pretraining_puts_the_mass_near_the_truth_where_expectation_pretraining_need_not() -> None:
    features, heights = _synthetic_dataset(1200, np.random.default_rng(5))
    near = {}
    for loss in ("brier", "expectation"):
        model = SIModel(6, DESK_HEIGHT, hidden_sizes=(32, 16), seed=0)
        config = PretrainConfig(batch_size=64, n_steps=600, loss=loss)
        pretrain(model, features[:1000], heights[:1000], config, seed=0)
        with torch.no_grad():
            probs = model.distribution(torch.as_tensor(features[1000:], dtype=torch.float32)).numpy()
        close = np.abs(DESK_HEIGHT.values[None, :] - heights[1000:, None]) <= 0.03
        near[loss] = float((probs * close).sum(axis=1).mean())
    # Within 3 cm of the truth: 7 of 41 candidates, 17 % of a uniform distribution's mass.
    assert near["brier"] > 0.5
    assert near["brier"] > near["expectation"] + 0.1


def test_an_unknown_pretraining_loss_is_refused() -> None:
    with pytest.raises(ValueError, match=r"loss must be one of .*'brier'.*got 'mse'"):
        PretrainConfig(loss="mse")

"""CO-PESI (Algorithm 1): small-loss selection, cross-updates, refreshes and the SI update on b_0."""

import numpy as np
import pytest
import torch

from hipref.learners.coteaching import CoPESIConfig, CoPESILearner, CoTeachingPair, coteach_select
from hipref.learners.sysid import DESK_HEIGHT, SIModel
from hipref.teachers.preference import ScriptedPreferenceTeacher
from tests._clips import shown


@pytest.fixture(autouse=True)
def _single_thread(single_thread: None) -> None:
    """Every test here runs torch on one thread (tests/conftest.py)."""


def _noisy_pairs(n: int, noise: float, seed: int) -> tuple[torch.Tensor, torch.Tensor, np.ndarray]:
    """Random candidate pairs labelled by nearness to a fixed height; a known subset of labels flipped."""
    rng = np.random.default_rng(seed)
    first = rng.integers(DESK_HEIGHT.size, size=n)
    second = rng.integers(DESK_HEIGHT.size - 1, size=n)
    second += second >= first
    a, b = DESK_HEIGHT.values[first], DESK_HEIGHT.values[second]
    true_height = 0.7537
    y = np.where(np.abs(a - true_height) < np.abs(b - true_height), 1, -1)
    flipped = rng.random(n) < noise
    y[flipped] *= -1
    pairs = torch.as_tensor(
        np.stack([DESK_HEIGHT.normalise(a), DESK_HEIGHT.normalise(b)], axis=1), dtype=torch.float32
    )
    return pairs, torch.as_tensor(y < 0).long(), flipped


def test_selection_keeps_exactly_batch_minus_forget_number_smallest_losses() -> None:
    loss0 = torch.tensor([0.9, 0.1, 0.5, 0.3, 2.0, 0.2])
    loss1 = torch.tensor([0.1, 0.9, 0.2, 3.0, 0.4, 0.3])
    for forget_number in range(6):
        b0, b1 = coteach_select(loss0, loss1, forget_number)
        assert len(b0) == len(b1) == 6 - forget_number
    b0, b1 = coteach_select(loss0, loss1, 2)
    assert set(b0) == {1, 5, 3, 2} and set(b1) == {0, 2, 5, 4}
    for bad in (-1, 6):
        with pytest.raises(ValueError, match="forget_number"):
            coteach_select(loss0, loss1, bad)


def test_each_classifier_is_updated_with_its_peers_selection(monkeypatch: pytest.MonkeyPatch) -> None:
    pairs, targets, _ = _noisy_pairs(32, 0.2, seed=0)
    pair = CoTeachingPair((16, 16), 1e-2, seed=0)
    for _ in range(20):  # make the two classifiers differ from their initialisation
        pair.step(pairs, targets, 0)
    trained_on: list[tuple[int, torch.Tensor]] = []
    original = CoTeachingPair.train_on

    def spy(self: CoTeachingPair, which: int, x: torch.Tensor, y: torch.Tensor) -> None:
        trained_on.append((which, x.clone()))
        original(self, which, x, y)

    monkeypatch.setattr(CoTeachingPair, "train_on", spy)
    loss0, loss1 = pair.losses(pairs, targets)
    b0, b1 = pair.step(pairs, targets, forget_number=8)
    np.testing.assert_array_equal(b0, coteach_select(loss0, loss1, 8)[0])
    assert set(b0) != set(b1)  # otherwise the check below could not tell the two selections apart
    assert [which for which, _ in trained_on] == [0, 1]
    torch.testing.assert_close(trained_on[0][1], pairs[b1])  # M_0 learns from M_1's selection
    torch.testing.assert_close(trained_on[1][1], pairs[b0])  # M_1 learns from M_0's selection


def test_selection_precision_beats_the_clean_fraction_of_the_batch() -> None:
    pairs, targets, flipped = _noisy_pairs(512, 0.2, seed=1)
    pair = CoTeachingPair((64, 64), 1e-2, seed=1)
    rng = np.random.default_rng(2)
    for step in range(200):
        batch = rng.choice(512, size=32, replace=False)
        pair.step(pairs[batch], targets[batch], forget_number=round(min(1.0, step / 10) * 0.2 * 32))
    kept_clean, batch_clean = [], []
    for _ in range(50):
        batch = rng.choice(512, size=32, replace=False)
        b0, b1 = coteach_select(*pair.losses(pairs[batch], targets[batch]), forget_number=6)
        kept_clean.append(np.mean(~flipped[batch[np.concatenate([b0, b1])]]))
        batch_clean.append(np.mean(~flipped[batch]))
    assert np.mean(kept_clean) > np.mean(batch_clean) + 0.05


def _learner(noise_level: float = 0.2, seed: int = 0, **config: object) -> CoPESILearner:
    model = SIModel(input_dim=4, candidates=DESK_HEIGHT, hidden_sizes=(32, 16), seed=seed)
    return CoPESILearner(model, noise_level, CoPESIConfig(**{"history": 1, **config}), seed=seed)


def test_forget_number_ramps_to_the_noise_level_and_keeps_at_least_one_sample() -> None:
    learner = _learner(noise_level=0.2, ramp_steps=10)
    assert learner.remember_rate == pytest.approx(0.8)
    assert [learner.forget_number(step, 16) for step in (0, 5, 10, 50)] == [0, 2, 3, 3]
    assert learner.forget_number(50, 32) == 6
    assert _learner(noise_level=1.0).forget_number(50, 16) == 15
    assert _learner(noise_level=0.2, ramp_steps=0).forget_number(0, 16) == 3


def test_nothing_is_learnt_until_the_buffer_exceeds_the_start_size() -> None:
    learner = _learner(start_size=8, batch_size=8)
    teacher = ScriptedPreferenceTeacher(0.8, 0.0, np.random.default_rng(0))
    features = np.ones(4)
    before = [p.clone() for p in learner.model.parameters()]
    for _ in range(8):
        query = learner.ask(shown(features))
        learner.tell(query, teacher.answer(query))
    assert learner.coteaching_steps == 0
    assert all(torch.equal(a, b) for a, b in zip(before, learner.model.parameters(), strict=True))
    query = learner.ask(shown(features))
    learner.tell(query, teacher.answer(query))
    assert learner.coteaching_steps == 1
    assert not all(torch.equal(a, b) for a, b in zip(before, learner.model.parameters(), strict=True))


def test_si_is_updated_on_b0_and_classifiers_refresh_on_schedule(monkeypatch: pytest.MonkeyPatch) -> None:
    learner = _learner(noise_level=0.25, start_size=4, batch_size=8, refresh_frequency=3, ramp_steps=0)
    si_batches: list[np.ndarray] = []
    refreshes: list[int] = []
    update_si, reinitialise = learner._update_si, learner.pair.reinitialise
    monkeypatch.setattr(learner, "_update_si", lambda batch: si_batches.append(batch) or update_si(batch))
    monkeypatch.setattr(
        learner.pair,
        "reinitialise",
        lambda seed: refreshes.append(learner.coteaching_steps) or reinitialise(seed),
    )
    teacher = ScriptedPreferenceTeacher(0.6, 0.25, np.random.default_rng(1))
    for _ in range(14):
        query = learner.ask(shown(np.zeros(4)))
        learner.tell(query, teacher.answer(query))
        if si_batches:
            np.testing.assert_array_equal(si_batches[-1], learner.last_selection)
    assert learner.coteaching_steps == 10
    # |D| = 5, 6, 7: batches of 5, 6, 7 forgetting 1, 2, 2; then batches of 8 forgetting round(0.25 * 8).
    assert [len(batch) for batch in si_batches] == [4, 4, 5] + [6] * 7
    assert refreshes == [3, 6, 9]


def test_noise_free_preferences_reduce_the_estimate_error_and_runs_are_reproducible() -> None:
    estimates = []
    for _ in range(2):
        learner = _learner(noise_level=0.1, seed=3, learning_rate=0.1)
        teacher = ScriptedPreferenceTeacher(0.843, 0.0, np.random.default_rng(4))
        features = np.array([0.3, -1.0, 2.0, 0.5])
        initial_error = abs(learner.estimate(features) - 0.843)
        for _ in range(200):
            query = learner.ask(shown(features))
            learner.tell(query, teacher.answer(query))
        estimates.append(learner.estimate(features))
    assert estimates[0] == estimates[1]
    assert abs(estimates[0] - 0.843) < 0.5 * initial_error


def test_invalid_settings_are_refused() -> None:
    with pytest.raises(ValueError, match="n_candidates must be 2"):
        CoPESIConfig(n_candidates=3)
    with pytest.raises(ValueError, match=r"refresh_frequency .*0"):
        CoPESIConfig(refresh_frequency=0)
    with pytest.raises(ValueError, match=r"noise_level .*1.5"):
        _learner(noise_level=1.5)

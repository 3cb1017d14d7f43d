"""The robust learners (their losses in `hipref.learners.losses`, their filters in `hipref.learners.filters`):
each one's defining property."""

import math
from collections.abc import Callable

import numpy as np
import pytest
import torch

from hipref.learners.coteaching import CoTeaching
from hipref.learners.filters import (
    FilterSetting,
    SIUpdateRecord,
    SmallLoss,
    TrustFlip,
    TrustFlipFilter,
    UpdateLog,
)
from hipref.learners.losses import conservative_pesi_loss, pesi_loss, preference_nll, unbiased_pesi_loss
from hipref.learners.noise_rate import FlipRate, Likelihood
from hipref.learners.pesi import PESI_FILTER, TRUSTING, PESIConfig, PESILearner
from hipref.learners.sysid import DESK_HEIGHT, SIModel
from hipref.teachers.preference import PreferenceQuery, ScriptedPreferenceTeacher
from tests._clips import shown

FEATURES = np.array([0.3, -1.0, 2.0, 0.5])


def _pairs(seed: int, batch: int = 8) -> tuple[torch.Tensor, torch.Tensor]:
    generator = torch.Generator().manual_seed(seed)
    logits = torch.randn(batch, 2, generator=generator, requires_grad=True)
    y = torch.where(torch.rand(batch, generator=generator) < 0.5, 1.0, -1.0)
    return logits, y


def _grad(loss_of: object, logits: torch.Tensor) -> torch.Tensor:
    logits.grad = None
    loss_of(torch.log_softmax(logits, dim=1)).backward()  # type: ignore[operator]
    return logits.grad.clone()


@pytest.mark.parametrize("rate", [0.0, 0.1, 0.3, 0.45])
@pytest.mark.parametrize("seed", range(3))
def test_the_unbiased_losss_expectation_under_flips_equals_the_clean_loss(rate: float, seed: int) -> None:
    logits, y = _pairs(seed)
    pair = torch.log_softmax(logits, dim=1)
    expected = (1 - rate) * unbiased_pesi_loss(pair, y, 0.25, rate) + rate * unbiased_pesi_loss(
        pair, -y, 0.25, rate
    )
    torch.testing.assert_close(expected, pesi_loss(pair, y, 0.25))
    # In gradient too, and the unbiased gradient is Eq. 2's scaled by 1 / (1 - 2 e).
    unbiased = _grad(lambda p: unbiased_pesi_loss(p, y, 0.25, rate), logits)
    torch.testing.assert_close(unbiased, _grad(lambda p: pesi_loss(p, y, 0.25), logits) / (1 - 2 * rate))


@pytest.mark.parametrize("smoothing", [0.0, 0.1, 0.3])
def test_label_smoothing_trusts_the_label_with_1_minus_eps_and_scales_eq2s_step_by_1_minus_2eps(
    smoothing: float,
) -> None:
    logits, y = _pairs(4)
    pair = torch.log_softmax(logits, dim=1)
    mixed = (1 - smoothing) * pesi_loss(pair, y, 0.25) + smoothing * pesi_loss(pair, -y, 0.25)
    torch.testing.assert_close(conservative_pesi_loss(pair, y, 0.25, smoothing), mixed)
    smoothed = _grad(lambda p: conservative_pesi_loss(p, y, 0.25, smoothing), logits)
    torch.testing.assert_close(smoothed, (1 - 2 * smoothing) * _grad(lambda p: pesi_loss(p, y, 0.25), logits))


def test_the_preference_loss_is_minus_log_pr_of_the_preferred_candidate() -> None:
    pair = torch.log(torch.tensor([[0.9, 0.1], [0.9, 0.1]]))
    torch.testing.assert_close(
        preference_nll(pair, torch.tensor([1.0, -1.0])), torch.tensor([-math.log(0.9), -math.log(0.1)])
    )


ESTIMATED = Likelihood(0.4)
"""The flip rate of the unbiased loss and the small-loss filter (as `hipref.experiments.si_methods`)."""


def _learner(
    filter: FilterSetting = PESI_FILTER, flip_rate: FlipRate = TRUSTING, seed: int = 0, **config: object
) -> PESILearner:
    model = SIModel(input_dim=4, candidates=DESK_HEIGHT, hidden_sizes=(32, 16), seed=seed)
    pesi = PESIConfig(**{"history": 1, "start_size": 8, "batch_size": 16, **config})  # type: ignore[arg-type]
    return PESILearner(model, pesi, seed, filter, flip_rate)


def _log(learner: PESILearner) -> UpdateLog:
    assert isinstance(learner.filter, UpdateLog)
    return learner.filter


def _trust_flip(learner: PESILearner) -> TrustFlipFilter:
    assert isinstance(learner.filter, TrustFlipFilter)
    return learner.filter


def _teach(learner: object, truth: float, noise: float, n: int, seed: int = 2) -> ScriptedPreferenceTeacher:
    teacher = ScriptedPreferenceTeacher(truth, noise, np.random.default_rng(seed))
    for _ in range(n):
        query = learner.ask(shown(FEATURES))  # type: ignore[attr-defined]
        learner.tell(query, teacher.answer(query))  # type: ignore[attr-defined]
    return teacher


def _teach_recording(learner: PESILearner, truth: float, noise: float, n: int) -> np.ndarray:
    """`_teach`, returning what was asked and answered: one row (first, second, label) per preference."""
    teacher = ScriptedPreferenceTeacher(truth, noise, np.random.default_rng(2))
    told = []
    for _ in range(n):
        query = learner.ask(shown(FEATURES))
        label = teacher.answer(query)
        learner.tell(query, label)
        told.append((*query.candidates[:2], label))
    return np.array(told, dtype=float)


def _brute_force_rate(told: np.ndarray, low: float, high: float, cap: float) -> float:
    """The maximum marginal likelihood flip rate by brute force: the likelihood of every rate on the 1001
    grid averaged over 8001 evenly spaced truths in [low, high] (no intervals between midpoints), capped."""
    truths = np.linspace(low, high, 8001)[:, None]
    first, second, label = told.T
    clean = np.where(np.abs(first - truths) < np.abs(second - truths), 1.0, -1.0)
    wrong = (clean != label).sum(axis=1)[:, None]
    rates = np.linspace(0.0, 0.5, 1001)[None, :]
    with np.errstate(divide="ignore"):
        log_terms = (len(label) - wrong) * np.log1p(-rates) + np.where(wrong > 0, wrong * np.log(rates), 0.0)
    peak = log_terms.max(axis=0)  # -inf at e = 0 unless one truth explains every answer
    with np.errstate(invalid="ignore"):
        log_likelihood = np.where(
            np.isfinite(peak), peak + np.log(np.exp(log_terms - peak).sum(axis=0)), -np.inf
        )
    return min(cap, float(rates[0, np.argmax(log_likelihood)]))


def test_a_perfect_filters_precision_and_recall_are_1_on_a_constructed_batch() -> None:
    learner = _learner(SmallLoss(), ESTIMATED)
    _teach(learner, 0.7, 0.0, 6)
    flipped = np.array([False, True, False, False, True, False])
    _log(learner).si_updates = [SIUpdateRecord(np.arange(6), np.flatnonzero(flipped))]
    assert learner.filter_precision_recall(flipped) == (1.0, 1.0)
    _log(learner).si_updates = [SIUpdateRecord(np.arange(6), np.array([0, 1]))]  # one right, one missed
    assert learner.filter_precision_recall(flipped) == (0.5, 0.5)


def test_the_small_loss_filter_forgets_the_estimated_share_with_the_largest_loss_under_si() -> None:
    learner = _learner(SmallLoss(), ESTIMATED, learning_rate=0.1)
    told = _teach_recording(learner, 0.8, 0.2, 60)
    record, rate = _log(learner).si_updates[-1], learner.noise_history[-1]
    assert abs(len(record.forgotten) - rate * len(record.batch)) <= 0.5  # the nearest count
    assert rate == pytest.approx(_brute_force_rate(told, 0.5, 0.9, 0.4), abs=1.5e-3)
    assert 0.1 < rate < 0.3  # 20 % of the answers were flipped
    with torch.no_grad():
        queried, labels = learner.queried(record.batch)
        losses = preference_nll(queried, labels[:, 0])
    forgotten = np.isin(record.batch, record.forgotten)
    assert losses[torch.as_tensor(forgotten)].min() >= losses[torch.as_tensor(~forgotten)].max()


def test_small_loss_filtering_finds_flips_better_than_chance_once_si_has_learnt() -> None:
    learner = _learner(SmallLoss(), ESTIMATED, learning_rate=0.1)
    teacher = _teach(learner, 0.8, 0.2, 120, seed=5)
    precision, recall = learner.filter_precision_recall(teacher.wrong_labels)
    assert precision > 0.3  # chance is the flip rate, 0.2
    assert recall > 0.2


def test_rime_trusts_small_losses_flips_very_large_ones_and_leaves_out_the_rest() -> None:
    trust_flip = _trust_flip(_learner(TrustFlip(trust_spread_start=0.0, trust_spread_end=0.0)))
    assert trust_flip.trust_threshold(torch.tensor([0.1, 5.0])) == pytest.approx(math.log(2))
    trust_flip = _trust_flip(
        _learner(TrustFlip(trust_spread_start=2.0, trust_spread_end=1.0, trust_spread_decay=0.5))
    )
    # By hand: losses (0, 1) have the sample standard deviation sqrt(1/2); beta_t = max(1, 2 - t / 2).
    losses = torch.tensor([0.0, 1.0])
    assert trust_flip.trust_threshold(losses) == pytest.approx(math.log(2) + 2.0 * math.sqrt(0.5))
    trust_flip.filtered_updates = 1
    assert trust_flip.trust_threshold(losses) == pytest.approx(math.log(2) + 1.5 * math.sqrt(0.5))
    trust_flip.filtered_updates = 10  # decayed to its floor
    assert trust_flip.trust_threshold(losses) == pytest.approx(math.log(2) + 1.0 * math.sqrt(0.5))
    # In a run: every left-out or flipped entry of an update is recorded as forgotten.
    learner = _learner(TrustFlip(), learning_rate=0.1)
    _teach(learner, 0.8, 0.3, 60)
    assert _trust_flip(learner).filtered_updates == 60 - 8
    record = _trust_flip(learner).si_updates[-1]
    with torch.no_grad():
        queried, labels = learner.queried(record.batch)
        losses = preference_nll(queried, labels[:, 0]).numpy()
    assert np.all(losses[np.isin(record.batch, record.forgotten)] >= math.log(2))


def test_the_unbiased_learner_estimates_the_rate_by_marginal_likelihood_before_each_update() -> None:
    learner = _learner(flip_rate=ESTIMATED, loss="unbiased")
    told = _teach_recording(learner, 0.6, 0.2, 30)
    assert len(learner.noise_history) == 30 - 8
    # Before each update, on the preferences told so far (the first update comes with the 9th).
    for k in (9, 20, 30):
        assert learner.noise_history[k - 9] == pytest.approx(
            _brute_force_rate(told[:k], 0.5, 0.9, 0.4), abs=1.5e-3
        )


def test_label_smoothing_learns_from_clean_preferences() -> None:
    learner = _learner(loss="smoothed", learning_rate=0.1)
    initial = abs(learner.estimate(FEATURES) - 0.843)
    _teach(learner, 0.843, 0.0, 150)
    assert abs(learner.estimate(FEATURES) - 0.843) < 0.5 * initial


def test_co_pesi_likelihood_forgets_the_marginal_likelihood_rate_of_its_buffer() -> None:
    model = SIModel(input_dim=4, candidates=DESK_HEIGHT, hidden_sizes=(16,), seed=0)
    learner = PESILearner(model, PESIConfig(history=1, start_size=8), 0, CoTeaching(rounds=2), Likelihood())
    told = _teach_recording(learner, 0.7, 0.25, 30)
    assert len(learner.noise_history) == 30 - 8
    assert learner.noise_history[-1] == pytest.approx(_brute_force_rate(told, 0.5, 0.9, 0.5), abs=1.5e-3)


@pytest.mark.parametrize(
    ("build", "message"),
    [
        (lambda: _learner(SmallLoss(), n_candidates=3), "n_candidates"),
        (lambda: _learner(loss="unbiased", n_candidates=3), "n_candidates"),
        (lambda: PESIConfig(smoothing=0.5), "smoothing"),
        (lambda: Likelihood(0.6), "cap"),
        (lambda: TrustFlip(flip_probability=0.9), "flip_probability"),
        (lambda: TrustFlip(trust_spread_end=5.0), "trust_spread_end"),
    ],
)
def test_invalid_robust_settings_are_refused(build: Callable[[], object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        build()


def test_robust_learners_store_nothing_for_a_skip() -> None:
    from hipref.teachers.models import SKIP

    learner = _learner(SmallLoss(), ESTIMATED)
    learner.tell(PreferenceQuery(learner.ask(shown(FEATURES)).candidates, FEATURES), SKIP)
    assert len(learner) == 0 and _log(learner).si_updates == []

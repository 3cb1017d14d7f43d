"""CO-PESI (Algorithm 1): small-loss selection, cross-updates, the refresh schedule, one SI update per
preference on b_0, and the filter's precision and recall against the recorded flips."""

import dataclasses
import math
from collections.abc import Callable

import numpy as np
import pytest
import torch

from hipref.learners.coteaching import CoTeaching, CoTeachingFilter, reset_every_step_schedule
from hipref.learners.coteaching_pair import CoTeachingPair, classifier_inputs, coteach_select
from hipref.learners.filters import SIUpdateRecord
from hipref.learners.noise_rate import Algorithm5, FlipRate, Told
from hipref.learners.pesi import PESIConfig, PESILearner
from hipref.learners.sysid import DESK_HEIGHT, SIModel
from hipref.teachers.preference import PreferenceQuery, ScriptedPreferenceTeacher
from tests._clips import shown

TRUE_HEIGHT = 0.7537


def _noisy_pairs(n: int, noise: float, seed: int) -> tuple[torch.Tensor, torch.Tensor, np.ndarray]:
    """Random candidate pairs labelled by nearness to a fixed height; a known subset of labels flipped.

    Returns the classifiers' inputs, the targets (class 0 for y = 1) and the flipped flags."""
    rng = np.random.default_rng(seed)
    first = rng.integers(DESK_HEIGHT.size, size=n)
    second = rng.integers(DESK_HEIGHT.size - 1, size=n)
    second += second >= first
    a, b = DESK_HEIGHT.values[first], DESK_HEIGHT.values[second]
    y = np.where(np.abs(a - TRUE_HEIGHT) < np.abs(b - TRUE_HEIGHT), 1, -1)
    flipped = rng.random(n) < noise
    y[flipped] *= -1
    normalised = np.stack([DESK_HEIGHT.normalise(a), DESK_HEIGHT.normalise(b)], axis=1)
    pairs = classifier_inputs(torch.as_tensor(normalised, dtype=torch.float32))
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


def test_a_trained_pair_forgets_mostly_flipped_labels() -> None:
    # One truth, so a clean label is a function of the pair; 20 % of the labels are flipped. After some
    # hundred co-teaching steps the samples M_0 forgets should be mostly the flipped ones: a filter that
    # forgets at random would give a precision of about the noise rate, 0.2.
    pairs, targets, flipped = _noisy_pairs(256, 0.2, seed=1)
    pair = CoTeachingPair((64, 64), 1e-2, seed=1)
    rng = np.random.default_rng(2)
    for step in range(800):
        batch = rng.choice(256, size=16, replace=False)
        pair.step(pairs[batch], targets[batch], forget_number=round(min(1.0, step / 10) * 0.2 * 16))
    forgotten_flipped = []
    for _ in range(100):
        batch = rng.choice(256, size=16, replace=False)
        b0, _ = coteach_select(*pair.losses(pairs[batch], targets[batch]), forget_number=3)
        forgotten_flipped.extend(flipped[np.setdiff1d(batch, batch[b0])])
    assert np.mean(forgotten_flipped) > 0.6


def test_the_default_schedules_filter_forgets_flipped_labels_well_above_chance() -> None:
    # Through the learner, on 99 preferences at 20 % noise with uniformly drawn pairs: a filter that
    # forgets at random has a precision of about 0.2; one step per preference with the refresh every 16
    # (the reset-every-step schedule) scored close to that when the queries are concentrated.
    precisions = []
    for seed in range(2):
        rng = np.random.default_rng(seed)
        model = SIModel(input_dim=4, candidates=DESK_HEIGHT, hidden_sizes=(16,), seed=0)
        learner = _co_pesi(model, Told(0.2), seed)
        flipped = []
        for _ in range(99):
            a, b = (float(c) for c in rng.choice(DESK_HEIGHT.values, size=2, replace=False))
            y = 1 if abs(a - TRUE_HEIGHT) < abs(b - TRUE_HEIGHT) else -1
            flipped.append(bool(rng.random() < 0.2))
            learner.tell(PreferenceQuery((a, b), features=rng.normal(size=4)), -y if flipped[-1] else y)
        precisions.append(learner.filter_precision_recall(flipped)[0])
    assert np.mean(precisions) > 0.35


COTEACHING_FIELDS = {field.name for field in dataclasses.fields(CoTeaching)}


def _co_pesi(
    model: SIModel, flip_rate: FlipRate, seed: int, schedule: type | Callable = CoTeaching, **config: object
) -> PESILearner:
    """CO-PESI: the preference learner with co-teaching, `config` split between PESI and the schedule."""
    coteaching = {k: v for k, v in config.items() if k in COTEACHING_FIELDS}
    pesi = {k: v for k, v in config.items() if k not in COTEACHING_FIELDS}
    return PESILearner(model, PESIConfig(**{"history": 1, **pesi}), seed, schedule(**coteaching), flip_rate)


def _learner(noise_level: float = 0.2, seed: int = 0, **config: object) -> PESILearner:
    model = SIModel(input_dim=4, candidates=DESK_HEIGHT, hidden_sizes=(32, 16), seed=seed)
    return _co_pesi(model, Told(noise_level), seed, **config)


def _filter(learner: PESILearner) -> CoTeachingFilter:
    assert isinstance(learner.filter, CoTeachingFilter)
    return learner.filter


def _teach(learner: PESILearner, n: int, noise: float, seed: int = 1) -> None:
    teacher = ScriptedPreferenceTeacher(TRUE_HEIGHT, noise, np.random.default_rng(seed))
    for _ in range(n):
        query = learner.ask(shown(np.zeros(4)))
        learner.tell(query, teacher.answer(query))


def test_forget_number_ramps_to_the_noise_level_and_keeps_at_least_one_sample() -> None:
    coteaching = _filter(_learner(ramp_steps=10))
    assert [coteaching.forget_number(step, 16, 0.2) for step in (0, 5, 10, 50)] == [0, 2, 3, 3]
    assert coteaching.forget_rate(50, 0.2) == pytest.approx(0.2)
    assert coteaching.forget_number(50, 32, 0.2) == 6
    assert coteaching.forget_number(50, 16, 1.0) == 15
    assert _filter(_learner(ramp_steps=0)).forget_number(0, 16, 0.2) == 3


def test_before_the_start_size_si_learns_unfiltered_and_the_classifiers_wait() -> None:
    learner = _learner(start_size=8, batch_size=8)
    coteaching = _filter(learner)
    before = [p.clone() for p in coteaching.pair.models[0].parameters()]
    _teach(learner, 8, noise=0.0)
    assert coteaching.coteaching_steps == coteaching.classifier_steps == 0
    assert all(torch.equal(a, b) for a, b in zip(before, coteaching.pair.models[0].parameters(), strict=True))
    # One SI update per preference, each on PESI's batch min(batch_size, |D|) with nothing forgotten.
    assert [len(r.batch) for r in coteaching.si_updates] == list(range(1, 9))
    assert all(len(r.forgotten) == 0 for r in coteaching.si_updates)
    _teach(learner, 1, noise=0.0)
    assert coteaching.coteaching_steps == 1 and coteaching.classifier_steps == coteaching.setting.rounds


def test_the_literal_reading_learns_nothing_before_the_start_size() -> None:
    learner = _learner(start_size=8, batch_size=8, update_before_start=False)
    before = [p.clone() for p in learner.model.parameters()]
    _teach(learner, 8, noise=0.0)
    assert _filter(learner).si_updates == []
    assert all(torch.equal(a, b) for a, b in zip(before, learner.model.parameters(), strict=True))
    _teach(learner, 1, noise=0.0)
    assert len(_filter(learner).si_updates) == 1
    assert not all(torch.equal(a, b) for a, b in zip(before, learner.model.parameters(), strict=True))


def test_the_classifiers_refresh_when_the_buffer_reaches_a_multiple_of_f_refresh(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    learner = _learner(start_size=4, batch_size=8, refresh_frequency=3, rounds=2)
    coteaching = _filter(learner)
    sizes_at_refresh: list[int] = []
    reinitialise = coteaching.pair.reinitialise

    def spy(seed: int) -> None:
        sizes_at_refresh.append(len(learner))
        reinitialise(seed)

    monkeypatch.setattr(coteaching.pair, "reinitialise", spy)
    _teach(learner, 14, noise=0.25)
    # Co-teaching runs from |D| = 5; the classifiers are fresh then, and are re-initialised before the
    # co-teaching of |D| = 6, 9 and 12, not at every 3 classifier steps (there are 2 per preference).
    assert sizes_at_refresh == coteaching.refreshed_at == [6, 9, 12]
    assert coteaching.coteaching_steps == 10 and coteaching.classifier_steps == 20


def test_the_reset_every_step_schedule_refreshes_every_f_refresh_classifier_steps(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    model = SIModel(input_dim=4, candidates=DESK_HEIGHT, hidden_sizes=(16,), seed=0)
    learner = _co_pesi(
        model, Told(0.25), 0, reset_every_step_schedule, start_size=4, batch_size=8, refresh_frequency=3
    )
    coteaching = _filter(learner)
    refreshed_after_steps: list[int] = []
    reinitialise = coteaching.pair.reinitialise
    monkeypatch.setattr(
        coteaching.pair,
        "reinitialise",
        lambda seed: refreshed_after_steps.append(coteaching.classifier_steps) or reinitialise(seed),
    )
    _teach(learner, 14, noise=0.25)
    assert coteaching.setting.rounds == 1 and coteaching.classifier_steps == 10
    assert refreshed_after_steps == [3, 6, 9]
    assert len(coteaching.si_updates) == 10  # no SI update while |D| <= s


def test_si_is_updated_once_per_preference_on_the_last_rounds_b0(monkeypatch: pytest.MonkeyPatch) -> None:
    learner = _learner(noise_level=0.25, start_size=4, batch_size=8, rounds=3, ramp_steps=0)
    sampled: list[np.ndarray] = []
    selected: list[np.ndarray] = []
    si_batches: list[np.ndarray] = []
    coteaching = _filter(learner)
    sample_batch, step, update_si = learner.sample_batch, coteaching.pair.step, learner.update_si

    def spy_sample() -> np.ndarray:
        sampled.append(sample_batch())
        return sampled[-1]

    def spy_step(
        pairs: torch.Tensor, targets: torch.Tensor, forget_number: int
    ) -> tuple[np.ndarray, np.ndarray]:
        b0, b1 = step(pairs, targets, forget_number)
        selected.append(sampled[-1][b0])
        return b0, b1

    monkeypatch.setattr(learner, "sample_batch", spy_sample)
    monkeypatch.setattr(coteaching.pair, "step", spy_step)
    monkeypatch.setattr(
        learner, "update_si", lambda batch, rate: si_batches.append(batch) or update_si(batch, rate)
    )
    _teach(learner, 10, noise=0.25)
    assert len(si_batches) == 10 and len(selected) == 3 * 6
    # The 6 co-teaching preferences: SI sees the b_0 of each one's third classifier step, nothing else.
    for k, batch in enumerate(si_batches[4:]):
        np.testing.assert_array_equal(batch, selected[3 * k + 2])
        record = coteaching.si_updates[4 + k]
        assert set(record.forgotten) == set(record.batch) - set(batch)
        assert len(record.forgotten) == round(0.25 * len(record.batch))
    np.testing.assert_array_equal(si_batches[-1], coteaching.last_selection)


def test_co_pesi_makes_as_many_si_updates_as_pesi_for_the_same_preferences(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    model = SIModel(input_dim=4, candidates=DESK_HEIGHT, hidden_sizes=(16,), seed=0)
    pesi = PESILearner(model, PESIConfig(history=1), seed=0)
    co_pesi = _co_pesi(model, Told(0.2), 0, rounds=2)
    counts = {"pesi": 0, "co_pesi": 0}
    for name, learner in (("pesi", pesi), ("co_pesi", co_pesi)):
        update_si = learner.update_si

        def counted(
            batch: np.ndarray, rate: float, name: str = name, update_si: Callable = update_si
        ) -> float:
            counts[name] += 1
            return update_si(batch, rate)

        monkeypatch.setattr(learner, "update_si", counted)
    teacher = ScriptedPreferenceTeacher(TRUE_HEIGHT, 0.2, np.random.default_rng(0))
    rng = np.random.default_rng(1)
    for _ in range(40):
        candidates = tuple(float(c) for c in rng.choice(DESK_HEIGHT.values, size=2, replace=False))
        query = PreferenceQuery(candidates, features=rng.normal(size=4))
        label = teacher.answer(query)
        pesi.tell(query, label)
        co_pesi.tell(query, label)
    assert counts == {"pesi": 40, "co_pesi": 40}
    coteaching = _filter(co_pesi)
    assert len(coteaching.si_updates) == 40 and coteaching.coteaching_steps == 40 - co_pesi.config.start_size


def test_precision_and_recall_count_every_update_entry_occurrence() -> None:
    learner = _learner()
    _teach(learner, 5, noise=0.0)
    coteaching = _filter(learner)
    flipped = [False, True, False, True, False]
    # A perfect filter: everything forgotten was flipped, every flipped entry offered was forgotten.
    coteaching.si_updates = [
        SIUpdateRecord(np.array([0, 1, 2]), np.array([1])),
        SIUpdateRecord(np.array([1, 3, 4]), np.array([1, 3])),
    ]
    assert learner.filter_precision_recall(flipped) == (1.0, 1.0)
    # Entry 1 is offered three times and forgotten twice; entry 2 (clean) forgotten once.
    coteaching.si_updates.append(SIUpdateRecord(np.array([1, 2, 4]), np.array([2])))
    precision, recall = learner.filter_precision_recall(np.array(flipped))
    assert precision == pytest.approx(3 / 4) and recall == pytest.approx(3 / 4)
    # Nothing forgotten: precision undefined, recall 0; no flipped entry offered: recall undefined.
    coteaching.si_updates = [SIUpdateRecord(np.array([0, 1]), np.array([], dtype=np.int64))]
    precision, recall = learner.filter_precision_recall(flipped)
    assert math.isnan(precision) and recall == 0.0
    coteaching.si_updates = [SIUpdateRecord(np.array([0, 2]), np.array([2]))]
    precision, recall = learner.filter_precision_recall(flipped)
    assert precision == 0.0 and math.isnan(recall)


def test_a_learner_that_forgets_nothing_has_undefined_precision_and_zero_recall() -> None:
    learner = _learner(noise_level=0.0, start_size=4, batch_size=8, rounds=2)
    teacher = ScriptedPreferenceTeacher(TRUE_HEIGHT, 0.0, np.random.default_rng(0))
    flipped = []
    for k in range(20):
        query = learner.ask(shown(np.zeros(4)))
        label = int(teacher.answer(query))
        flipped.append(k % 3 == 0)
        learner.tell(query, -label if flipped[-1] else label)
    precision, recall = learner.filter_precision_recall(flipped)
    assert math.isnan(precision) and recall == 0.0


def test_precision_and_recall_refuse_flags_that_do_not_match_the_buffer() -> None:
    learner = _learner()
    _teach(learner, 5, noise=0.0)
    for bad in ([False] * 4, [False] * 6, np.zeros((5, 1), dtype=bool)):
        with pytest.raises(ValueError, match=r"flipped must hold one flag per preference in D \(5\)"):
            learner.filter_precision_recall(bad)
    with pytest.raises(ValueError, match="flipped must hold booleans"):
        learner.filter_precision_recall([0, 1, 2, 0, 0])


def test_the_estimated_noise_level_sets_each_preferences_forget_number() -> None:
    model = SIModel(4, DESK_HEIGHT, hidden_sizes=(8,), seed=0)
    config = dict(batch_size=8, start_size=8, refresh_frequency=8, rounds=2, ramp_steps=0)
    learner = _co_pesi(model, Algorithm5(), 1, **config)
    _teach(learner, 24, noise=0.3)
    coteaching_updates = _filter(learner).si_updates[8:]
    assert len(learner.noise_history) == len(coteaching_updates) == 24 - 8
    for level, record in zip(learner.noise_history, coteaching_updates, strict=True):
        # The count nearest e B (no ramp), unless that would leave nothing to learn from.
        forgotten, batch = len(record.forgotten), len(record.batch)
        assert abs(forgotten - level * batch) <= 0.5 or (forgotten == batch - 1 and level * batch > batch - 1)
    assert len(set(learner.noise_history)) > 1  # the level does change as D grows


def test_noise_free_preferences_reduce_the_estimate_error_and_runs_are_reproducible() -> None:
    estimates = []
    for _ in range(2):
        learner = _learner(noise_level=0.1, seed=3, learning_rate=0.1, rounds=2)
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
    model = SIModel(input_dim=4, candidates=DESK_HEIGHT, hidden_sizes=(8,), seed=0)
    with pytest.raises(ValueError, match="n_candidates must be 2"):
        PESILearner(model, PESIConfig(n_candidates=3, history=1), 0, CoTeaching())
    with pytest.raises(ValueError, match=r"refresh_frequency .*0"):
        CoTeaching(refresh_frequency=0)
    with pytest.raises(ValueError, match=r"refresh_unit .*'episodes'"):
        CoTeaching(refresh_unit="episodes")
    with pytest.raises(ValueError, match=r"rounds .*0"):
        CoTeaching(rounds=0)
    with pytest.raises(ValueError, match=r"ramp_origin .*'never'"):
        CoTeaching(ramp_origin="never")
    with pytest.raises(ValueError, match=r"update_before_start .*1"):
        CoTeaching(update_before_start=1)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"value .*1.5"):
        _learner(noise_level=1.5)

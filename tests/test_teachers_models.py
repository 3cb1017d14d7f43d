"""The teacher models (`hipref.teachers.models`): each one's defining property, the record of wrong
answers, and a learner storing nothing for an answer without a label."""

import math
import re

import numpy as np
import pytest
import torch

from hipref.learners.pesi import PESIConfig, PESILearner
from hipref.learners.sysid import DESK_HEIGHT, SIModel
from hipref.teachers import models
from hipref.teachers.models import EQUAL, SKIP, TEACHER_KINDS, TeacherModel, picture_floor
from hipref.teachers.preference import PreferenceQuery, ScriptedPreferenceTeacher
from tests._clips import shown

FEATURES = np.zeros(3)
R = 0.4  # the desk-height range, 0.5-0.9 m


def _teacher(kind: str, truth: float = 0.7, noise: float = 0.0, seed: int = 0, **params: float):
    return ScriptedPreferenceTeacher(
        truth, noise, np.random.default_rng(seed), TeacherModel(kind, **params), scale=R
    )


def _ask(teacher: ScriptedPreferenceTeacher, a: float, b: float, n: int) -> list[object]:
    return [teacher.answer(PreferenceQuery((a, b), FEATURES)) for _ in range(n)]


def _within_four_sigma(count: int, n: int, p: float) -> bool:
    return abs(count - n * p) <= 4 * math.sqrt(n * p * (1 - p)) + 1


def test_the_default_model_is_the_papers_teacher_draw_for_draw() -> None:
    rng = np.random.default_rng(3)
    pairs = [tuple(rng.choice(DESK_HEIGHT.values, 2, replace=False)) for _ in range(500)]
    default = ScriptedPreferenceTeacher(0.66, 0.3, np.random.default_rng(9))
    named = ScriptedPreferenceTeacher(0.66, 0.3, np.random.default_rng(9), TeacherModel("mistake"), scale=R)
    for a, b in pairs:
        query = PreferenceQuery((a, b), FEATURES)
        assert default.answer(query) == named.answer(query)
    assert default.flipped == named.flipped == named.wrong_labels
    assert 100 < sum(default.flipped) < 200


def test_the_oracle_always_prefers_the_nearer_candidate_and_refuses_a_flip_rate() -> None:
    teacher = _teacher("oracle", truth=0.63)
    rng = np.random.default_rng(1)
    for _ in range(500):
        a, b = rng.choice(DESK_HEIGHT.values, 2, replace=False)
        if not math.isclose(abs(a - 0.63), abs(b - 0.63)):
            assert _ask(teacher, a, b, 1)[0] == (1 if abs(a - 0.63) < abs(b - 0.63) else -1)
    assert not any(teacher.flipped)
    with pytest.raises(ValueError, match="noise must be 0"):
        _teacher("oracle", noise=0.1)


@pytest.mark.parametrize(("a", "b"), [(0.72, 0.76), (0.6, 0.9), (0.68, 0.75)])
def test_the_stochastic_teacher_prefers_a_with_probability_sigmoid_beta_r_a_minus_r_b(
    a: float, b: float
) -> None:
    beta, truth, n = 7.0, 0.7, 4000
    teacher = _teacher("stochastic", truth=truth, beta=beta)
    r_a, r_b = -abs(a - truth) / R, -abs(b - truth) / R
    p_a = 1.0 / (1.0 + math.exp(-beta * (r_a - r_b)))
    assert _within_four_sigma(_ask(teacher, a, b, n).count(1), n, p_a)
    # Wrong answers are the ones preferring the farther candidate.
    assert _within_four_sigma(sum(teacher.flipped), n, min(p_a, 1 - p_a))


def test_the_skip_teacher_answers_nothing_when_both_candidates_are_far_from_the_truth() -> None:
    teacher = _teacher("skip", truth=0.5, skip_distance=0.3)  # 0.3 of the range: 0.12 m
    assert _ask(teacher, 0.63, 0.9, 3) == [SKIP] * 3
    assert _ask(teacher, 0.61, 0.9, 3) == [1] * 3  # 0.11 m from the truth: answered, correctly
    assert teacher.labelled == [False] * 3 + [True] * 3
    assert teacher.flipped == [False] * 6
    assert teacher.wrong_labels == [False] * 3


def test_a_skipped_answer_is_never_flipped() -> None:
    teacher = _teacher("skip", truth=0.5, noise=1.0)
    assert _ask(teacher, 0.8, 0.9, 5) == [SKIP] * 5
    assert _ask(teacher, 0.51, 0.9, 1) == [-1]  # the flip applies to labels only
    assert teacher.wrong_labels == [True]


def test_the_equal_teacher_answers_equal_when_the_closeness_differs_by_less_than_the_margin() -> None:
    teacher = _teacher("equal", truth=0.7, equal_margin=0.05)  # 0.05 of the range: 0.02 m
    # 0.61 vs 0.62 m around 0.7: 0.09 and 0.08 m away, differing by 0.01 m < 0.02 m.
    assert _ask(teacher, 0.61, 0.62, 2) == [EQUAL, EQUAL]
    assert _ask(teacher, 0.69, 0.72, 2) == [EQUAL, EQUAL]  # on both sides: 0.01 and 0.02 m
    assert _ask(teacher, 0.6, 0.65, 2) == [-1, -1]  # 0.1 and 0.05 m: told apart
    assert teacher.labelled == [False] * 4 + [True] * 2


def test_the_myopic_teachers_picture_has_the_stationary_spread_and_its_errors_come_in_runs() -> None:
    gamma, sigma, n = 0.9, 1.3, 6000
    teacher = _teacher("myopic", truth=0.7, memory=gamma, glimpse_noise=sigma)
    pictures, answers = [], []
    for _ in range(n):
        answers.append(_ask(teacher, 0.66, 0.76, 1)[0])  # 0.04 m below vs 0.06 m above the truth
        pictures.append(teacher._state.memory)
    assert np.std(pictures) == pytest.approx(sigma * math.sqrt((1 - gamma) / (1 + gamma)), rel=0.15)
    wrong = np.array(teacher.flipped)
    # It prefers the candidate nearer its picture: wrong exactly when the picture is beyond 0.71 m.
    np.testing.assert_array_equal(wrong, np.array(pictures) * R > 0.01)
    # A remembered picture drifts slowly: a wrong answer is likelier right after a wrong one.
    assert 0.05 < wrong.mean() < 0.95
    assert wrong[1:][wrong[:-1]].mean() > wrong.mean() + 0.2


def test_the_distance_teacher_errs_with_probability_max_exp_minus_gap_over_width() -> None:
    truth, n = 0.7, 4000
    for a, b in [(0.69, 0.715), (0.6, 0.75), (0.5, 0.85)]:
        teacher = _teacher(
            "distance", truth=truth, seed=int(a * 100), confusion_max=0.5, confusion_width=0.21
        )
        _ask(teacher, a, b, n)
        gap = abs(abs(a - truth) - abs(b - truth)) / R
        assert _within_four_sigma(sum(teacher.flipped), n, 0.5 * math.exp(-gap / 0.21))


def test_the_distance_teacher_errs_more_as_the_candidates_close_in_on_each_other_and_the_truth() -> None:
    rates = []
    for a, b in [(0.5, 0.9), (0.6, 0.8), (0.65, 0.72), (0.69, 0.715)]:  # truth 0.7: ever harder to tell
        teacher = _teacher("distance", truth=0.7, seed=5)
        _ask(teacher, a, b, 3000)
        rates.append(np.mean(teacher.flipped))
    assert rates == sorted(rates)
    with pytest.raises(ValueError, match="pairs only"):
        _teacher("distance").answer(PreferenceQuery((0.5, 0.6, 0.7), FEATURES))


@pytest.mark.parametrize("kind", ["stochastic", "myopic", "distance"])
def test_graded_teachers_answer_about_a_fifth_of_uniform_pairs_wrongly_by_default(kind: str) -> None:
    rng, rates = np.random.default_rng(0), []
    for truth in (0.54, 0.62, 0.7, 0.78, 0.86):
        teacher = _teacher(kind, truth=truth, seed=1)
        for _ in range(1500):
            a, b = rng.choice(DESK_HEIGHT.values, 2, replace=False)
            teacher.answer(PreferenceQuery((a, b), FEATURES))
        rates.append(np.mean(teacher.wrong_labels))
    assert 0.17 < np.mean(rates) < 0.23


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"kind": "lazy"}, "kind"),
        ({"beta": -1.0}, "beta"),
        ({"memory": 1.0}, "memory"),
        ({"confusion_max": 1.5}, "confusion_max"),
        ({"skip_distance": 2.0}, "skip_distance"),
    ],
)
def test_invalid_teacher_models_are_refused(params: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        TeacherModel(**params)


def test_every_kind_the_docstring_describes_is_a_teacher_option() -> None:
    # The kinds the module's docstring gives a rule for, read from its "- 'kind'" items.
    described = re.findall(r"^- '(\w+)'", models.__doc__ or "", flags=re.MULTILINE)
    assert len(described) == 7 and set(TEACHER_KINDS) == set(described)


@pytest.mark.parametrize("kind", TEACHER_KINDS)
def test_every_kind_without_flips_prefers_the_truth_over_the_far_end_of_the_range(kind: str) -> None:
    # Every rule is the oracle changed in one respect, which hardly applies to a candidate at the truth
    # against one a whole range away: a wrong answer has probability sigmoid(-7) < 0.001 (stochastic),
    # 0.5 exp(-1 / 0.21) < 0.005 (distance), and, with glimpses of spread 0.5 R, a remembered picture of
    # spread 0.5 R sqrt(0.1 / 1.9) = 0.11 R past the midpoint, < 1e-5 (myopic); none for the others.
    for truth, far in ((0.5, 0.9), (0.9, 0.5)):
        teacher = _teacher(kind, truth=truth, seed=5, glimpse_noise=0.5)
        answers = _ask(teacher, truth, far, 200) + _ask(teacher, far, truth, 200)
        assert answers[:200].count(1) + answers[200:].count(-1) >= 396


def test_a_learner_stores_nothing_for_skip_or_equal_and_refuses_other_non_labels() -> None:
    model = SIModel(input_dim=3, candidates=DESK_HEIGHT, hidden_sizes=(8,), seed=0)
    learner = PESILearner(model, PESIConfig(history=1), seed=0)
    before = [p.detach().clone() for p in learner.model.parameters()]
    for answer in (SKIP, EQUAL):
        learner.tell(learner.ask(shown(FEATURES)), answer)
    assert len(learner) == 0 and learner.unlabelled == 2
    assert all(torch.equal(a, b) for a, b in zip(before, learner.model.parameters(), strict=True))
    for bad in (None, "skip", 0, 0.5):
        with pytest.raises(ValueError, match="preference over 2 candidates"):
            learner.tell(learner.ask(shown(FEATURES)), bad)


def test_the_myopic_floor_is_the_least_squares_mean_of_correlated_pictures() -> None:
    # Brute force: the variance of the best unbiased mean of n stationary AR(1) pictures, 1 / (1' S^-1 1).
    model = TeacherModel("myopic", memory=0.8, glimpse_noise=0.9)
    spread = 0.9 * math.sqrt(0.2 / 1.8)
    for n in (2, 3, 17):
        lags = np.abs(np.subtract.outer(np.arange(n), np.arange(n)))
        covariance = spread**2 * 0.8**lags
        brute = 1.0 / (np.ones(n) @ np.linalg.solve(covariance, np.ones(n)))
        assert picture_floor(model, n) == pytest.approx(math.sqrt(brute), rel=1e-12)
    # Correlated errors carry less than independent ones: n answers are worth about n (1 - g) / (1 + g).
    assert picture_floor(model, 400) > spread / math.sqrt(400)
    with pytest.raises(ValueError, match="myopic"):
        picture_floor(TeacherModel("mistake"), 10)

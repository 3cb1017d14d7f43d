"""The scripted feedback teacher: +1 for the expert's action, -1 otherwise, and its optional noise."""

import math

import numpy as np
import pytest

from hipref.teachers.feedback import FeedbackQuery, ScriptedFeedbackTeacher, validate_feedback


def _expert(state: int) -> int:
    return state % 4


def test_matching_the_expert_earns_plus_one_and_differing_minus_one() -> None:
    teacher = ScriptedFeedbackTeacher(expert=_expert)
    for state in range(8):
        for action in range(4):
            expected = 1 if action == state % 4 else -1
            assert teacher.answer(FeedbackQuery(state, action)) == expected


def test_vector_actions_are_compared_elementwise() -> None:
    teacher = ScriptedFeedbackTeacher(expert=lambda s: np.array([0.1, 0.2]))
    assert teacher.answer(FeedbackQuery(0, np.array([0.1, 0.2]))) == 1
    assert teacher.answer(FeedbackQuery(0, np.array([0.1, 0.3]))) == -1


@pytest.mark.parametrize("flip_probability", [0.1, 0.35])
def test_flip_rate_matches_flip_probability(flip_probability: float) -> None:
    teacher = ScriptedFeedbackTeacher(
        _expert, flip_probability=flip_probability, rng=np.random.default_rng(1)
    )
    n = 20_000
    # Half the queries match the expert (true answer +1), half do not (true answer -1).
    queries = [FeedbackQuery(s, s % 4 if s % 2 else (s + 1) % 4) for s in range(n)]
    truth = [1 if s % 2 else -1 for s in range(n)]
    flips = sum(teacher.answer(q) != t for q, t in zip(queries, truth, strict=True))
    sigma = math.sqrt(n * flip_probability * (1 - flip_probability))
    assert abs(flips - n * flip_probability) < 4 * sigma


def test_indifference_rate_matches_indifferent_probability_and_is_never_flipped() -> None:
    teacher = ScriptedFeedbackTeacher(
        _expert, flip_probability=0.5, indifferent_probability=0.2, rng=np.random.default_rng(2)
    )
    n = 20_000
    answers = np.array([teacher.answer(FeedbackQuery(0, 0)) for _ in range(n)])
    assert set(np.unique(answers)) <= {-1, 0, 1}
    assert abs((answers == 0).sum() - 0.2 * n) < 4 * math.sqrt(n * 0.2 * 0.8)


def test_noise_free_teacher_needs_no_rng_but_a_noisy_one_does() -> None:
    ScriptedFeedbackTeacher(_expert)
    with pytest.raises(ValueError, match="rng"):
        ScriptedFeedbackTeacher(_expert, flip_probability=0.1)
    with pytest.raises(ValueError, match=r"flip_probability .*\[0.0, 1.0\].*1.5"):
        ScriptedFeedbackTeacher(_expert, flip_probability=1.5, rng=np.random.default_rng())


def test_validate_feedback_accepts_exactly_minus_one_zero_one() -> None:
    assert [validate_feedback(f) for f in (-1, 0, 1, 1.0, np.int64(-1))] == [-1, 0, 1, 1, -1]
    for bad in (2, 0.5, math.nan, True, np.bool_(False), "0", None):
        with pytest.raises(ValueError, match="feedback"):
            validate_feedback(bad)

"""Tabular COACH: Eq. 1 as a feedback-weighted policy-gradient step on a softmax table."""

import math

import numpy as np
import pytest

from hipref.learners.coach import CoachConfig, TabularCoach
from hipref.teachers.feedback import ScriptedFeedbackTeacher


def _coach_with_random_table(seed: int = 0, **config: float) -> TabularCoach:
    coach = TabularCoach(n_states=5, n_actions=4, config=CoachConfig(**config))
    coach.theta[:] = np.random.default_rng(seed).normal(size=coach.theta.shape)
    return coach


@pytest.mark.parametrize("action", [0, 3])
def test_positive_feedback_moves_probability_toward_the_action(action: int) -> None:
    coach = _coach_with_random_table()
    before = coach.probabilities(2)
    coach.tell(coach.ask(2, action), 1)
    after = coach.probabilities(2)
    assert after[action] > before[action]
    others = np.arange(4) != action
    assert np.all(after[others] < before[others])


def test_negative_feedback_moves_probability_away_from_the_action() -> None:
    coach = _coach_with_random_table()
    before = coach.probabilities(1)
    coach.tell(coach.ask(1, 2), -1)
    assert coach.probabilities(1)[2] < before[2]


def test_update_is_eq1_with_feedback_as_advantage() -> None:
    coach = _coach_with_random_table(learning_rate=0.3)
    theta, pi = coach.theta.copy(), coach.probabilities(4)
    coach.tell(coach.ask(4, 1), -1)
    expected = theta.copy()
    expected[4] += 0.3 * -1 * (np.eye(4)[1] - pi)
    np.testing.assert_allclose(coach.theta, expected)


@pytest.mark.parametrize("trace_decay", [0.0, 0.9])
def test_zero_feedback_changes_nothing(trace_decay: float) -> None:
    coach = _coach_with_random_table(trace_decay=trace_decay)
    theta = coach.theta.copy()
    for state, action in [(0, 1), (3, 2), (0, 0)]:
        coach.tell(coach.ask(state, action), 0)
    np.testing.assert_array_equal(coach.theta, theta)


@pytest.mark.parametrize("feedback", [2, -2, 0.5, math.nan, math.inf, True, "1", None, [1]])
def test_feedback_outside_the_allowed_set_is_refused(feedback: object) -> None:
    coach = _coach_with_random_table()
    theta = coach.theta.copy()
    with pytest.raises(ValueError, match="feedback must be one of"):
        coach.tell(coach.ask(0, 0), feedback)
    np.testing.assert_array_equal(coach.theta, theta)


def test_eligibility_trace_credits_the_previous_step() -> None:
    coach = _coach_with_random_table(learning_rate=1.0, trace_decay=0.5)
    theta, pi0 = coach.theta.copy(), coach.probabilities(0)
    coach.tell(coach.ask(0, 1), 0)  # no feedback yet: only the trace moves
    coach.tell(coach.ask(3, 2), 1)
    np.testing.assert_allclose(coach.theta[0] - theta[0], 0.5 * (np.eye(4)[1] - pi0))
    coach.reset_trace()
    assert not coach.trace.any()


def test_grid_coordinates_get_their_own_rows_and_capacity_is_enforced() -> None:
    coach = TabularCoach(n_states=2, n_actions=4)
    coach.tell(coach.ask((0, 0), 1), 1)
    assert coach.greedy((0, 0)) == 1
    assert coach.greedy((0, 1)) == 0  # untouched row: uniform, lowest index
    with pytest.raises(ValueError, match="n_states"):
        coach.ask((5, 5), 0)
    with pytest.raises(ValueError, match="integer indices"):
        coach.ask(0, 0)


def test_invalid_states_actions_and_config_are_refused() -> None:
    coach = TabularCoach(n_states=3, n_actions=4)
    with pytest.raises(ValueError, match="state"):
        coach.ask(3, 0)
    with pytest.raises(ValueError, match="action"):
        coach.ask(0, 4)
    with pytest.raises(ValueError, match="action"):
        coach.ask(0, 1.5)
    with pytest.raises(ValueError, match=r"learning_rate .*-1"):
        CoachConfig(learning_rate=-1.0)
    with pytest.raises(ValueError, match=r"trace_decay .*\[0.0, 1.0\]"):
        CoachConfig(trace_decay=1.5)


def test_feedback_from_an_expert_teaches_the_expert_policy() -> None:
    expert_actions = [3, 0, 2, 1, 1, 0, 3, 2]
    coach = TabularCoach(n_states=8, n_actions=4)
    teacher = ScriptedFeedbackTeacher(expert=lambda s: expert_actions[s])
    rng = np.random.default_rng(0)
    for step in range(400):
        state = step % 8
        query = coach.ask(state, coach.act(state, rng))
        coach.tell(query, teacher.answer(query))
    assert [coach.greedy(s) for s in range(8)] == expert_actions
    assert min(coach.probabilities(s)[expert_actions[s]] for s in range(8)) > 0.9

"""Tabular COACH (MacGlashan et al. 2017): a softmax policy table trained with feedback as advantage (Eq. 1).

The high-level goal selector of the paper: states are grid cells of the desk, actions the four moves. The
teacher's feedback f stands in for the advantage in the policy gradient, Eq. 1:

    grad J(theta) = E_{a ~ pi(.|s)} [ grad_theta log pi(a|s) * f ],

and for a softmax over the row theta[s], grad_theta[s] log pi(a|s) = onehot(a) - pi(.|s).
"""

from __future__ import annotations

import numbers
from collections.abc import Hashable
from dataclasses import dataclass
from typing import Annotated

import numpy as np

from hipref.teachers.feedback import FeedbackQuery, validate_feedback
from hipref.validation import Range, check_fields, check_int


@dataclass(frozen=True)
class CoachConfig:
    """Step size and eligibility trace of tabular COACH."""

    learning_rate: Annotated[float, Range(0.0, 1e3)] = 0.5
    """alpha in theta[s] += alpha * f * grad log pi(a|s). The paper gives no value; at 0.5 five consistent
    positive feedbacks raise an action's probability from 0.25 (uniform over four moves) to about 0.68, so
    the 50 feedback episodes of A.7 are plenty."""
    trace_decay: Annotated[float, Range(0.0, 1.0)] = 0.0
    """lambda of Real-time COACH's eligibility trace e <- lambda * e + grad log pi(a|s), in [0, 1]. It lets a
    feedback also credit the steps just before the one asked about (useful when a person's feedback lags).
    0 (the default) is plain Eq. 1: each feedback updates only the queried state."""

    def __post_init__(self) -> None:
        check_fields(self)


class TabularCoach:
    """Softmax policy pi(a|s) proportional to exp(theta[s, a]), learnt from feedback through ask/tell.

    States are either integer indices in [0, n_states) or any other hashable value (such as a (row, col)
    grid coordinate), which is given the next free row of the table when first seen. One learner uses one
    kind: mixing integers and other keys would let two different states share a row.
    """

    def __init__(self, n_states: int, n_actions: int, config: CoachConfig | None = None) -> None:
        check_int("n_states", n_states, 1)
        check_int("n_actions", n_actions, 2)
        self.config = config if config is not None else CoachConfig()
        self.n_states = n_states
        self.n_actions = n_actions
        # Zero preferences: the uniform policy, so nothing is assumed before the teacher speaks.
        self.theta = np.zeros((n_states, n_actions))
        self.trace = np.zeros((n_states, n_actions))
        self._rows: dict[Hashable, int] = {}
        self._integer_states: bool | None = None

    def _row(self, state: Hashable) -> int:
        integral = isinstance(state, numbers.Integral) and not isinstance(state, bool | np.bool_)
        index = int(state) if integral and isinstance(state, numbers.Integral) else None
        is_integer = index is not None
        if self._integer_states is None:
            self._integer_states = is_integer
        elif self._integer_states != is_integer:
            raise ValueError(f"states must all be integer indices or all other hashables; got {state!r}")
        if index is not None:
            check_int("state", index, 0, self.n_states - 1)
            return index
        if state not in self._rows:
            if len(self._rows) == self.n_states:
                raise ValueError(
                    f"more than n_states={self.n_states} distinct states seen; new state {state!r}"
                )
            self._rows[state] = len(self._rows)
        return self._rows[state]

    def probabilities(self, state: Hashable) -> np.ndarray:
        """pi(.|s): the softmax of theta[s]."""
        logits = self.theta[self._row(state)]
        weights = np.exp(logits - logits.max())  # shifted by the max so exp cannot overflow
        return weights / weights.sum()

    def act(self, state: Hashable, rng: np.random.Generator) -> int:
        """Sample a ~ pi(.|s): the exploration the expectation in Eq. 1 is taken over."""
        return int(rng.choice(self.n_actions, p=self.probabilities(state)))

    def greedy(self, state: Hashable) -> int:
        """The most probable action in s (ties: the lowest index), for evaluation."""
        return int(np.argmax(self.theta[self._row(state)]))

    def _check_action(self, action: object) -> int:
        if not isinstance(action, numbers.Integral) or isinstance(action, bool | np.bool_):
            raise ValueError(f"action must be an integer in [0, {self.n_actions - 1}], got {action!r}")
        check_int("action", int(action), 0, self.n_actions - 1)
        return int(action)

    def ask(self, state: Hashable, action: int) -> FeedbackQuery:
        """The question to put to a teacher about taking `action` in `state`."""
        self._row(state)
        return FeedbackQuery(state=state, action=self._check_action(action))

    def tell(self, query: FeedbackQuery, feedback: int) -> None:
        """Apply the teacher's feedback f in {-1, 0, 1} on the queried (state, action)."""
        f = validate_feedback(feedback)
        s = self._row(query.state)
        a = self._check_action(query.action)
        # Eq. 1: grad_theta[s] log pi(a|s) for a softmax row is onehot(a) - pi(.|s).
        grad_log_pi = -self.probabilities(query.state)
        grad_log_pi[a] += 1.0
        # Real-time COACH's trace; with trace_decay = 0 it is just this step's gradient.
        self.trace *= self.config.trace_decay
        self.trace[s] += grad_log_pi
        # Eq. 1 ascent step with f as the advantage: f = 0 leaves theta unchanged.
        self.theta += self.config.learning_rate * f * self.trace

    def reset_trace(self) -> None:
        """Clear the eligibility trace; call at the start of an episode so credit does not cross episodes."""
        self.trace[:] = 0.0

"""Feedback on the high-level policy: the query, the allowed answers and a scripted teacher (sections 4, 5).

A learner asks about one (state, action) it took; a teacher answers with f in {-1, 0, 1}: -1 discourages
the behaviour, 0 is indifference and 1 encourages it (the convention of COACH and TAMER).
"""

from __future__ import annotations

import math
import numbers
from collections.abc import Callable, Hashable
from dataclasses import dataclass
from typing import Any

import numpy as np

from hipref.validation import check_range

FEEDBACK_VALUES: tuple[int, ...] = (-1, 0, 1)
"""The feedback a teacher may give (section 4: f in {-1, 0, 1})."""


@dataclass(frozen=True)
class FeedbackQuery:
    """A learner's question 'was taking `action` in `state` good?'."""

    state: Hashable
    """The high-level state in which the action was taken (a grid coordinate or an integer index)."""
    action: Any
    """The action the agent took (an integer index for the grid world)."""


def validate_feedback(feedback: object) -> int:
    """Return `feedback` as an int if it is one of -1, 0, 1; raise ValueError otherwise.

    Booleans are refused: True would silently count as +1 although feedback is ternary.
    """
    if (
        not isinstance(feedback, numbers.Real)
        or isinstance(feedback, bool | np.bool_)
        or not math.isfinite(float(feedback))
        or float(feedback) not in FEEDBACK_VALUES
    ):
        raise ValueError(f"feedback must be one of {list(FEEDBACK_VALUES)}, got {feedback!r}")
    return int(float(feedback))


class ScriptedFeedbackTeacher:
    """Answers +1 when the agent did what the expert would have done in that state, -1 when it did not.

    This is the paper's simulated teacher (section 5, 'Teacher details'); its high-level feedback is
    noise-free (A.7), so both noise options default to off. They are here so the study can ask what noisy
    feedback would do without touching the learner.
    """

    def __init__(
        self,
        # Any: each learner has its own kind of state (a grid cell, a flat observation) and of action.
        expert: Callable[[Any], Any],
        flip_probability: float = 0.0,
        indifferent_probability: float = 0.0,
        rng: np.random.Generator | None = None,
    ) -> None:
        """
        Args:
            expert: maps a state to the expert's action in it.
            flip_probability: probability that a +1/-1 answer has its sign flipped, in [0, 1].
            indifferent_probability: probability of answering 0 whatever the action (an inattentive
                teacher), in [0, 1]; drawn before the flip, so an indifferent answer is never flipped.
            rng: source of the noise; required when either probability is positive.
        """
        check_range("flip_probability", flip_probability, 0.0, 1.0)
        check_range("indifferent_probability", indifferent_probability, 0.0, 1.0)
        if rng is None and (flip_probability > 0 or indifferent_probability > 0):
            raise ValueError(
                "rng must be a numpy.random.Generator when a noise probability is positive, got None"
            )
        self.expert = expert
        self.flip_probability = float(flip_probability)
        self.indifferent_probability = float(indifferent_probability)
        self.rng = rng

    def answer(self, query: FeedbackQuery) -> int:
        """Feedback on the queried (state, action): 1 if it matches the expert, -1 if not, noise applied."""
        # Draw only when a noise option is on, so a noise-free teacher consumes no randomness.
        if self._happens(self.indifferent_probability):
            return 0
        # np.array_equal also covers vector-valued actions; for grid actions it is plain equality.
        feedback = 1 if np.array_equal(query.action, self.expert(query.state)) else -1
        if self._happens(self.flip_probability):
            feedback = -feedback
        return feedback

    def _happens(self, probability: float) -> bool:
        """One draw of an event of `probability`; none at probability 0."""
        if probability == 0:
            return False
        assert self.rng is not None  # the constructor requires an rng when a probability is positive
        return bool(self.rng.random() < probability)

"""The goal-conditioned low-level policy pi^l(q_bar | s, phi) of A.3, as the tasks execute it.

Two low levels give the joint reference q_bar that SPD (Eq. 5-6) tracks: the analytic stack of Fig. 6
(admittance -> IK -> SPD, with its own state: Algorithm 3's position-controlled system P, the expert) and a
learned policy (`hipref.learners.imitation`) that maps the state, the goal and phi to q_bar directly. Both
act once per control period through the same SPD, so physics and the torque law stay the same loop.

What a learned pi^l sees at the start of a control period (the state s, `STATE_SIZE` values): the last
period's features (joint positions, joint velocities, wrist force and joint reference,
`hipref.control.tool`), the tool tip's position and the time since the episode began. Its goal g is the
task's, a few points: wiping, the next point of the stroke's reference path; pushing, the cube's goal and
its start on the desk. pi^l is given them relative to the tool tip (`relative_goal`): what P's inverse
kinematics acts on is that difference, which a network reads at once but finds hard to form from two
absolute positions whose spread is a hundred times larger.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple, Protocol

import numpy as np

from hipref.control.tool import FEATURES_PER_PERIOD, ToolController

LOW_LEVELS: tuple[str, ...] = ("admittance", "learned")
"""The low levels a task executes: the analytic admittance-on-SPD stack, or a policy learned from it."""

STATE_SIZE = FEATURES_PER_PERIOD + 3 + 1
"""Values of the state s: the last period's features, the tool tip's position (3) and the time (1)."""
TIME = STATE_SIZE - 1
"""The column of a state holding the time in s since the episode began."""
REFERENCE = slice(15, 21)
"""The columns of a period's features holding the joint reference q_bar SPD tracked."""


class JointReferencePolicy(Protocol):
    """A learned pi^l: the joint reference q_bar (6) from the state s, the goal g and phi."""

    @property
    def goal_size(self) -> int:
        """Values of the goal g it was trained for."""
        ...

    def __call__(self, state: np.ndarray, goal: np.ndarray, phi: float) -> np.ndarray: ...


class Demonstration(NamedTuple):
    """One trajectory tau of the expert P (Algorithm 3, line 6): per control period, what pi^l sees and
    the joint reference P gave."""

    states: np.ndarray
    """(periods, STATE_SIZE): the state s at the start of each period."""
    goals: np.ndarray
    """(periods, goal size): the goal g of each period, relative to the tool tip (`relative_goal`)."""
    phi: float
    """The parameter the simulator was set to, which P was given."""
    references: np.ndarray
    """(periods, 6): q_bar, the joint reference P gave SPD over each period."""


def check_policy(
    policy: JointReferencePolicy | None, goal_size: int, task: str
) -> JointReferencePolicy | None:
    """A task's learned pi^l (None: the analytic one), refused before any physics unless it was trained for
    the task's goal of `goal_size` values."""
    if policy is not None and policy.goal_size != goal_size:
        raise ValueError(
            f"low_level must be a policy trained for {task}'s goal of {goal_size} values, "
            f"got one trained for {policy.goal_size}"
        )
    return policy


def relative_goal(points: np.ndarray, tool_pos: np.ndarray) -> np.ndarray:
    """The goal pi^l is given: the goal's points (points, dims), each less the tool tip's first `dims`
    coordinates, flattened."""
    return (points - tool_pos[: points.shape[-1]]).reshape(-1)


def initial_state(controller: ToolController) -> np.ndarray:
    """The state at an episode's start (after the task's reset): the arm at rest holding its pose."""
    state = np.zeros(STATE_SIZE)
    state[:FEATURES_PER_PERIOD] = controller.observation()
    state[FEATURES_PER_PERIOD:TIME] = controller.tool_position()
    return state


Perturb = Callable[[int], np.ndarray]
"""Given a number of control periods, a (periods, 6) perturbation of the joint reference SPD tracks (what
a perturbed demonstration executes; `hipref.learners.imitation`)."""


def demonstration(
    first: np.ndarray,
    features: np.ndarray,
    tool_pos: np.ndarray,
    goal_points: np.ndarray,
    phi: float,
    control_period: float,
    perturbation: np.ndarray,
) -> Demonstration:
    """The demonstration of an expert execution whose per-period `features` and `tool_pos` were recorded,
    starting from the state `first`: period p's state is what period p - 1 ended with; `goal_points`
    (periods, points, dims) are each period's goal. SPD tracked P's reference plus the row of
    `perturbation` (its last row past its end); the labels are P's own."""
    periods = len(features)
    rows = np.minimum(np.arange(periods), len(perturbation) - 1)
    states = np.empty((periods, STATE_SIZE))
    states[0] = first
    states[1:, :FEATURES_PER_PERIOD] = features[:-1]
    states[1:, FEATURES_PER_PERIOD:TIME] = tool_pos[:-1]
    states[:, TIME] = np.arange(periods) * control_period
    tools = states[:, FEATURES_PER_PERIOD:TIME]
    goals = np.stack([relative_goal(g, tool) for g, tool in zip(goal_points, tools, strict=True)])
    return Demonstration(states, goals, float(phi), features[:, REFERENCE] - perturbation[rows])


def no_perturbation(periods: int) -> np.ndarray:
    """The unperturbed execution: zeros."""
    return np.zeros((periods, 6))


def execute_policy(
    controller: ToolController,
    policy: JointReferencePolicy,
    goal_points: np.ndarray,
    phi: float,
    control_period: float,
    done: Callable[[int], bool] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Execute the learned pi^l from the state the task was reset to, one control period per goal of
    `goal_points` (periods, points, dims), given `phi`; `done(p)`, asked after period p, may end it early.
    Returns the periods' features (periods, 21) and tool tip positions (periods, 3)."""
    state = initial_state(controller)
    features = np.empty((len(goal_points), FEATURES_PER_PERIOD))
    tool_pos = np.empty((len(goal_points), 3))
    for period, points in enumerate(goal_points):
        state[TIME] = period * control_period
        goal = relative_goal(points, state[FEATURES_PER_PERIOD:TIME])
        features[period], tool_pos[period] = controller.hold(policy(state, goal, phi))
        state[:FEATURES_PER_PERIOD] = features[period]
        state[FEATURES_PER_PERIOD:TIME] = tool_pos[period]
        if done is not None and done(period):
            return features[: period + 1], tool_pos[: period + 1]
    return features, tool_pos

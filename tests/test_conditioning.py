"""Teaching pi^l its phi (issue 29): demonstrations told an estimate carry it as their label, and a pi^l
that ignores its phi is caught, on the network (`phi_response`) and on rollouts' outcomes (`conditioning`)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

from hipref.envs.low_level import STATE_SIZE, no_perturbation
from hipref.envs.pushing import PushingTask
from hipref.envs.wiping import WipingTask
from hipref.experiments.conditioning import conditioning
from hipref.experiments.low_level import demonstrations
from hipref.learners.imitation import (
    ImitationConfig,
    estimate_around,
    learn_low_level_policy,
    phi_response,
)


@pytest.mark.parametrize("task", [WipingTask(), PushingTask()], ids=["wiping", "pushing"])
def test_a_demonstration_told_an_estimate_off_the_truth_is_labelled_with_the_estimate(task) -> None:
    layout = task.sample_layout(np.random.default_rng(3))
    low, high = task.parameter_range
    truth, told = low + 0.3 * (high - low), low + 0.4 * (high - low)
    honest = task.demonstrate(truth, layout, no_perturbation)
    taught = task.demonstrate(truth, layout, no_perturbation, estimate=told)
    assert honest.phi == truth and taught.phi == told
    # The same world and start; the expert acting on another parameter acts otherwise.
    assert np.array_equal(honest.states[0], taught.states[0])
    periods = min(len(honest.references), len(taught.references))
    assert not np.allclose(honest.references[:periods], taught.references[:periods], atol=1e-4)
    with pytest.raises(ValueError, match="estimate"):
        task.demonstrate(truth, layout, no_perturbation, estimate=high + 1.0)


def test_algorithm_3s_data_read_around_the_truth_is_labelled_with_the_estimate_not_the_truth() -> None:
    """The same iterations' worlds and layouts in both readings; only the label and P's actions differ."""
    taught_config = ImitationConfig(iterations=1, normalise_after=1, estimate_spread=1.0)
    paper = demonstrations("pushing", dataclasses.replace(taught_config, estimate_spread=0.0), False)[0]
    taught = demonstrations("pushing", taught_config, False)[0]
    assert taught.phi != paper.phi
    assert np.array_equal(taught.states[0], paper.states[0])


def test_an_estimate_around_the_truth_stays_in_the_range_and_within_the_spread() -> None:
    rng = np.random.default_rng(0)
    assert estimate_around(rng, 12.0, 8.0, 20.0, 0.0) == 12.0
    near = np.array([estimate_around(rng, 9.0, 8.0, 20.0, 0.25) for _ in range(500)])
    assert near.min() >= 8.0 and near.max() <= 12.0 and near.max() > 11.5
    anywhere = np.array([estimate_around(rng, 9.0, 8.0, 20.0, 1.0) for _ in range(500)])
    assert anywhere.min() < 9.0 and anywhere.max() > 19.0


def test_a_policy_whose_phi_input_is_replaced_by_a_constant_does_not_respond_to_phi() -> None:
    tau = PushingTask().demonstrate(12.0, PushingTask().sample_layout(np.random.default_rng(1)))
    config = ImitationConfig(iterations=2, updates_per_iteration=5, normalise_after=1, hidden=(16,))
    trained = learn_low_level_policy([tau, tau._replace(phi=16.0)], STATE_SIZE, tau.goals.shape[1], config)

    def constant(state: np.ndarray, goal: np.ndarray, phi: float) -> np.ndarray:
        return trained.policy(state, goal, 14.0)

    assert phi_response(trained.policy, tau, 0.12) > 0.0
    assert phi_response(constant, tau, 0.12) == 0.0


def outcomes(learned_slope: float, seeds: int = 12) -> pd.DataFrame:
    """Rows of an expert whose outcome moves 2 per unit of error and a learned pi^l moving `learned_slope`,
    each episode with its own offset and a little noise."""
    rng = np.random.default_rng(0)
    rows = []
    for seed in range(seeds):
        offset = rng.normal(0.0, 1.0)
        for error in (-2.0, 0.0, 2.0):
            rows.append(("admittance", seed, error, offset + 2.0 * error + rng.normal(0.0, 0.1)))
            rows.append(("learned", seed, error, offset + learned_slope * error + rng.normal(0.0, 0.1)))
    frame = pd.DataFrame(rows, columns=["method", "seed", "estimate_error", "value"])
    return frame.assign(metric="goal_overshoot")


def test_the_conditioning_check_tells_a_learned_slope_like_the_experts_from_one_that_ignores_phi() -> None:
    assert conditioning(outcomes(2.0), "goal_overshoot", "learned").verdict == "yes"
    ignored = conditioning(outcomes(0.0), "goal_overshoot", "learned")
    assert ignored.verdict == "no"
    assert ignored.difference.high < -1.5 and ignored.expert.low > 1.8


def test_a_policy_blind_to_state_columns_acts_the_same_whatever_they_hold() -> None:
    tau = PushingTask().demonstrate(12.0, PushingTask().sample_layout(np.random.default_rng(1)))
    blind = tuple(range(15, 21))
    config = ImitationConfig(
        iterations=1, updates_per_iteration=5, normalise_after=1, hidden=(16,), blind=blind
    )
    policy = learn_low_level_policy([tau], STATE_SIZE, tau.goals.shape[1], config).policy
    state, goal = tau.states[10], tau.goals[10]
    moved = state.copy()
    moved[list(blind)] += 0.3
    assert np.array_equal(policy(state, goal, 12.0), policy(moved, goal, 12.0))
    moved[6] += 0.3  # a column it sees
    assert not np.array_equal(policy(state, goal, 12.0), policy(moved, goal, 12.0))
    with pytest.raises(ValueError, match="blind"):
        ImitationConfig(blind=(2,))

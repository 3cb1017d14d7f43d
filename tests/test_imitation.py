"""Algorithm 3 (A.3): the replay buffer and the MSE update behave as written, a learned pi^l plugs into the
tasks where the analytic one does, and what does not fit it is refused before anything is computed."""

from __future__ import annotations

import numpy as np
import pytest

from hipref.envs.low_level import REFERENCE, STATE_SIZE, Demonstration, no_perturbation
from hipref.envs.pushing import PushingTask
from hipref.envs.task import clip
from hipref.envs.wiping import WipingTask
from hipref.experiments.learned_controller import LearnedControllerConfig
from hipref.experiments.low_level import LowLevel
from hipref.experiments.si_pretraining import PretrainData, pretrained_model
from hipref.learners.imitation import (
    ImitationConfig,
    ImitationResult,
    ReplayBuffer,
    collect_demonstrations,
    learn_low_level_policy,
    perturbation,
)

LAYOUT = (np.array([-0.05, 0.0]), np.array([0.03, 0.04]))
"""A short stroke (wiping): its demonstration is about 130 control periods, approach included."""


def fit_one_trajectory(tau: Demonstration, goal_size: int, iterations: int, updates: int) -> ImitationResult:
    """Algorithm 3 whose every iteration brings the same trajectory `tau`."""
    config = ImitationConfig(
        iterations=iterations, updates_per_iteration=updates, normalise_after=1, hidden=(64, 64)
    )
    return learn_low_level_policy([tau] * iterations, STATE_SIZE, goal_size, config)


@pytest.fixture(scope="module")
def stroke_demonstration() -> Demonstration:
    return WipingTask().demonstrate(0.7, LAYOUT)


def test_a_policy_trained_on_a_fixed_expert_trajectory_reproduces_it(
    stroke_demonstration: Demonstration,
) -> None:
    """Open loop: the expert's own states give back its references, to a small fraction of how far they
    move."""
    tau = stroke_demonstration
    policy = fit_one_trajectory(tau, WipingTask.goal_size, iterations=40, updates=50).policy
    spread = np.ptp(tau.references - tau.states[:, :6], axis=0).max()
    assert np.abs(policy.references(tau) - tau.references).max() < 0.05 * spread


def test_a_policy_taught_one_stroke_with_perturbed_demonstrations_retraces_it() -> None:
    """Closed loop: taught one stroke (one goal, one height) from perturbed executions, the policy moves the
    sponge along the expert's path, from the same start (its contact force is not asked to match)."""
    teacher = WipingTask()
    config = ImitationConfig(iterations=40, updates_per_iteration=50, hidden=(64, 64))
    demonstrations = collect_demonstrations(
        lambda rng: (LAYOUT, 0.7),
        lambda layout, phi, perturb: teacher.demonstrate(phi, layout, perturb),
        teacher.control_period,
        config,
    )
    policy = learn_low_level_policy(demonstrations, STATE_SIZE, WipingTask.goal_size, config).policy
    start, goal = LAYOUT
    strokes = []
    for task in (WipingTask(low_level=policy), WipingTask()):
        task.reset(0.7, (float(start[0]), float(start[1])))
        strokes.append(task.execute(goal, 0.7))
    learned, expert = strokes
    assert learned.features.shape == expert.features.shape
    assert np.abs(learned.tool_xy - expert.tool_xy).max() < 0.01
    assert learned.reached and expert.reached


def test_the_mse_update_starts_once_r_is_measured_and_the_loss_falls(
    stroke_demonstration: Demonstration,
) -> None:
    tau = stroke_demonstration
    config = ImitationConfig(iterations=6, updates_per_iteration=7, normalise_after=4, hidden=(16,))
    result = learn_low_level_policy([tau] * 6, STATE_SIZE, 3, config)
    # Line 10 runs after each iteration from the one that completes R's standardisation on.
    assert len(result.losses) == (6 - 4 + 1) * 7
    assert result.losses[-3:].mean() < result.losses[:3].mean()


def test_a_snapshot_is_the_policy_a_run_of_that_many_iterations_trains(
    stroke_demonstration: Demonstration,
) -> None:
    """What lets notebook 10 draw pi^l's learning curve from one training run."""
    tau = stroke_demonstration

    def trained(iterations: int, snapshots: tuple[int, ...] = ()) -> ImitationResult:
        config = ImitationConfig(
            iterations=iterations,
            updates_per_iteration=3,
            normalise_after=2,
            hidden=(16,),
            snapshots=snapshots,
        )
        return learn_low_level_policy([tau] * iterations, STATE_SIZE, 3, config)

    long, short = trained(6, snapshots=(3,)), trained(3)
    assert set(long.snapshots) == {3} and not short.snapshots
    copy = long.snapshots[3]
    for a, b in zip(
        [*copy.weights, *copy.biases], [*short.policy.weights, *short.policy.biases], strict=True
    ):
        assert np.array_equal(a, b)
    # A copy: the three later iterations moved the trained policy, not the snapshot.
    assert not np.array_equal(long.policy.weights[0], copy.weights[0])


def test_r_holds_every_row_pushed_and_samples_them_uniformly() -> None:
    rng = np.random.default_rng(0)
    buffer = ReplayBuffer(STATE_SIZE, 2)
    for periods, phi in ((5, 0.6), (3, 0.8)):
        states = rng.normal(size=(periods, STATE_SIZE))
        buffer.push(Demonstration(states, rng.normal(size=(periods, 2)), phi, states[:, :6] + 1.0))
    assert len(buffer) == 8 and buffer.trajectories == 2
    inputs, targets = buffer.arrays()
    # Input rows: state, goal, phi; targets: q_bar - q.
    assert inputs.shape == (8, STATE_SIZE + 2 + 1)
    assert np.array_equal(inputs[:5, -1], np.full(5, 0.6)) and np.array_equal(inputs[5:, -1], np.full(3, 0.8))
    assert np.allclose(targets, 1.0)
    drawn, _ = buffer.sample(np.random.default_rng(1), 4000)
    counts = np.unique(drawn[:, 0], return_counts=True)[1]
    assert len(counts) == 8 and counts.min() > 400


@pytest.mark.parametrize(
    ("goal", "phi", "message"),
    [
        (np.zeros(2), 0.7, r"goals must be \(1, 3\)"),
        (np.zeros((1, 3)), 0.7, r"goals must be \(1, 3\)"),
        (np.zeros(3), np.array([0.7, 0.8]), "phi must be one finite number"),
        (np.zeros(3), float("nan"), "phi must be one finite number"),
    ],
)
def test_a_wrong_shaped_goal_or_phi_is_refused(
    stroke_demonstration: Demonstration, goal: np.ndarray, phi: object, message: str
) -> None:
    tau = stroke_demonstration
    policy = fit_one_trajectory(tau, 3, iterations=1, updates=1).policy
    with pytest.raises(ValueError, match=message):
        policy(tau.states[0], goal, phi)  # type: ignore[arg-type]


def test_a_trajectory_of_other_shapes_than_r_is_refused() -> None:
    buffer = ReplayBuffer(STATE_SIZE, 3)
    states = np.zeros((4, STATE_SIZE))
    with pytest.raises(ValueError, match=r"goals must be \(4, 3\)"):
        buffer.push(Demonstration(states, np.zeros((4, 2)), 0.7, np.zeros((4, 6))))
    with pytest.raises(ValueError, match=r"states must be \(periods, 25\)"):
        buffer.push(Demonstration(np.zeros((4, 7)), np.zeros((4, 3)), 0.7, np.zeros((4, 6))))
    with pytest.raises(ValueError, match=r"references must be \(4, 6\)"):
        buffer.push(Demonstration(states, np.zeros((4, 3)), 0.7, np.zeros((4, 5))))
    assert len(buffer) == 0


def test_a_policy_for_another_tasks_goal_is_refused_by_the_task(stroke_demonstration: Demonstration) -> None:
    policy = fit_one_trajectory(stroke_demonstration, 3, iterations=1, updates=1).policy
    with pytest.raises(ValueError, match="trained for pushing's goal of 4 values, got one trained for 3"):
        PushingTask(low_level=policy)
    assert WipingTask(low_level=policy).low_level is policy


def test_si_pretrained_on_a_learned_low_level_keeps_its_network_in_the_cache_it_is_given(
    tmp_path, monkeypatch
) -> None:
    default, given = tmp_path / "default", tmp_path / "given"
    monkeypatch.setenv("HIPREF_CACHE_DIR", str(default))
    # A config of its own (seed 5), so that no other test of this process has the network in memory.
    imitation = ImitationConfig(iterations=10, updates_per_iteration=2, hidden=(8,), seed=5)
    data = PretrainData(
        n_trajectories=2, trajectory_steps=20, pretrain_steps=2, low_level=LowLevel("learned", imitation)
    )
    pretrained_model("wiping", data, given)
    assert len(list((given / "artefacts").glob("low_level_wiping-*.pkl"))) == 1
    assert not list(default.rglob("*low_level_wiping*"))


def test_a_learned_wiping_slice_is_the_start_of_its_whole_rollout(
    stroke_demonstration: Demonstration,
) -> None:
    """What `clip` relies on: the first periods of a stroke, executed alone, are the whole stroke's."""
    policy = fit_one_trajectory(stroke_demonstration, 3, iterations=2, updates=5).policy
    task = WipingTask(low_level=policy)
    whole = task.rollout(0.7, 0.68, LAYOUT).features
    assert len(whole) == task.planned_periods(LAYOUT)
    assert np.array_equal(task.rollout(0.7, 0.68, LAYOUT, periods=20).features, whole[:20])
    tau = clip(task, 0.7, 0.68, LAYOUT, 3, np.random.default_rng(0)).tau
    assert tau.shape == (3 * 21,)


@pytest.mark.parametrize("task", [WipingTask(), PushingTask()], ids=["wiping", "pushing"])
def test_a_demonstrations_labels_are_the_experts_references_not_the_perturbed_ones(task) -> None:
    layout = task.sample_layout(np.random.default_rng(3))
    plain = task.demonstrate(task.parameter_range[0] + 0.1, layout, no_perturbation)
    offsets = perturbation(np.random.default_rng(0), 2000, 0.01, 0.2, 0.01)
    perturbed = task.demonstrate(task.parameter_range[0] + 0.1, layout, lambda n: offsets[:n])
    assert plain.states.shape[1] == STATE_SIZE and plain.goals.shape[1] == task.goal_size
    # Unperturbed, the label of period p is the reference SPD tracked in it (its features, the next state).
    assert np.array_equal(plain.references[:-1], plain.states[1:, REFERENCE])
    # Perturbed, SPD tracked the label plus the offset, and the arm went elsewhere.
    periods = min(len(perturbed.references), len(offsets)) - 1
    tracked = perturbed.states[1 : periods + 1, REFERENCE]
    assert np.allclose(tracked - offsets[:periods], perturbed.references[:periods], atol=1e-12)
    assert not np.allclose(perturbed.states[5:20, :6], plain.states[5:20, :6], atol=1e-3)


def test_iteration_is_demonstration_is_the_same_in_a_short_run_and_a_long_one() -> None:
    """What lets a study read the start of a longer study's demonstrations, and what the batches' own
    stream guarantees: collecting draws nothing the updates draw."""
    teacher = PushingTask()

    def collected(iterations: int) -> list[Demonstration]:
        config = ImitationConfig(iterations=iterations, normalise_after=1)
        return collect_demonstrations(
            lambda rng: (teacher.sample_layout(rng), float(rng.uniform(8.0, 20.0))),
            lambda layout, phi, perturb: teacher.demonstrate(phi, layout, perturb),
            teacher.control_period,
            config,
        )

    short, long = collected(2), collected(3)
    for a, b in zip(short, long[:2], strict=True):
        assert (
            a.phi == b.phi
            and np.array_equal(a.states, b.states)
            and np.array_equal(a.references, b.references)
        )


def test_algorithm_3_runs_one_iteration_per_demonstration(stroke_demonstration: Demonstration) -> None:
    with pytest.raises(ValueError, match="runs 3 iterations, got 2 trajectories"):
        learn_low_level_policy(
            [stroke_demonstration] * 2, STATE_SIZE, 3, ImitationConfig(iterations=3, normalise_after=1)
        )


def test_the_perturbation_is_smooth_with_the_spread_asked() -> None:
    offsets = perturbation(np.random.default_rng(0), 20000, 0.02, 0.2, 0.01)
    assert offsets.shape == (20000, 6)
    assert np.all(offsets[0] != 0.0) and np.abs(offsets[0]).max() < 0.02
    assert offsets[1000:].std() == pytest.approx(0.02, rel=0.1)
    # One period apart, an Ornstein-Uhlenbeck process of correlation time 0.2 s keeps exp(-0.05) of itself.
    lagged = np.corrcoef(offsets[1000:-1, 0], offsets[1001:, 0])[0, 1]
    assert lagged == pytest.approx(np.exp(-0.05), abs=0.01)


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: LowLevel("neural"), "kind must be one of"),
        (lambda: ImitationConfig(perturbation=-0.1), "perturbation must be"),
        (lambda: ImitationConfig(hidden=()), "hidden must hold at least one"),
        (lambda: ImitationConfig(iterations=5, normalise_after=6), "normalise_after must be"),
        (
            lambda: ImitationConfig(iterations=20, snapshots=(30,)),
            r"snapshots must be .* in \[10, 20\]",
        ),
        (
            lambda: ImitationConfig(iterations=20, snapshots=(5,)),
            r"snapshots must be .* in \[10, 20\]",
        ),
        (lambda: LearnedControllerConfig(iterations=30, snapshots=(30,)), r"snapshots must be .* \[10, 29\]"),
        (lambda: LearnedControllerConfig(snapshots=(15, 15)), "snapshots must not repeat a value"),
        (lambda: LearnedControllerConfig(height_errors=(-0.05, 0.05)), "height_errors must hold 0.0"),
        (lambda: LearnedControllerConfig(mass_errors=(0.0, 4.0, 4.0)), "mass_errors must not repeat a value"),
    ],
)
def test_bad_settings_are_refused_naming_the_parameter(make, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        make()

"""Algorithm 3 (A.3): a goal-conditioned low-level policy pi^l(q_bar | s, phi) learnt by imitation.

The expert is the position-controlled system P (the analytic admittance + IK + SPD stack, told the true
phi); pi^l is an MLP that maps the state s, the goal g and phi to the joint reference q_bar that SPD
tracks. As in the paper, each iteration samples a goal and a parameter, collects one trajectory of P in a
simulator set to that parameter, pushes it into a replay buffer R and updates pi^l by the MSE on a batch
of N (state, goal, phi, q_bar) rows sampled from R. P does not depend on pi^l, so its trajectories are
collected first (`collect_demonstrations`, lines 2-6, cached by the studies) and then pushed and learnt from
in the same order (`learn_low_level_policy`, lines 8-10): the same iterations, in two loops.

Covariate shift. A policy trained only on P's own states drifts off them and meets states it never saw:
trained this way, pi^l lost the sponge's path by centimetres within a second. So, as in DART (Laskey et
al., 2017), each demonstration is executed with P's reference perturbed by a smooth random offset (an
Ornstein-Uhlenbeck process, `perturbation`), while the labels stay P's own references: R then holds the
corrections P makes from states off its path. `perturbation=0` is Algorithm 3 read literally.

Teaching phi. Line 4 sets the simulator with phi and P is told it, so in R the phi column always equals the
world's truth phi*: the network can read what it needs from the state (the wrist force the true parameter
produces) and never sees how P's behaviour changes with phi, and then ignores its phi input (issue 29).
`estimate_spread` > 0 sets the simulator with a truth phi* and tells P an estimate phi drawn around it
(`estimate_around`), each row labelled with phi: pi^l imitates "P acting on phi" in a world whose truth is
phi*, what an SI estimate asks of it. `estimate_spread = 0` is the paper's reading, phi = phi*.

What the network predicts is q_bar - q, the offset of the reference from the joints now (the first six
values of s), each input and output standardised by its mean and spread over R's first trajectories
(`ImitationConfig.normalise_after`): P's own step, q + J^+ e, is an offset of the same kind, so the
network learns a bounded correction rather than the arm's configuration.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Annotated, Any, ClassVar, NamedTuple, Protocol, TypeVar

import numpy as np
import torch
from torch import nn

from hipref.learners.mlp import tanh_mlp
from hipref.numerics import adam
from hipref.validation import Integer, NonEmptyTuple, Range, check_fields, check_int

JOINTS = 6
"""Joints of the arm: q_bar's size, and the first values of a state (the joint positions)."""


class Trajectory(Protocol):
    """A trajectory tau of P as Algorithm 3 stores it (`hipref.envs.low_level.Demonstration`)."""

    @property
    def states(self) -> np.ndarray: ...  # (periods, state size)
    @property
    def goals(self) -> np.ndarray: ...  # (periods, goal size)
    @property
    def phi(self) -> float: ...
    @property
    def references(self) -> np.ndarray: ...  # (periods, 6)


@dataclass(frozen=True)
class ImitationConfig:
    """Algorithm 3's size and the network of pi^l (the paper gives neither; the defaults are the study's full
    profile, notebook 10)."""

    iterations: Annotated[int, Integer(1)] = 600
    """Iterations of Algorithm 3: trajectories of P collected, one per iteration."""
    updates_per_iteration: Annotated[int, Integer(1)] = 25
    """MSE updates of pi^l per collected trajectory (line 10, repeated)."""
    batch_size: Annotated[int, Integer(1)] = 128
    """N, rows per update."""
    hidden: NonEmptyTuple[Annotated[int, Integer(1, 4096)]] = (256, 256)
    """Widths of the MLP's hidden layers (tanh)."""
    learning_rate: Annotated[float, Range(1e-8, 1.0)] = 1e-3
    """Adam step size."""
    perturbation: Annotated[float, Range(0.0, 0.5)] = 0.005
    """Stationary spread in rad of the perturbation of each joint's reference in demonstrations (0: none)."""
    perturbation_time: Annotated[float, Range(1e-3, 10.0)] = 0.2
    """Correlation time in s of the perturbation: slow enough that the arm follows it off P's path."""
    estimate_spread: Annotated[float, Range(0.0, 1.0)] = 0.0
    """Half-width, as a fraction of the parameter range, of the estimate phi P is told around the truth phi*
    the simulator is set to (`estimate_around`); each row is labelled with phi. 0: phi = phi*, Algorithm 3
    read as the paper writes it; 1: phi independent of phi*, uniform over the range."""
    blind: tuple[Annotated[int, Integer(JOINTS)], ...] = ()
    """Columns of the state pi^l does not see (0 in its inputs, in R and when it acts), each past the joint
    positions: e.g. the last period's joint reference (`hipref.envs.low_level.REFERENCE`), from which the
    next reference can be extrapolated without reading phi. (): the whole state."""
    normalise_after: int = 10
    """Trajectories in R from whose rows the inputs' and outputs' standardisation is measured; updates
    begin once it is (earlier iterations only collect)."""
    seed: Annotated[int, Integer(0)] = 0
    """Seed of the sampled goals and parameters, the batches and the network's initial weights."""
    snapshots: tuple[int, ...] = ()
    """Iterations after which a copy of pi^l is also kept (`ImitationResult.snapshots`): its learning curve.
    They change nothing of the training: the copy after i iterations is the policy an `iterations=i` run
    trains."""

    SEQUENCES: ClassVar[tuple[str, ...]] = ("hidden",)
    """Layer widths, whose values may repeat (`check_fields`)."""

    def __post_init__(self) -> None:
        check_fields(self, self.SEQUENCES)
        check_int("normalise_after", self.normalise_after, 1, self.iterations)
        for iteration in self.snapshots:
            check_int("snapshots", iteration, self.normalise_after, self.iterations)


def perturbation(
    rng: np.random.Generator, periods: int, spread: float, correlation_time: float, control_period: float
) -> np.ndarray:
    """(periods, 6): an Ornstein-Uhlenbeck offset of each joint's reference, from 0, of stationary spread
    `spread` rad and correlation time `correlation_time` s, sampled once per control period."""
    decay = np.exp(-control_period / correlation_time)
    kicks = rng.normal(0.0, spread * np.sqrt(1.0 - decay**2), (periods, JOINTS))
    offsets = np.empty((periods, JOINTS))
    current = np.zeros(JOINTS)
    for p in range(periods):
        current = decay * current + kicks[p]
        offsets[p] = current
    return offsets


def estimate_around(rng: np.random.Generator, truth: float, low: float, high: float, spread: float) -> float:
    """The estimate phi P is told in a world whose truth is `truth`: uniform over the range [low, high]
    within `spread` x (high - low) of the truth (spread 1: uniform over the range, whatever the truth); with
    spread 0, the truth itself and nothing drawn."""
    if spread == 0.0:
        return float(truth)
    width = spread * (high - low)
    return float(rng.uniform(max(low, truth - width), min(high, truth + width)))


class ReplayBuffer:
    """R: every (state, goal, phi, q_bar) row of the trajectories pushed so far."""

    def __init__(self, state_size: int, goal_size: int, blind: tuple[int, ...] = ()) -> None:
        self.state_size, self.goal_size, self.blind = state_size, goal_size, blind
        self._inputs: list[np.ndarray] = []
        self._targets: list[np.ndarray] = []
        self._rows = 0
        self.trajectories = 0
        """Trajectories pushed so far."""

    def __len__(self) -> int:
        return self._rows

    def push(self, tau: Trajectory) -> None:
        """Line 8: push tau's rows into R; a tau of other shapes than R's is refused."""
        inputs = policy_inputs(tau.states, tau.goals, tau.phi, self.state_size, self.goal_size, self.blind)
        references = np.asarray(tau.references, dtype=float)
        if references.shape != (len(inputs), JOINTS):
            raise ValueError(f"references must be ({len(inputs)}, {JOINTS}), got shape {references.shape}")
        self._inputs.append(inputs)
        self._targets.append(references - inputs[:, :JOINTS])
        self._rows += len(inputs)
        self.trajectories += 1

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """Every row's input (state, goal, phi) and target (q_bar - q)."""
        if len(self._inputs) > 1:
            self._inputs = [np.concatenate(self._inputs)]
            self._targets = [np.concatenate(self._targets)]
        return self._inputs[0], self._targets[0]

    def sample(self, rng: np.random.Generator, n: int) -> tuple[np.ndarray, np.ndarray]:
        """N rows drawn uniformly with replacement."""
        inputs, targets = self.arrays()
        rows = rng.integers(0, len(inputs), n)
        return inputs[rows], targets[rows]


def policy_inputs(
    states: np.ndarray,
    goals: np.ndarray,
    phi: float,
    state_size: int,
    goal_size: int,
    blind: tuple[int, ...] = (),
) -> np.ndarray:
    """The network's input rows (state, goal, phi), the state's `blind` columns 0; states and goals of
    other shapes than pi^l's, or a phi that is not one finite number, are refused before anything is
    computed."""
    states, goals = np.asarray(states, dtype=float), np.asarray(goals, dtype=float)
    if states.ndim != 2 or states.shape[1] != state_size:
        raise ValueError(f"states must be (periods, {state_size}), got shape {states.shape}")
    if goals.shape != (len(states), goal_size):
        raise ValueError(f"goals must be ({len(states)}, {goal_size}), got shape {goals.shape}")
    if np.ndim(phi) != 0 or not np.isfinite(phi):
        raise ValueError(f"phi must be one finite number, got {phi!r}")
    inputs = np.concatenate([states, goals, np.full((len(states), 1), float(phi))], axis=1)
    inputs[:, list(blind)] = 0.0
    return inputs


class Standardisation(NamedTuple):
    """Means and spreads of the network's inputs and outputs, measured on R's first trajectories."""

    input_mean: np.ndarray
    input_scale: np.ndarray
    output_mean: np.ndarray
    output_scale: np.ndarray


def measure_standardisation(inputs: np.ndarray, targets: np.ndarray) -> Standardisation:
    """Each column's mean and standard deviation (1 where a column does not vary, such as a constant
    joint reference of a held pose)."""

    def spread(x: np.ndarray) -> np.ndarray:
        scale = x.std(axis=0)
        return np.where(scale > 1e-8, scale, 1.0)

    return Standardisation(inputs.mean(axis=0), spread(inputs), targets.mean(axis=0), spread(targets))


class LearnedLowLevelPolicy:
    """pi^l(q_bar | s, phi) as the tasks execute it (`hipref.envs.low_level.JointReferencePolicy`): the
    trained network's weights in float64 numpy arrays, so that a control period costs a few small
    matrix products and no torch call."""

    def __init__(
        self,
        network: nn.Sequential,
        scaling: Standardisation,
        state_size: int,
        goal_size: int,
        blind: tuple[int, ...] = (),
    ):
        self.state_size, self.goal_size, self.blind = state_size, goal_size, blind
        self.scaling = scaling
        linears = [m for m in network if isinstance(m, nn.Linear)]
        self.weights = [m.weight.detach().numpy().astype(np.float64) for m in linears]
        self.biases = [m.bias.detach().numpy().astype(np.float64) for m in linears]

    def offsets(self, inputs: np.ndarray) -> np.ndarray:
        """q_bar - q for input rows (rows, state + goal + 1)."""
        s = self.scaling
        x = (inputs - s.input_mean) / s.input_scale
        for w, b in zip(self.weights[:-1], self.biases[:-1], strict=True):
            x = np.tanh(x @ w.T + b)
        x = x @ self.weights[-1].T + self.biases[-1]
        return x * s.output_scale + s.output_mean

    def __call__(self, state: np.ndarray, goal: np.ndarray, phi: float) -> np.ndarray:
        """q_bar for one state s (state size), goal g (goal size) and phi."""
        state, goal = np.asarray(state, dtype=float), np.asarray(goal, dtype=float)
        inputs = policy_inputs(state[None], goal[None], phi, self.state_size, self.goal_size, self.blind)
        return inputs[0, :JOINTS] + self.offsets(inputs)[0]

    def references(self, tau: Trajectory) -> np.ndarray:
        """q_bar for each period of a trajectory's states (what it would give P's states)."""
        inputs = policy_inputs(tau.states, tau.goals, tau.phi, self.state_size, self.goal_size, self.blind)
        return inputs[:, :JOINTS] + self.offsets(inputs)


def phi_response(
    policy: Callable[[np.ndarray, np.ndarray, float], np.ndarray], tau: Trajectory, step: float
) -> float:
    """How much pi^l's joint reference moves with its phi input on tau's states and goals: the root mean
    square over periods and joints of (pi^l(s, g, phi + step) - pi^l(s, g, phi)) / step, in rad per unit
    of phi. 0 for a pi^l that ignores phi."""
    if not np.isfinite(step) or step == 0.0:
        raise ValueError(f"step must be a finite non-zero number, got {step!r}")
    moved = np.array(
        [
            policy(state, goal, tau.phi + step) - policy(state, goal, tau.phi)
            for state, goal in zip(tau.states, tau.goals, strict=True)
        ]
    )
    return float(np.sqrt(np.mean((moved / step) ** 2)))


class ImitationResult(NamedTuple):
    """Algorithm 3's product: the policy, and its training curve."""

    policy: LearnedLowLevelPolicy
    losses: np.ndarray
    """(updates,): the MSE of each update's batch, in standardised units."""
    snapshots: dict[int, LearnedLowLevelPolicy]
    """The policy after each of `ImitationConfig.snapshots` iterations."""


TrajectoryT = TypeVar("TrajectoryT", bound=Trajectory)
Collect = Callable[[Any, float, Callable[[int], np.ndarray]], TrajectoryT]
"""`collect(goal, phi, perturb)`: return the trajectory of P told phi under the goal (which may carry the
truth the simulator is set to, else phi), SPD tracking P's reference plus `perturb(periods)` (periods, 6)."""


def algorithm_streams(seed: int) -> tuple[np.random.Generator, np.random.Generator]:
    """Algorithm 3's two random streams: the goals, parameters and perturbations of the collection, and the
    batches of the updates."""
    collection, batches = np.random.SeedSequence([seed, 3]).spawn(2)
    return np.random.default_rng(collection), np.random.default_rng(batches)


def collect_demonstrations(
    sample_goal_and_phi: Callable[[np.random.Generator], tuple[Any, float]],
    collect: Collect[TrajectoryT],
    control_period: float,
    config: ImitationConfig,
    count: int | None = None,
) -> list[TrajectoryT]:
    """Algorithm 3, lines 2-6, of its first `count` iterations (all of `config.iterations` by default).

    P does not depend on pi^l, so the trajectory of iteration i is the same whether the updates run between
    the collections or after them: collected from a stream of their own, the demonstrations are an artefact
    shared by every network trained on them, and iteration i's is the same in a short run and a long one.
    `sample_goal_and_phi` draws a goal (with the truth phi* where it is not phi) and the parameter phi P is
    told; `collect` executes P, its reference perturbed as
    `config` says (`control_period` s per row of the perturbation)."""
    rng, _ = algorithm_streams(config.seed)
    demonstrations: list[TrajectoryT] = []
    for _ in range(config.iterations if count is None else count):
        # 2: randomly sample goal g and environmental parameter phi
        goal, phi = sample_goal_and_phi(rng)
        # 4-6: set the simulator with phi, collect trajectory tau using P under goal g
        tau = collect(
            goal,
            phi,
            lambda n: perturbation(rng, n, config.perturbation, config.perturbation_time, control_period),
        )
        demonstrations.append(tau)
    return demonstrations


def learn_low_level_policy(
    demonstrations: Sequence[Trajectory], state_size: int, goal_size: int, config: ImitationConfig
) -> ImitationResult:
    """Algorithm 3: pi^l learnt by imitation of P, iteration i pushing the i-th of P's `demonstrations`
    (`collect_demonstrations`, lines 2-6) into R and updating pi^l on batches of R."""
    if len(demonstrations) != config.iterations:
        raise ValueError(
            f"Algorithm 3 runs {config.iterations} iterations, got {len(demonstrations)} trajectories"
        )
    _, rng = algorithm_streams(config.seed)
    buffer = ReplayBuffer(state_size, goal_size, config.blind)
    network: nn.Sequential | None = None
    optimiser: torch.optim.Optimizer | None = None
    scaling: Standardisation | None = None
    losses: list[float] = []
    snapshots: dict[int, LearnedLowLevelPolicy] = {}
    for tau in demonstrations:
        # 8: push tau into R
        buffer.push(tau)
        if buffer.trajectories < config.normalise_after:
            continue
        if network is None:
            scaling = measure_standardisation(*buffer.arrays())
            # The MLP of pi^l: tanh hidden layers, a linear output of the 6 joints' (standardised) offsets.
            network = tanh_mlp(state_size + goal_size + 1, config.hidden, JOINTS, config.seed)
            optimiser = adam(network.parameters(), config.learning_rate)
        assert optimiser is not None and scaling is not None
        # 10: update pi^l with the MSE loss on an N-sized batch sampled from R
        for _ in range(config.updates_per_iteration):
            inputs, targets = buffer.sample(rng, config.batch_size)
            x = torch.from_numpy(((inputs - scaling.input_mean) / scaling.input_scale).astype(np.float32))
            y = torch.from_numpy(((targets - scaling.output_mean) / scaling.output_scale).astype(np.float32))
            loss = torch.mean((network(x) - y) ** 2)
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            losses.append(float(loss.detach()))
        if buffer.trajectories in config.snapshots:
            snapshots[buffer.trajectories] = LearnedLowLevelPolicy(
                network, scaling, state_size, goal_size, config.blind
            )
    assert network is not None and scaling is not None
    policy = LearnedLowLevelPolicy(network, scaling, state_size, goal_size, config.blind)
    return ImitationResult(policy, np.array(losses), snapshots)

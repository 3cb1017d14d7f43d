"""The learned low-level controller (notebook 10, paper A.3 / Algorithm 3).

1. Training: pi^l learnt by imitation of the analytic admittance-on-SPD stack in each domain
   (`hipref.experiments.low_level.learned_policy`), once per reading of its demonstrations
   (`estimate_spreads`: the expert told the truth, the paper's reading, or an estimate around it, each row
   labelled with the estimate); its MSE over updates (`imitation_mse`) and how far its joint reference
   moves with its phi input on demonstration states (`phi_response`, rad per unit of phi).
2. Controllers: the learned pi^l against its expert on the same episodes (true parameter, layout), with
   the true parameter and with estimates off it by the errors of notebook 05: success, and wiping's contact
   force over the stroke (`force_mean`, `force_std`) or pushing's final distance of the cube to its goal
   (`goal_distance`; its part along the push, past the goal positive, `goal_overshoot`, and its distance to
   the side of the push's line, `goal_sideways`); and with the true parameter, pi^l after fewer of
   Algorithm 3's iterations (its `snapshots`): how its success grows with the demonstrations. In wiping,
   the estimate's two routes into a learned stroke apart (`route`): the parameter input wrong with the path
   from the truth ('input'), or the path wrong with the true input ('path'). And the true parameter on
   held-out episodes (`held_out`), seeds apart from those the study was designed on.
3. SI on top: OSI and PESI (perfect preferences) on a grid of truths, executing the analytic low level or
   the learned one of the last reading; each low level's SI is pretrained (Algorithm 4) on its own
   rollouts.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Annotated, Any, ClassVar

import numpy as np
import pandas as pd

from hipref.envs.low_level import REFERENCE
from hipref.envs.task import ROUTES, Task
from hipref.experiments.controllers import truth_and_estimate
from hipref.experiments.domains import DOMAINS, estimate_error_grids
from hipref.experiments.low_level import LowLevel, demonstrations, learned_policy, make_task
from hipref.experiments.protocol import SIStudy
from hipref.experiments.si_pretraining import PretrainData, pretrained_model
from hipref.experiments.si_run import SIRun, run_si
from hipref.learners.imitation import ImitationConfig, phi_response
from hipref.learners.sysid import PRETRAIN_LOSSES
from hipref.numerics import one_thread
from hipref.results import tidy_rows
from hipref.seeds import child_seeds
from hipref.sweep import run_sweep
from hipref.validation import Integer, NonEmptyTuple, OneOf, Range, check_int, check_range

SI_METHODS: tuple[str, ...] = ("osi", "pesi")
"""The SI methods run on top of each low level."""
ROW_METRICS: tuple[str, ...] = (
    "imitation_mse",
    "phi_response",
    "success_rate",
    "force_mean",
    "force_std",
    "goal_distance",
    "goal_overshoot",
    "goal_sideways",
    "param_error",
    "param_error_argmax",
    "param_error_multislice",
)
"""The metrics of the study's rows."""
DOMAIN_ROUTES: dict[str, tuple[str, ...]] = {"wiping": ROUTES, "pushing": ROUTES[:1]}
"""The routes each domain's learned low level is compared by: a wiping stroke follows a path planned from
the estimate and is given it as input, so the two can be told apart; a push takes the estimate only as
input ('both')."""
RESPONSE_TRAJECTORIES = 10
"""Demonstrations of the last reading on whose states each pi^l's `phi_response` is measured."""
CURVE_POINTS = 50
"""Points of each training curve kept in the rows (the MSE averaged over as many equal runs of updates)."""


@dataclass(frozen=True)
class LearnedControllerConfig(SIStudy):
    """Parameters of notebook 10 (defaults: the quick profile). The SI fields are `SIStudy`'s; the others
    size Algorithm 3 (the paper gives no numbers for it) and the controllers' comparison."""

    SEQUENCES: ClassVar[tuple[str, ...]] = ("hidden",)

    heights: tuple[float, ...] = (0.7,)
    """True desk heights in m of the SI environments, each in [0.5, 0.9]."""
    masses: tuple[float, ...] = (14.0,)
    """True cube masses in kg of the SI environments, each in [8, 20]."""
    episodes: Annotated[int, Integer(1)] = 20
    """Learning episodes per SI run, at least 1."""
    eval_every: Annotated[int, Integer(1)] = 20
    """Learning episodes between SI evaluations (section 5: 33)."""
    eval_episodes: Annotated[int, Integer(1)] = 3
    """Evaluation episodes per SI evaluation (section 5: 10)."""
    n_trajectories: int = 10
    """Algorithm 4 trajectories, collected with each low level (A.7: 100)."""
    pretrain_steps: int = 300
    """Adam steps of Algorithm 4."""
    pretrain_loss: Annotated[str, OneOf(PRETRAIN_LOSSES)] = "brier"
    """Algorithm 4's loss: A.7's squared loss over SI's distribution, for every low level (the study's 3000
    trajectories with the negative log-likelihood would cost a collection per learned low level)."""
    iterations: int = 30
    """Algorithm 3's iterations: expert trajectories collected, one per iteration, per domain."""
    updates_per_iteration: int = 25
    """MSE updates of pi^l per collected trajectory."""
    batch_size: int = 128
    """N, rows per update."""
    hidden: tuple[int, ...] = (256, 256)
    """Widths of pi^l's hidden layers."""
    imitation_learning_rate: float = 1e-3
    """Adam step size of Algorithm 3."""
    perturbation: float = 0.005
    """Spread in rad of the perturbation of the expert's joint reference while it demonstrates (DART; 0:
    Algorithm 3 read literally)."""
    perturbation_time: float = 0.2
    """Correlation time in s of that perturbation."""
    snapshots: tuple[int, ...] = (15,)
    """Algorithm 3 iterations after which pi^l is also executed with the true parameter, on the same episodes
    (its learning curve): distinct, each from 10 (the iterations standardisation waits for) to below
    `iterations` (the trained policy is executed anyway)."""
    height_errors: tuple[float, ...] = (-0.05, 0.0, 0.05)
    """Errors in m of the desk-height estimate the controllers are compared at (notebook 05's claim: most
    strokes fail at +-0.05); distinct, 0.0 (the true parameter) among them."""
    mass_errors: tuple[float, ...] = (-4.0, 0.0, 4.0)
    """Errors in kg of the cube-mass estimate the controllers are compared at (notebook 05's claim: most
    pushes fail at +-4); distinct, 0.0 (the true parameter) among them."""
    episodes_per_error: Annotated[int, Integer(1)] = 3
    """Episodes (truth, layout) per estimate error, each executed by both low levels."""
    comparison_seed: Annotated[int, Integer(0)] = 0
    """Root seed of the comparison's episodes."""
    estimate_spreads: NonEmptyTuple[Annotated[float, Range(0.0, 1.0)]] = (0.0, 0.35)
    """Readings of Algorithm 3's demonstrations, one learned pi^l each (`ImitationConfig.estimate_spread`):
    the half-width, as a fraction of the parameter range, of the estimate the expert is told around the
    world's truth, each row labelled with the estimate. 0.0 is the paper's reading (told the truth); the
    last is the pi^l SI runs on. Distinct, each in [0, 1]."""
    blind_reference: bool = False
    """Whether pi^l does without the last period's joint reference among the state's features
    (`ImitationConfig.blind`): the next reference can be extrapolated from it without reading phi."""
    held_out_episodes: Annotated[int, Integer(1)] = 3
    """Episodes with the true parameter on held-out seeds, executed by every low level."""
    held_out_seed: Annotated[int, Integer(0)] = 1
    """Root seed of the held-out episodes: another grid than `comparison_seed`'s, on which nothing of the
    study was tuned."""

    def __post_init__(self) -> None:
        super().__post_init__()
        for snapshot in self.snapshots:
            check_int("snapshots", snapshot, ImitationConfig.normalise_after, self.iterations - 1)
        self.imitation(0.0)  # validates Algorithm 3's fields
        for domain, errors in estimate_error_grids(self).items():
            name, candidates = DOMAINS[domain].estimate_errors, DOMAINS[domain].candidates
            bound = (candidates.high - candidates.low) / 2
            if not any(error == 0.0 for error in errors):
                raise ValueError(f"{name} must hold 0.0 (the true parameter), got {list(errors)!r}")
            for error in errors:
                check_range(name, error, -bound, bound)
        if self.held_out_seed == self.comparison_seed:
            raise ValueError(f"held_out_seed must differ from comparison_seed, both {self.held_out_seed}")

    def imitation(self, estimate_spread: float) -> ImitationConfig:
        """Algorithm 3's config for one reading of its demonstrations, the same in both domains."""
        return ImitationConfig(
            iterations=self.iterations,
            updates_per_iteration=self.updates_per_iteration,
            batch_size=self.batch_size,
            hidden=tuple(self.hidden),
            learning_rate=self.imitation_learning_rate,
            perturbation=self.perturbation,
            perturbation_time=self.perturbation_time,
            snapshots=tuple(self.snapshots),
            estimate_spread=estimate_spread,
            blind=tuple(range(REFERENCE.start, REFERENCE.stop)) if self.blind_reference else (),
        )

    def learned(self) -> list[LowLevel]:
        """The learned low level of each reading; the last is the one SI runs on."""
        return [LowLevel("learned", self.imitation(spread)) for spread in self.estimate_spreads]

    def low_levels(self) -> tuple[LowLevel, LowLevel]:
        """The low levels SI runs on: the analytic one and the learned one of the last reading."""
        return LowLevel(), self.learned()[-1]


@dataclass(frozen=True)
class PreparationCell:
    """What one domain's runs load: Algorithm 3's pi^l, then Algorithm 4's SI on each low level."""

    domain: str
    imitations: tuple[ImitationConfig, ...]
    """Algorithm 3 per reading; the last's demonstrations are those `phi_response` is measured on."""
    data: tuple[PretrainData, ...]
    """Algorithm 4's data and pretraining per low level."""


@dataclass(frozen=True)
class ComparisonCell:
    """Episodes executed by one low level with an estimate `error` off the true parameter."""

    domain: str
    low_level: LowLevel
    error: float
    seeds: tuple[int, ...]
    """One episode per seed, its truth and layout drawn from it: the same for every low level."""
    snapshot: int | None = None
    """For the learned low level: the policy after this many of Algorithm 3's iterations (None: the trained
    one)."""
    route: str = "both"
    """Wiping: how the estimate reaches the learned stroke (`ROUTES`)."""
    held_out: bool = False
    """Whether the seeds are the held-out grid's."""


def run_preparation_cell(cell: PreparationCell) -> pd.DataFrame:
    """Train (or load) the domain's pi^l of each reading and pretrain SI on each low level, all cached;
    rows per reading: the training curve, the MSE averaged over CURVE_POINTS equal runs of updates, each
    row at the run's last update; and `phi_response` on each of the last reading's first
    RESPONSE_TRAJECTORIES demonstrations (`episode`: its index), with a step of 1 % of the range."""
    frames = []
    low, high = DOMAINS[cell.domain].candidates.low, DOMAINS[cell.domain].candidates.high
    shown = demonstrations(cell.domain, cell.imitations[-1])[:RESPONSE_TRAJECTORIES]
    for imitation in cell.imitations:
        trained = learned_policy(cell.domain, imitation)
        losses = trained.losses
        chunks = np.array_split(np.arange(len(losses)), min(CURVE_POINTS, len(losses)))
        rows = [(int(chunk[-1]) + 1, "imitation_mse", float(losses[chunk].mean())) for chunk in chunks]
        step = 0.01 * (high - low)
        rows += [(i, "phi_response", phi_response(trained.policy, tau, step)) for i, tau in enumerate(shown)]
        frames.append(
            tidy_rows(
                rows,
                domain=cell.domain,
                method="learned",
                noise=0.0,
                seed=imitation.seed,
                estimate_spread=imitation.estimate_spread,
            )
        )
    for data in cell.data:
        pretrained_model(cell.domain, data)
    return pd.concat(frames, ignore_index=True)


def _episode_metrics(
    task: Task, seed: int, error: float, route: str = "both"
) -> tuple[float, dict[str, float]]:
    """One episode (truth and layout from `seed`) executed with the estimate off the truth by `error`
    (`truth_and_estimate`), by the `route` (`ROUTES`): its truth, and its metrics (`Task.episode_metrics`)."""
    rng = np.random.default_rng(seed)
    truth, estimate = truth_and_estimate(rng, error, *task.parameter_range)
    return truth, task.episode_metrics(truth, estimate, task.sample_layout(rng), route)


def run_comparison_cell(cell: ComparisonCell) -> pd.DataFrame:
    """The cell's episodes, each executed by its low level."""
    frames = []
    learned = cell.low_level.kind == "learned"
    iterations = (cell.snapshot or cell.low_level.imitation.iterations) if learned else None
    with one_thread():
        task = make_task(cell.domain, cell.low_level, snapshot=cell.snapshot)
        for seed in cell.seeds:
            truth, metrics = _episode_metrics(task, seed, cell.error, cell.route)
            frames.append(
                tidy_rows(
                    [(name, float(value)) for name, value in metrics.items()],
                    ("metric", "value"),
                    domain=cell.domain,
                    method=cell.low_level.kind,
                    noise=0.0,
                    seed=seed,
                    episode=0,
                    estimate_error=cell.error,
                    ground_truth=round(truth, 6),
                    iterations=iterations,
                    estimate_spread=cell.low_level.imitation.estimate_spread if learned else None,
                    route=cell.route,
                    held_out=cell.held_out,
                )
            )
    return pd.concat(frames, ignore_index=True)


def run_evaluation_cell(cell: ComparisonCell | SIRun) -> pd.DataFrame:
    """A cell of the study's second sweep: a comparison of the low levels, or an SI run (`run_si`)."""
    return run_si(cell) if isinstance(cell, SIRun) else run_comparison_cell(cell)


def pretrain_data(config: LearnedControllerConfig) -> tuple[PretrainData, ...]:
    """Algorithm 4's data and pretraining, per low level."""
    return tuple(dataclasses.replace(config.data, low_level=low_level) for low_level in config.low_levels())


def preparation_cells(config: LearnedControllerConfig) -> list[PreparationCell]:
    imitations = tuple(low_level.imitation for low_level in config.learned())
    return [PreparationCell(domain, imitations, pretrain_data(config)) for domain in DOMAINS]


def comparison_cells(config: LearnedControllerConfig) -> list[ComparisonCell]:
    """Every (domain, error) executed by the analytic low level and each learned one on the same episodes;
    in wiping, the last reading's routes apart at every error but 0; with the true parameter, also each
    snapshot of the last reading's, and every low level on the held-out episodes."""
    analytic, learned = LowLevel(), config.learned()
    cells = []
    for label, (domain, errors) in enumerate(estimate_error_grids(config).items()):
        seeds = tuple(child_seeds([config.comparison_seed, label], config.episodes_per_error))
        held_out = tuple(child_seeds([config.held_out_seed, label], config.held_out_episodes))
        routes = DOMAIN_ROUTES[domain]
        for error in errors:
            cells.append(ComparisonCell(domain, analytic, float(error), seeds))
            cells += [ComparisonCell(domain, low_level, float(error), seeds) for low_level in learned]
            if error != 0.0:
                cells += [
                    ComparisonCell(domain, learned[-1], float(error), seeds, route=r) for r in routes[1:]
                ]
        cells += [ComparisonCell(domain, learned[-1], 0.0, seeds, snapshot) for snapshot in config.snapshots]
        cells += [ComparisonCell(domain, ll, 0.0, held_out, held_out=True) for ll in [analytic, *learned]]
    return cells


def si_cells(config: LearnedControllerConfig) -> list[SIRun]:
    """OSI and PESI (perfect preferences) in every environment of the grid, on each low level."""
    cells = []
    for low_level in config.low_levels():
        for domain in DOMAINS:
            for method in SI_METHODS:
                for truth, seed in config.environments(domain):
                    run = config.run_cell(domain, method, truth, seed)
                    cells.append(
                        dataclasses.replace(run, data=dataclasses.replace(run.data, low_level=low_level))
                    )
    return cells


def run(config: LearnedControllerConfig, **sweep: Any) -> pd.DataFrame:
    """The three parts, as one tidy frame: training curves, the controllers' comparison, SI on top.

    Two sweeps: the domains' networks and SI models side by side, then every comparison and SI run, which
    load them."""
    training = run_sweep(run_preparation_cell, preparation_cells(config), desc="Algorithms 3 and 4", **sweep)
    comparisons, runs = comparison_cells(config), si_cells(config)
    evaluated = run_sweep(run_evaluation_cell, [*comparisons, *runs], desc="low levels and SI", **sweep)
    si = evaluated[evaluated.method.isin(SI_METHODS)].copy()
    # run_si names only a learned low level; here every SI row says which one it executed.
    si["low_level"] = si["low_level"].fillna("admittance") if "low_level" in si else "admittance"
    return pd.concat([training, evaluated[~evaluated.method.isin(SI_METHODS)], si], ignore_index=True)

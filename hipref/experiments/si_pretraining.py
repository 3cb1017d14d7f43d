"""Algorithm 4 (A.4): SI pretrained once per domain on trajectories collected under domain randomisation.
The pretrained model, never updated, is OSI; every fine-tuning run starts from a copy of it.

The study's default pretrains on 3,000 trajectories with the negative log-likelihood, not on A.7's 100 with
the mean squared (Brier) loss: notebook 13 shows A.7's reading starves the model (in pushing it does no better
than always answering the middle of the range, and its 90 % intervals hold the truth about half the time).
A.7's reading stays available as `PAPER_A7` (notebook 08's 'paper_a7' variant, notebook 13's 'paper_a7')."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Annotated, Any, ClassVar, NamedTuple

import numpy as np
import pandas as pd

from hipref.envs.task import random_estimate
from hipref.experiments.domains import domain_spec
from hipref.experiments.low_level import LowLevel, make_task
from hipref.learners.sysid import PRETRAIN_LOSSES, PretrainConfig, SIModel, pretrain
from hipref.numerics import one_thread
from hipref.results import tidy_rows
from hipref.sweep import NO_CACHE, CacheDir, Expect, cached_artefact, run_sweep
from hipref.validation import Integer, NonEmptyTuple, OneOf, Range, check_fields, check_int


@dataclass(frozen=True)
class PretrainData:
    """Algorithm 4's dataset D and the pretraining of SI (A.4, A.7)."""

    n_trajectories: Annotated[int, Integer(2)] = 3000
    """Domain-randomised trajectories in D (A.7: 100, which starve SI: notebook 13)."""
    trajectory_steps: int = 100
    """Control periods per trajectory (A.7: 100 states and actions)."""
    history: Annotated[int, Integer(1)] = 3
    """h, control periods per SI input slice (Table 2: 3)."""
    pretrain_steps: Annotated[int, Integer(0)] = 3000
    """Adam steps of Algorithm 4 (its loop has no stated end)."""
    learning_rate: Annotated[float, Range(1e-8, 1.0)] = 1e-3
    """Adam step size of Algorithm 4 (Table 2: 1e-3)."""
    loss: Annotated[str, OneOf(PRETRAIN_LOSSES)] = "nll"
    """Algorithm 4's loss: 'nll', the negative log-likelihood of the true parameter's candidates, so that
    Pr(phi | tau) is a posterior (notebook 13: calibrated given enough data), or a mean squared loss as A.7
    says, over SI's distribution against the target distribution ('brier'), over its mean only
    ('expectation'), or both ('brier_expectation'); `hipref.learners.sysid.pretrain`."""
    hidden_sizes: NonEmptyTuple[Annotated[int, Integer(1)]] = (256, 128, 64, 32)
    """SI's hidden layers (Table 2: [256, 128, 64, 32], tanh)."""
    seed: Annotated[int, Integer(0)] = 0
    """Seed of the collection and of the pretraining: one pretrained model per domain, shared by all runs."""
    low_level: LowLevel = field(default_factory=LowLevel)
    """The pi^l whose rollouts make D, and which every run that starts from this model executes."""

    SEQUENCES: ClassVar[tuple[str, ...]] = ("hidden_sizes",)
    """Layer widths, whose values may repeat (`check_fields`)."""

    def __post_init__(self) -> None:
        check_fields(self, self.SEQUENCES)
        check_int("trajectory_steps", self.trajectory_steps, self.history)

    @property
    def collection(self) -> tuple[Any, ...]:
        """What the trajectories of D depend on besides their number (not how SI is then trained on them):
        every collection of a config is the first trajectories of a larger one (`collected_trajectories`)."""
        return (self.trajectory_steps, self.seed, self.low_level.key)

    @property
    def key(self) -> dict[str, Any]:
        """What the pretrained model depends on: every field, of the low level only what rollouts do."""
        return {**dataclasses.asdict(self), "low_level": self.low_level.key}


PAPER_A7 = PretrainData(n_trajectories=100, loss="brier")
"""Algorithm 4 as A.7 reads: 100 trajectories and the mean squared loss over SI's distribution (the study's
default before notebook 13)."""


class Trajectories(NamedTuple):
    """Algorithm 4's domain-randomised trajectories before they are cut into slices."""

    features: np.ndarray
    """(n, trajectory_steps, features per period): what SI sees of each control period."""
    parameters: np.ndarray
    """(n,): each trajectory's true parameter phi."""
    phase: np.ndarray
    """(n, trajectory_steps): how far into its rollout's clip each period is, in [0, 1)."""


def collect_trajectories(
    domain: str, n_trajectories: int, data: PretrainData, cache_dir: CacheDir = None
) -> Trajectories:
    """`n_trajectories` domain-randomised trajectories of `data.trajectory_steps` periods (Algorithm 4's D
    before slicing, with `data.seed`).

    Each trajectory has its parameter drawn uniformly from the range (A.7) and is made of rollouts of pi^l,
    each with its own uniformly random estimate, chained until `trajectory_steps` periods are collected:
    the estimate is what pi^l acts on, so a spread of estimates shows SI how each parameter looks through
    both good and bad control. The draws are sequential, so the first n trajectories of a larger collection
    are those of a collection of n. Where the layout sets a rollout's length (wiping) only the periods kept
    are simulated, bit for bit the whole rollout's. A learned pi^l is loaded from (or trained into)
    `cache_dir`.
    """
    spec = domain_spec(domain)
    task = make_task(domain, data.low_level, cache_dir)
    rng = np.random.default_rng(np.random.SeedSequence([data.seed, 4]))
    features, parameters, phases = [], [], []
    for _ in range(n_trajectories):
        phi = float(rng.uniform(spec.candidates.low, spec.candidates.high))
        periods: list[np.ndarray] = []
        phase: list[np.ndarray] = []
        while (collected := sum(len(p) for p in periods)) < data.trajectory_steps:
            estimate, layout = random_estimate(task, rng), task.sample_layout(rng)
            planned = task.planned_periods(layout)
            kept = None if planned is None else min(planned, data.trajectory_steps - collected)
            periods.append(task.rollout(phi, estimate, layout, periods=kept).features)
            length = len(periods[-1]) if planned is None else planned
            phase.append(np.arange(len(periods[-1])) / length)
        features.append(np.concatenate(periods)[: data.trajectory_steps])
        phases.append(np.concatenate(phase)[: data.trajectory_steps])
        parameters.append(phi)
    return Trajectories(np.stack(features), np.asarray(parameters), np.stack(phases))


def cut_slices(
    trajectories: Trajectories, history: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every h-period slice of every trajectory (Algorithm 4's D): (features (m, h * features per period) in
    time order, parameters (m,), trajectory index (m,), phase of the slice's first period (m,))."""
    n, steps, width = trajectories.features.shape
    check_int("history", history, 1, steps)
    # sliding_window_view puts the window last: (n, m, 21, h) -> (n, m, h, 21), flattened in time order.
    windows = np.lib.stride_tricks.sliding_window_view(trajectories.features, history, axis=1)
    per_trajectory = windows.shape[1]
    features = windows.transpose(0, 1, 3, 2).reshape(n * per_trajectory, history * width)
    index = np.repeat(np.arange(n), per_trajectory)
    phase = trajectories.phase[:, :per_trajectory].reshape(-1)
    return features, trajectories.parameters[index], index, phase


def collected_trajectories(
    domain: str, n_trajectories: int, data: PretrainData, cache_dir: CacheDir = None
) -> Trajectories:
    """`collect_trajectories`, collected once per (domain, number, `data.collection`) and cached in
    `cache_dir` (None: the running sweep's, else the default directory): OSI's pretraining and notebook 13's
    measurements read the same collection."""
    return cached_artefact(
        f"si_trajectories_{domain}",
        (n_trajectories, data.collection),
        lambda: collect_trajectories(domain, n_trajectories, data, cache_dir),
        cache_dir=cache_dir,
        expect=Expect(
            Trajectories,
            lambda t: (
                t.features.shape[:2] == (n_trajectories, data.trajectory_steps)
                and t.parameters.shape == (n_trajectories,)
            ),
        ),
    )


def collect_dataset(
    domain: str, data: PretrainData, cache_dir: CacheDir = None
) -> tuple[np.ndarray, np.ndarray]:
    """Algorithm 4's D: every h-period slice of `data.n_trajectories` trajectories (`collected_trajectories`).
    Returns (features (n, h * features per period), parameters (n,))."""
    features, parameters, _, _ = cut_slices(
        collected_trajectories(domain, data.n_trajectories, data, cache_dir), data.history
    )
    return features, parameters


def fit_si(domain: str, features: np.ndarray, parameters: np.ndarray, data: PretrainData) -> SIModel:
    """A fresh SI pretrained by Algorithm 4 on (features, parameters) as `data` says (single-threaded)."""
    with one_thread():
        model = SIModel(features.shape[1], domain_spec(domain).candidates, data.hidden_sizes, seed=data.seed)
        pretrain(
            model,
            features,
            parameters,
            PretrainConfig(data.learning_rate, n_steps=data.pretrain_steps, loss=data.loss),
            data.seed,
        )
    return model


def pretrained_model(domain: str, data: PretrainData, cache_dir: CacheDir = None) -> SIModel:
    """The OSI model: SI pretrained by Algorithm 4 on `collect_dataset`, built once per config and cached in
    `cache_dir` (None: the running sweep's, else the default directory), with its dataset."""

    def build() -> SIModel:
        return fit_si(domain, *collect_dataset(domain, data, cache_dir), data)

    return cached_artefact(f"si_osi_{domain}", (domain, data.key), build, cache_dir=cache_dir, expect=SIModel)


@dataclass(frozen=True)
class PretrainCell:
    """Algorithm 4 for one domain as a sweep cell, so that the domains' models are built side by side."""

    domain: str
    """'wiping' or 'pushing'."""
    data: PretrainData
    """The dataset and pretraining of the model."""


def pretrain_cell(cell: PretrainCell) -> pd.DataFrame:
    """Build and cache `cell.domain`'s OSI model (`pretrained_model`); no rows: the model is the product."""
    pretrained_model(cell.domain, cell.data)
    return tidy_rows([], domain=cell.domain, method="osi", noise=0.0, seed=cell.data.seed)


def pretrain_models(cells: Iterable[PretrainCell], cache_dir: CacheDir = None, **sweep: Any) -> None:
    """Build the OSI model of every cell before a study's runs, side by side (a sweep of `pretrain_cell`,
    `sweep` its options), cached in `cache_dir` (None: the default directory): the study's workers then
    load them, not race to build them. Without a cache each process builds its own, so nothing is built
    here."""
    if cache_dir is NO_CACHE:
        return
    run_sweep(pretrain_cell, list(dict.fromkeys(cells)), cache_dir=cache_dir, desc="Algorithm 4", **sweep)

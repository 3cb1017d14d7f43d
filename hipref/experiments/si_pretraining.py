"""Algorithm 4 (A.4): SI pretrained once per domain on trajectories collected under domain randomisation.
The pretrained model, never updated, is OSI; every fine-tuning run starts from a copy of it."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pandas as pd

from hipref.envs.task import random_estimate
from hipref.experiments.domains import domain_spec
from hipref.experiments.low_level import LowLevel, make_task
from hipref.learners.sysid import PRETRAIN_LOSSES, PretrainConfig, SIModel, pretrain
from hipref.numerics import one_thread
from hipref.results import tidy_rows
from hipref.sweep import NO_CACHE, CacheDir, Expect, cached_artefact, run_sweep
from hipref.validation import check_choice, check_int, check_range


@dataclass(frozen=True)
class PretrainData:
    """Algorithm 4's dataset D and the pretraining of SI (A.4, A.7)."""

    n_trajectories: int = 100
    """Domain-randomised trajectories in D (A.7: 100)."""
    trajectory_steps: int = 100
    """Control periods per trajectory (A.7: 100 states and actions)."""
    history: int = 3
    """h, control periods per SI input slice (Table 2: 3)."""
    pretrain_steps: int = 3000
    """Adam steps of Algorithm 4 (its loop has no stated end)."""
    learning_rate: float = 1e-3
    """Adam step size of Algorithm 4 (Table 2: 1e-3)."""
    loss: str = "brier"
    """What Algorithm 4's mean squared loss is taken over: 'brier' (SI's distribution against the target
    distribution), 'expectation' (its mean only) or 'brier_expectation' (`hipref.learners.sysid.pretrain`)."""
    seed: int = 0
    """Seed of the collection and of the pretraining: one pretrained model per domain, shared by all runs."""
    low_level: LowLevel = field(default_factory=LowLevel)
    """The pi^l whose rollouts make D, and which every run that starts from this model executes."""

    def __post_init__(self) -> None:
        check_choice("loss", self.loss, PRETRAIN_LOSSES)
        check_int("n_trajectories", self.n_trajectories, 2)
        check_int("trajectory_steps", self.trajectory_steps, self.history if self.history >= 1 else 1)
        check_int("history", self.history, 1)
        check_int("pretrain_steps", self.pretrain_steps, 0)
        check_range("learning_rate", self.learning_rate, 1e-8, 1.0)
        check_int("seed", self.seed, 0)

    @property
    def collection(self) -> tuple[Any, ...]:
        """What the dataset D depends on (not how SI is then trained on it), so pretraining variants share
        one collection."""
        return (self.n_trajectories, self.trajectory_steps, self.history, self.seed, self.low_level.key)

    @property
    def key(self) -> dict[str, Any]:
        """What the pretrained model depends on: every field, of the low level only what rollouts do."""
        return {**dataclasses.asdict(self), "low_level": self.low_level.key}


def collect_dataset(
    domain: str, data: PretrainData, cache_dir: CacheDir = None
) -> tuple[np.ndarray, np.ndarray]:
    """Algorithm 4's D: every h-period slice of `n_trajectories` domain-randomised trajectories.

    Each trajectory has its parameter drawn uniformly from the range (A.7) and is made of rollouts of pi^l,
    each with its own uniformly random estimate, chained until `trajectory_steps` periods are collected:
    the estimate is what pi^l acts on, so a spread of estimates shows SI how each parameter looks through
    both good and bad control. A learned pi^l is loaded from (or trained into) `cache_dir`. Returns (features
    (n, h * features per period), parameters (n,)).
    """
    spec = domain_spec(domain)
    task = make_task(domain, data.low_level, cache_dir)
    rng = np.random.default_rng(np.random.SeedSequence([data.seed, 4]))
    features, parameters = [], []
    for _ in range(data.n_trajectories):
        phi = float(rng.uniform(spec.candidates.low, spec.candidates.high))
        periods: list[np.ndarray] = []
        while sum(len(p) for p in periods) < data.trajectory_steps:
            periods.append(task.rollout(phi, random_estimate(task, rng), task.sample_layout(rng)).features)
        trajectory = np.concatenate(periods)[: data.trajectory_steps]
        windows = np.lib.stride_tricks.sliding_window_view(trajectory, data.history, axis=0)
        # sliding_window_view puts the window last: (n, 21, h) -> (n, h, 21), flattened in time order.
        features.append(windows.transpose(0, 2, 1).reshape(len(windows), -1))
        parameters.append(np.full(len(windows), phi))
    return np.concatenate(features), np.concatenate(parameters)


def pretrained_model(domain: str, data: PretrainData, cache_dir: CacheDir = None) -> SIModel:
    """The OSI model: SI pretrained by Algorithm 4 on `collect_dataset`, built once per config and cached in
    `cache_dir` (None: the running sweep's, else the default directory), with its dataset."""
    spec = domain_spec(domain)

    def build() -> SIModel:
        features, parameters = cached_artefact(
            f"si_dataset_{domain}",
            data.collection,
            lambda: collect_dataset(domain, data, cache_dir),
            cache_dir=cache_dir,
            expect=Expect(
                tuple,
                lambda d: d[0].ndim == 2 and d[0].shape[1] % data.history == 0 and d[1].shape == (len(d[0]),),
            ),
        )
        with one_thread():
            model = SIModel(features.shape[1], spec.candidates, seed=data.seed)
            pretrain(
                model,
                features,
                parameters,
                PretrainConfig(data.learning_rate, n_steps=data.pretrain_steps, loss=data.loss),
                data.seed,
            )
        return model

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

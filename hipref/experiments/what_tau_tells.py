"""How much does a slice tau tell about the parameter? Strong regressors on Algorithm 4's slices (nb. 13).

For each domain, gradient-boosted trees and k-nearest neighbours are fitted on the slices Algorithm 4
collects (`hipref.experiments.si_pretraining.collected_trajectories`, `cut_slices`) and scored on held-out
environments: trajectories of a separate collection (`test_seed`), whose parameters no training slice has.
One factor changes at a time from the base (h = 3, slices cut anywhere in the clip, every column, the largest
data size): the slice length h, where in the clip the slice is cut, which columns of tau are kept, and the
number of pretraining trajectories (the first n of one collection, so the sizes are nested). Beside them, SI
itself (OSI) in several readings of Algorithm 4 (`OSI_READINGS`), scored on the same held-out slices for its
error and for the calibration of Pr(phi | tau) (PIT, `hipref.learners.calibration`), and the constant guess.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Annotated, Any

import numpy as np
import pandas as pd
import torch
from sklearn.ensemble import HistGradientBoostingRegressor
from sklearn.neighbors import KNeighborsRegressor
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler
from threadpoolctl import threadpool_limits

from hipref.control.tool import FEATURES_PER_PERIOD
from hipref.experiments.constant_guess import CONSTANT_BEST, CONSTANT_MIDDLE, best_constant, range_middle
from hipref.experiments.domains import DOMAINS, domain_spec
from hipref.experiments.si_pretraining import (
    PAPER_A7,
    PretrainData,
    Trajectories,
    collected_trajectories,
    cut_slices,
    pretrained_model,
)
from hipref.learners.calibration import pit
from hipref.results import tidy_rows
from hipref.sweep import run_sweep
from hipref.validation import Integer, NonEmptyTuple, OneOf, check_choice, check_fields

COLUMN_GROUPS: dict[str, tuple[int, int]] = {
    "joint_positions": (0, 6),
    "joint_velocities": (6, 12),
    "wrist_force": (12, 15),
    "joint_reference": (15, 21),
}
"""The columns of one period's features (`hipref.control.tool.FEATURES_PER_PERIOD`), by what they hold."""

COLUMN_SETS: dict[str, tuple[str, ...]] = {
    "all": tuple(COLUMN_GROUPS),
    "joint_states": ("joint_positions", "joint_velocities"),
    "actions": ("joint_reference",),
    "wrist_force": ("wrist_force",),
    "without_wrist_force": ("joint_positions", "joint_velocities", "joint_reference"),
}
"""Which column groups of tau a regressor is given: the arm's state, the action (the joint reference
pi^l commands), the wrist force/torque sensor's force."""

CUTS: dict[str, tuple[float, float]] = {
    "anywhere": (0.0, 1.0),
    "first_quarter": (0.0, 0.25),
    "second_quarter": (0.25, 0.5),
    "third_quarter": (0.5, 0.75),
    "last_quarter": (0.75, 1.0),
}
"""Where in its clip a slice starts, as a fraction of the clip's length (Algorithm 4 cuts anywhere)."""

REGRESSORS: tuple[str, ...] = ("gbt", "knn")
"""'gbt': histogram gradient-boosted trees; 'knn': k-nearest neighbours on standardised columns."""

OSI_READINGS: tuple[str, ...] = ("paper_a7", "nll", "nll_more_data")
"""SI pretrained by Algorithm 4 as A.7 says (`PAPER_A7`: Brier on the distribution, 100 trajectories,
Table 2's network), with the negative log-likelihood instead, and with it on the largest data size collected
(the study's OSI, `PretrainData()`, when that is its 3,000)."""

BASE_HISTORY = 3
"""h of the base setting (Table 2: 3), the one OSI reads."""


def osi_reading(name: str, n_largest: int, pretrain_steps: int) -> PretrainData:
    """The Algorithm 4 configuration of an OSI reading (`OSI_READINGS`)."""
    check_choice("name", name, OSI_READINGS)
    paper = dataclasses.replace(PAPER_A7, pretrain_steps=pretrain_steps)
    if name == "paper_a7":
        return paper
    if name == "nll":
        return dataclasses.replace(paper, loss="nll")
    return dataclasses.replace(paper, loss="nll", n_trajectories=n_largest)


@dataclass(frozen=True)
class TauConfig:
    """The measurements of notebook 13."""

    domains: NonEmptyTuple[Annotated[str, OneOf(DOMAINS)]] = ("wiping", "pushing")
    """Domains to measure."""
    n_trajectories: NonEmptyTuple[Annotated[int, Integer(2, 100_000)]] = (30, 100)
    """Pretraining data sizes compared, in trajectories of 100 periods (100, 300, 1000, 3000 in the full
    profile); at least 100 are collected, so that the paper's OSI (A.7: 100) can be pretrained."""
    base_trajectories: Annotated[int, Integer(2, 100_000)] = 100
    """The data size of the other factors' settings (h, cut, columns) and of the OSI readings' base."""
    test_trajectories: Annotated[int, Integer(2, 10_000)] = 20
    """Held-out environments: trajectories of the `test_seed` collection, each with its own parameter."""
    test_slices: Annotated[int, Integer(1, 90)] = 10
    """Slices scored per held-out environment, drawn among those the setting allows."""
    slice_stride: Annotated[int, Integer(1, 50)] = 5
    """A training slice starts every `slice_stride` periods (neighbouring slices share h - 1 periods)."""
    histories: NonEmptyTuple[Annotated[int, Integer(1, 50)]] = (1, 3)
    """Slice lengths h compared."""
    cuts: tuple[Annotated[str, OneOf(CUTS)], ...] = ("anywhere", "first_quarter", "last_quarter")
    """Where the slice is cut, keys of CUTS."""
    column_sets: tuple[Annotated[str, OneOf(COLUMN_SETS)], ...] = (
        "all",
        "without_wrist_force",
        "wrist_force",
    )
    """Which columns are kept, keys of COLUMN_SETS."""
    regressors: tuple[Annotated[str, OneOf(REGRESSORS)], ...] = REGRESSORS
    """Regressors fitted, of REGRESSORS."""
    osi_readings: tuple[Annotated[str, OneOf(OSI_READINGS)], ...] = OSI_READINGS
    """SI readings scored, of OSI_READINGS."""
    pretrain_steps: Annotated[int, Integer(0)] = 300
    """Adam steps of every OSI reading (the study's Algorithm 4 default: 3000)."""
    seed: Annotated[int, Integer(0)] = 0
    """Seed of the training collection (0: Algorithm 4's own, so the first 100 trajectories are OSI's D)."""
    test_seed: Annotated[int, Integer(0)] = 1
    """Seed of the held-out collection, different from `seed`."""

    def __post_init__(self) -> None:
        check_fields(self)
        if BASE_HISTORY not in self.histories:
            raise ValueError(f"histories must include OSI's h = {BASE_HISTORY}, got {self.histories!r}")
        if self.test_seed == self.seed:
            raise ValueError(
                f"test_seed must differ from seed={self.seed} (held-out environments), got it equal"
            )


def columns_of(column_set: str, history: int) -> np.ndarray:
    """Indices into a flattened slice of `history` periods of the column groups of `column_set`."""
    check_choice("column_set", column_set, tuple(COLUMN_SETS))
    per_period = np.concatenate([np.arange(*COLUMN_GROUPS[g]) for g in COLUMN_SETS[column_set]])
    return np.concatenate([per_period + k * FEATURES_PER_PERIOD for k in range(history)])


def make_regressor(name: str, seed: int) -> Any:
    """A fresh regressor of REGRESSORS."""
    check_choice("name", name, REGRESSORS)
    if name == "gbt":
        return HistGradientBoostingRegressor(max_iter=300, random_state=seed)
    return make_pipeline(StandardScaler(), KNeighborsRegressor(n_neighbors=10))


def select_slices(
    trajectories: Trajectories, history: int, cut: str, per_trajectory: int | None, stride: int, seed: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Slices of h periods starting inside `cut`: every `stride`-th of each trajectory, or (`per_trajectory`)
    that many drawn at random from each. Returns (features, parameters, trajectory index)."""
    features, parameters, index, phase = cut_slices(trajectories, history)
    low, high = CUTS[cut]
    start = np.tile(np.arange(len(index) // len(trajectories.parameters)), len(trajectories.parameters))
    allowed = (phase >= low) & (phase < high)
    if per_trajectory is None:
        keep = np.flatnonzero(allowed & (start % stride == 0))
    else:
        rng = np.random.default_rng(seed)
        keep = np.concatenate(
            [
                rng.choice(rows, size=min(per_trajectory, len(rows)), replace=False)
                for rows in (
                    np.flatnonzero(allowed & (index == t)) for t in range(len(trajectories.parameters))
                )
                if len(rows)
            ]
        )
    return features[keep], parameters[keep], index[keep]


def regressor_estimates(
    name: str,
    train: tuple[np.ndarray, np.ndarray],
    test_features: np.ndarray,
    low: float,
    high: float,
    seed: int,
) -> np.ndarray:
    """A regressor of REGRESSORS fitted on (features, parameters), its estimates on `test_features` clipped
    to the range [low, high] (single-threaded)."""
    regressor = make_regressor(name, seed)
    # One thread, as every run of the study: OpenMP's default team fights the sweep's other process.
    with threadpool_limits(1):
        regressor.fit(*train)
        return np.clip(regressor.predict(test_features), low, high)


def _environment_rows(
    estimates: np.ndarray, truths: np.ndarray, index: np.ndarray
) -> list[tuple[float, str, float]]:
    """Per held-out environment: its |error| averaged over its slices and its mean estimate."""
    rows = []
    for t in np.unique(index):
        mine = index == t
        rows.append(
            (float(truths[mine][0]), "param_error", float(np.mean(np.abs(estimates[mine] - truths[mine]))))
        )
        rows.append((float(truths[mine][0]), "estimate", float(np.mean(estimates[mine]))))
    return rows


def _frame(
    rows: list[tuple[float, str, float]], domain: str, method: str, factor: str, level: str, seed: int
) -> pd.DataFrame:
    """Tidy rows of (true parameter, metric, value) triples of one method in one setting."""
    return tidy_rows(
        rows,
        ("ground_truth", "metric", "value"),
        domain=domain,
        method=method,
        noise=0.0,
        seed=seed,
        episode=0,
        factor=factor,
        level=level,
    )


def measure_domain(domain: str, config: TauConfig) -> pd.DataFrame:
    """Every setting of `config` for one domain: regressors, OSI readings and the constant guess."""
    spec = domain_spec(domain)
    low, high = spec.candidates.low, spec.candidates.high
    n_largest = max(*config.n_trajectories, config.base_trajectories, PAPER_A7.n_trajectories)
    n_base = config.base_trajectories
    data = PretrainData(seed=config.seed)
    train_all = collected_trajectories(domain, n_largest, data)
    test = collected_trajectories(
        domain, config.test_trajectories, dataclasses.replace(data, seed=config.test_seed)
    )

    def first(n: int) -> Trajectories:
        return Trajectories(*(part[:n] for part in train_all))

    settings = {
        ("n_trajectories", str(n)): (n, BASE_HISTORY, "anywhere", "all") for n in config.n_trajectories
    }
    settings |= {("history", str(h)): (n_base, h, "anywhere", "all") for h in config.histories}
    settings |= {("cut", cut): (n_base, BASE_HISTORY, cut, "all") for cut in config.cuts}
    settings |= {("columns", c): (n_base, BASE_HISTORY, "anywhere", c) for c in config.column_sets}
    base = (n_base, BASE_HISTORY, "anywhere", "all")
    estimates_of: dict[tuple[int, int, str, str], list[tuple[str, list[tuple[float, str, float]]]]] = {}
    frames = []
    for (factor, level), setting in settings.items():
        if setting not in estimates_of:  # the base setting recurs in every factor: fitted once
            n, history, cut, column_set = setting
            columns = columns_of(column_set, history)
            features, parameters, _ = select_slices(
                first(n), history, cut, None, config.slice_stride, config.seed
            )
            test_features, truths, index = select_slices(
                test, history, cut, config.test_slices, 1, config.test_seed
            )
            estimates_of[setting] = [
                (
                    name,
                    _environment_rows(
                        regressor_estimates(
                            name,
                            (features[:, columns], parameters),
                            test_features[:, columns],
                            low,
                            high,
                            config.seed,
                        ),
                        truths,
                        index,
                    ),
                )
                for name in config.regressors
            ]
            if setting == base:
                frames += _osi_and_constants(domain, config, (test_features, truths, index), n_largest)
        frames += [
            _frame(rows, domain, name, factor, level, config.seed) for name, rows in estimates_of[setting]
        ]
    return pd.concat(frames, ignore_index=True)


def _osi_and_constants(
    domain: str, config: TauConfig, test: tuple[np.ndarray, np.ndarray, np.ndarray], n_largest: int
) -> list[pd.DataFrame]:
    """OSI readings (error, estimates, PIT of every held-out slice) and the constant guesses on the base
    setting's held-out slices. Each reading's model is the study's cached one where the study pretrains the
    same (the largest reading is notebook 02's OSI at the full profile)."""
    test_features, truths, index = test
    spec = domain_spec(domain)
    frames = []
    for reading in config.osi_readings:
        data = dataclasses.replace(osi_reading(reading, n_largest, config.pretrain_steps), seed=config.seed)
        model = pretrained_model(domain, data)
        with torch.no_grad():
            probabilities = (
                model.distribution(torch.as_tensor(test_features, dtype=torch.float32)).double().numpy()
            )
        estimates = np.clip(probabilities @ spec.candidates.values, spec.candidates.low, spec.candidates.high)
        rows = _environment_rows(estimates, truths, index)
        pits = pit(probabilities / probabilities.sum(axis=1, keepdims=True), spec.candidates, truths)
        rows += [(float(t), "pit", float(u)) for t, u in zip(truths, pits, strict=True)]
        frames.append(_frame(rows, domain, f"osi_{reading}", "osi", reading, config.seed))
    for method, constant in (
        (CONSTANT_MIDDLE, range_middle(domain)),
        (CONSTANT_BEST, best_constant(np.unique(truths))),
    ):
        estimates = np.full(len(truths), constant)
        frames.append(
            _frame(
                _environment_rows(estimates, truths, index), domain, method, "constant", method, config.seed
            )
        )
    return frames


@dataclass(frozen=True)
class TauCell:
    """One domain's measurements as a sweep cell."""

    domain: str
    """'wiping' or 'pushing'."""
    config: TauConfig
    """The measurements."""


def measure_cell(cell: TauCell) -> pd.DataFrame:
    """`measure_domain` of one cell."""
    return measure_domain(cell.domain, cell.config)


def run(config: TauConfig) -> pd.DataFrame:
    """Every domain's measurements, the domains side by side."""
    return run_sweep(
        measure_cell, [TauCell(domain, config) for domain in config.domains], desc="what tau tells"
    )

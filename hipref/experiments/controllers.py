"""The controllers study (notebook 05): paper A.8 / Fig. 7, and how much the unknown parameter matters.

1. Controller ablation: desk at 0.81 m, the wiping policy given desired heights 0.72-0.80 m, the same
   start and the same random trajectory on the desk for plain SPD and for admittance + SPD; the z-axis
   wrist force's mean and standard deviation (`force_mean`, `force_std`).
2. Success against estimate error: each task executed with the estimate off the true parameter by an
   error; the fraction of successes at each error (`success_rate`) is what gives the SI studies their
   meaning. The estimate is never clipped to the parameter's range: the true parameter is drawn only from
   the part of its range where the estimate stays inside, so the error on the x axis is the real error.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any

import numpy as np
import pandas as pd

from hipref.envs.wiping import WipingTask
from hipref.experiments.domains import DOMAINS, domain_spec, estimate_error_grids
from hipref.results import tidy_rows
from hipref.seeds import child_seeds
from hipref.sweep import run_sweep
from hipref.validation import Integer, OneOf, Range, check_fields, check_range

COMPLIANT: dict[str, bool] = {"spd": False, "admittance": True}
"""The ablation's controllers by name, and whether each puts admittance control on SPD (A.8)."""

CLAIM_ERRORS: dict[str, str] = {"wiping": "claim_height_error", "pushing": "claim_mass_error"}
"""The field of `ControllersConfig` holding each domain's claimed error (its notebook parameter)."""


@dataclass(frozen=True)
class ControllersConfig:
    """Parameters of notebook 05 (defaults: the quick profile; the paper's values where it gives them)."""

    desk_height: Annotated[float, Range(0.5, 0.9)] = 0.81
    """True desk height of the ablation in m (A.8)."""
    desired_heights: tuple[Annotated[float, Range(0.5, 0.9)], ...] = (0.72, 0.74, 0.76, 0.78, 0.80)
    """Desk heights the controllers are told, in m (A.8)."""
    trajectory_goals: Annotated[int, Integer(1, 100)] = 6
    """Random goals on the desk that make up the ablation's shared trajectory."""
    ablation_seeds: Annotated[int, Integer(1, 1000)] = 3
    """Random trajectories per desired height and controller."""
    height_errors: tuple[float, ...] = tuple(np.round(np.arange(-0.06, 0.0601, 0.01), 2))
    """Errors of the desk-height estimate in m for the success curve."""
    mass_errors: tuple[float, ...] = tuple(float(e) for e in range(-6, 7))
    """Errors of the cube-mass estimate in kg for the success curve."""
    curve_seeds: Annotated[int, Integer(1, 10000)] = 10
    """Random episodes (parameter, start and goal) per estimate error."""
    seed: Annotated[int, Integer(0)] = 0
    """Root seed; every episode's seed derives from it."""
    claim_height_error: float = 0.05
    """Height error in m at which the wiping task should mostly fail (claim: success at most 0.3 at
    +- this error, at least 0.9 at 0); 0 and +- it must be in `height_errors`."""
    claim_mass_error: float = 4.0
    """Mass error in kg at which the pushing task should mostly fail (the same claim); 0 and +- it must be
    in `mass_errors`."""

    def __post_init__(self) -> None:
        check_fields(self)
        claims = self.claim_errors()
        for domain, errors in estimate_error_grids(self).items():
            name, candidates = DOMAINS[domain].estimate_errors, DOMAINS[domain].candidates
            claim_name, claim = CLAIM_ERRORS[domain], claims[domain]
            # At most half the range, so that the true parameters of every error (drawn where the
            # estimate stays in the range) still cover half of it.
            bound = (candidates.high - candidates.low) / 2
            for e in errors:
                check_range(name, e, -bound, bound)
            check_range(claim_name, claim, 1e-9, bound)
            needed = (0.0, -claim, claim)
            if not set(needed) <= set(errors):
                raise ValueError(
                    f"{name} must contain {needed} (the claim compares success at the true parameter with "
                    f"success at +-{claim_name}), got {tuple(errors)!r}"
                )

    def claim_errors(self) -> dict[str, float]:
        """Each domain's error at which its task should mostly fail (`CLAIM_ERRORS`)."""
        return {domain: getattr(self, name) for domain, name in CLAIM_ERRORS.items()}


@dataclass(frozen=True)
class AblationCell:
    """One controller following one random trajectory under one desired height."""

    method: Annotated[str, OneOf(COMPLIANT)]
    desk_height: Annotated[float, Range(0.5, 0.9)]
    desired_height: Annotated[float, Range(0.5, 0.9)]
    trajectory_goals: Annotated[int, Integer(1, 100)]
    seed: Annotated[int, Integer(0)]

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class CurveCell:
    """One episode of one task executed with an estimate `error` off the true parameter."""

    domain: str
    error: float
    seed: Annotated[int, Integer(0)]

    def __post_init__(self) -> None:
        check_fields(self)
        phi = domain_spec(self.domain).candidates
        # Beyond the range's width no true parameter leaves the estimate inside the range.
        check_range("error", self.error, phi.low - phi.high, phi.high - phi.low)


def _rows(domain: str, method: str, seed: int, metrics: dict[str, float], **extra: float) -> pd.DataFrame:
    return tidy_rows(
        [(name, float(value)) for name, value in metrics.items()],
        ("metric", "value"),
        domain=domain,
        method=method,
        noise=0.0,
        seed=seed,
        episode=0,
        **extra,
    )


def run_ablation_cell(cell: AblationCell) -> pd.DataFrame:
    """Follow the cell's random trajectory; the z force over every stroke (A.8, Fig. 7)."""
    task = WipingTask(compliant=COMPLIANT[cell.method])
    goals = task.area_points(np.random.default_rng(cell.seed), cell.trajectory_goals)
    task.reset(cell.desk_height, (0.0, 0.05))
    forces = np.concatenate([task.stroke(goal, cell.desired_height).force for goal in goals])
    return _rows(
        "wiping",
        cell.method,
        cell.seed,
        {"force_mean": forces.mean(), "force_std": forces.std()},
        desired_height=cell.desired_height,
    )


def truth_and_estimate(
    rng: np.random.Generator, error: float, low: float, high: float
) -> tuple[float, float]:
    """A true parameter uniform over the part of [low, high] where truth + error stays inside, and that
    estimate. Clipping the estimate instead would make the real error smaller than the one plotted."""
    truth = rng.uniform(max(low, low - error), min(high, high - error))
    # min/max only undo rounding: truth + error lies in [low, high] by the choice of the truth's range.
    return truth, min(max(truth + error, low), high)


def run_curve_cell(cell: CurveCell) -> pd.DataFrame:
    """One episode whose estimate is off the true parameter by exactly `cell.error` (see
    `truth_and_estimate`: the truth is drawn only where that estimate is inside the range)."""
    rng = np.random.default_rng(cell.seed)
    task = domain_spec(cell.domain).make_task()
    truth, estimate = truth_and_estimate(rng, cell.error, *task.parameter_range)
    success = task.rollout(truth, estimate, task.sample_layout(rng)).success
    return _rows(cell.domain, "admittance", cell.seed, {"success_rate": success}, estimate_error=cell.error)


def run_ablation(config: ControllersConfig, **sweep: Any) -> pd.DataFrame:
    """Fig. 7: both controllers at every desired height, on `ablation_seeds` random trajectories."""
    seeds = child_seeds([config.seed, 5], config.ablation_seeds)
    cells = [
        AblationCell(method, config.desk_height, h, config.trajectory_goals, seed)
        for method in COMPLIANT
        for h in config.desired_heights
        for seed in seeds
    ]
    return run_sweep(run_ablation_cell, cells, desc="Fig. 7 ablation", **sweep)


def run_curves(config: ControllersConfig, **sweep: Any) -> pd.DataFrame:
    """Success against estimate error in both tasks, `curve_seeds` random episodes per error."""
    cells = [
        CurveCell(domain, float(error), seed)
        for label, (domain, errors) in enumerate(estimate_error_grids(config).items(), start=1)
        for error in errors
        for seed in child_seeds([config.seed, label], config.curve_seeds)
    ]
    return run_sweep(run_curve_cell, cells, desc="success vs estimate error", **sweep)


def run(config: ControllersConfig, **sweep: Any) -> pd.DataFrame:
    """Both parts of the study, as one tidy frame (the ablation's rows, then the curves')."""
    return pd.concat([run_ablation(config, **sweep), run_curves(config, **sweep)], ignore_index=True)

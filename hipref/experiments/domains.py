"""The two domains of the study: each one's unknown parameter, SI's candidates for it, its batch sizes
(Table 2), its task (`hipref.envs.task.Task`) and the fields of a study's config that hold its truths and
estimate errors, looked up here once (`truth_grids`, `estimate_error_grids`) so that a study holds
per-domain maps."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from hipref.envs.pushing import PushingTask
from hipref.envs.task import Task
from hipref.envs.wiping import WipingTask
from hipref.learners.sysid import CUBE_MASS, DESK_HEIGHT, CandidateSet
from hipref.validation import check_choice


@dataclass(frozen=True)
class DomainSpec:
    """What a domain contributes to system identification (Table 2)."""

    name: str
    """'wiping' or 'pushing'."""
    parameter: str
    """The unknown parameter phi, for axis labels."""
    unit: str
    """Its unit."""
    candidates: CandidateSet
    """Phi, the candidate set over the randomisation range."""
    batch_size: int
    """Preferences per SI update (Table 2: 16 for height, 32 for mass)."""
    refresh_frequency: int
    """f_refresh of the co-teaching classifiers (Table 2: 16 for height, 32 for mass)."""
    make_task: Callable[..., Task]
    """The domain's task, with its physics built afresh (its analytic pi^l unless given `low_level=`, a
    learned one: `hipref.experiments.low_level.make_task`)."""
    truths: str
    """The field of a study's config (and the notebooks' parameter) holding the domain's true parameters."""
    estimate_errors: str
    """The field holding the errors of the estimate a study executes the domain's task with."""
    outcome_metric: str
    """The metric of an episode (`Task.episode_metrics`) a study shows beside its success: wiping's
    contact force, pushing's distance of the cube to its goal."""


DOMAINS: dict[str, DomainSpec] = {
    "wiping": DomainSpec(
        "wiping",
        "desk height",
        "m",
        DESK_HEIGHT,
        16,
        16,
        WipingTask,
        truths="heights",
        estimate_errors="height_errors",
        outcome_metric="force_mean",
    ),
    "pushing": DomainSpec(
        "pushing",
        "cube mass",
        "kg",
        CUBE_MASS,
        32,
        32,
        PushingTask,
        truths="masses",
        estimate_errors="mass_errors",
        outcome_metric="goal_distance",
    ),
}


def domain_spec(domain: str) -> DomainSpec:
    """The spec of `domain`; ValueError naming the allowed domains otherwise."""
    check_choice("domain", domain, tuple(DOMAINS))
    return DOMAINS[domain]


def truth_grids(config: Any) -> dict[str, Any]:
    """Each domain's true parameters, read from `config`'s field of them (`DomainSpec.truths`)."""
    return {name: getattr(config, spec.truths) for name, spec in DOMAINS.items()}


def estimate_error_grids(config: Any) -> dict[str, Any]:
    """Each domain's estimate errors, read from `config`'s field of them (`DomainSpec.estimate_errors`)."""
    return {name: getattr(config, spec.estimate_errors) for name, spec in DOMAINS.items()}

"""The two domains of the study: each one's unknown parameter, SI's candidates for it, its batch sizes
(Table 2) and its task (`hipref.envs.task.Task`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

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


DOMAINS: dict[str, DomainSpec] = {
    "wiping": DomainSpec("wiping", "desk height", "m", DESK_HEIGHT, 16, 16, WipingTask),
    "pushing": DomainSpec("pushing", "cube mass", "kg", CUBE_MASS, 32, 32, PushingTask),
}


def domain_spec(domain: str) -> DomainSpec:
    """The spec of `domain`; ValueError naming the allowed domains otherwise."""
    check_choice("domain", domain, tuple(DOMAINS))
    return DOMAINS[domain]

"""Which low-level policy pi^l a study's tasks execute (A.3): the analytic admittance-on-SPD stack, or the
goal-conditioned network Algorithm 3 learns from it (`hipref.learners.imitation`), trained once per domain
and config and cached, so that every run, notebook and worker of a profile shares one."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from hipref.envs.low_level import LOW_LEVELS, STATE_SIZE, Perturb
from hipref.envs.task import Layout, Task
from hipref.experiments.domains import domain_spec
from hipref.learners.imitation import ImitationConfig, ImitationResult, learn_low_level_policy
from hipref.numerics import one_thread
from hipref.sweep import CacheDir, Expect, cached_artefact
from hipref.validation import check_choice


@dataclass(frozen=True)
class LowLevel:
    """The pi^l a task executes."""

    kind: str = "admittance"
    """'admittance' (the analytic stack of Fig. 6) or 'learned' (Algorithm 3's network)."""
    imitation: ImitationConfig = field(default_factory=ImitationConfig)
    """How the learned pi^l is trained (ignored for 'admittance')."""

    def __post_init__(self) -> None:
        check_choice("low_level", self.kind, LOW_LEVELS)
        if not isinstance(self.imitation, ImitationConfig):
            raise ValueError(f"imitation must be an ImitationConfig, got {self.imitation!r}")

    @property
    def key(self) -> tuple[Any, ...]:
        """What rollouts depend on: the kind, and for a learned pi^l how it was trained."""
        if self.kind == "admittance":
            return (self.kind,)
        return (self.kind, dataclasses.asdict(self.imitation))


def learned_policy(domain: str, imitation: ImitationConfig, cache_dir: CacheDir = None) -> ImitationResult:
    """Algorithm 3 in `domain`: pi^l learnt by imitation of the analytic stack, each trajectory's goal a
    random layout and its parameter uniform over the range; built once per config and cached in
    `cache_dir` (None: the running sweep's, else the default directory)."""
    spec = domain_spec(domain)

    def build() -> ImitationResult:
        expert = spec.make_task()
        low, high = expert.parameter_range

        def sample_goal_and_phi(rng: np.random.Generator) -> tuple[Layout, float]:
            return expert.sample_layout(rng), float(rng.uniform(low, high))

        def collect(layout: Layout, phi: float, perturb: Perturb) -> Any:
            return expert.demonstrate(phi, layout, perturb)

        with one_thread():
            return learn_low_level_policy(
                sample_goal_and_phi, collect, STATE_SIZE, expert.goal_size, expert.control_period, imitation
            )

    expect = Expect(ImitationResult, lambda r: r.losses.ndim == 1 and r.policy.state_size == STATE_SIZE)
    return cached_artefact(f"low_level_{domain}", imitation, build, cache_dir=cache_dir, expect=expect)


def make_task(domain: str, low_level: LowLevel = LowLevel(), cache_dir: CacheDir = None) -> Task:
    """`domain`'s task, its physics built afresh, executing `low_level`'s pi^l."""
    spec = domain_spec(domain)
    if low_level.kind == "admittance":
        return spec.make_task()
    return spec.make_task(low_level=learned_policy(domain, low_level.imitation, cache_dir).policy)

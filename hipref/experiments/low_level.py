"""Which low-level policy pi^l a study's tasks execute (A.3): the analytic admittance-on-SPD stack, or the
goal-conditioned network Algorithm 3 learns from it (`hipref.learners.imitation`): its demonstrations and the
trained network are cached, built once per domain and config and shared by every run, notebook and worker."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Annotated, Any

import numpy as np

from hipref.envs.low_level import LOW_LEVELS, STATE_SIZE, Demonstration, Perturb
from hipref.envs.task import Layout, Task
from hipref.experiments.domains import domain_spec
from hipref.learners.imitation import (
    ImitationConfig,
    ImitationResult,
    collect_demonstrations,
    estimate_around,
    learn_low_level_policy,
)
from hipref.numerics import one_thread
from hipref.sweep import CacheDir, Expect, cached_artefact, cached_prefix
from hipref.validation import OneOf, check_fields


@dataclass(frozen=True)
class LowLevel:
    """The pi^l a task executes."""

    kind: Annotated[str, OneOf(LOW_LEVELS)] = "admittance"
    """'admittance' (the analytic stack of Fig. 6) or 'learned' (Algorithm 3's network)."""
    imitation: ImitationConfig = field(default_factory=ImitationConfig)
    """How the learned pi^l is trained (ignored for 'admittance')."""

    def __post_init__(self) -> None:
        check_fields(self)
        if not isinstance(self.imitation, ImitationConfig):
            raise ValueError(f"imitation must be an ImitationConfig, got {self.imitation!r}")

    @property
    def key(self) -> tuple[Any, ...]:
        """What rollouts depend on: the kind, and for a learned pi^l how it was trained (not which of its
        snapshots were kept along the way)."""
        if self.kind == "admittance":
            return (self.kind,)
        return (self.kind, dataclasses.asdict(dataclasses.replace(self.imitation, snapshots=())))


@dataclass(frozen=True)
class DemonstrationSpec:
    """What Algorithm 3's demonstrations in a domain depend on: not the network or its updates, nor how many
    are collected (the i-th is the same in a short run and a long one)."""

    domain: str
    perturbation: float
    perturbation_time: float
    estimate_spread: float
    seed: int


def demonstrations(
    domain: str, imitation: ImitationConfig, cache_dir: CacheDir = None
) -> list[Demonstration]:
    """Algorithm 3's expert trajectories in `domain` (`collect_demonstrations`): each trajectory's goal a
    random layout and its true parameter phi* uniform over the range, executed by the analytic stack told
    an estimate phi around it (`estimate_around`, `ImitationConfig.estimate_spread`; phi* itself at 0) and
    labelled with phi; built once and cached in `cache_dir` (None: the running sweep's, else the default
    directory), a shorter study reading the start of a longer one's."""
    spec = DemonstrationSpec(
        domain, imitation.perturbation, imitation.perturbation_time, imitation.estimate_spread, imitation.seed
    )

    def build(count: int) -> list[Demonstration]:
        expert = domain_spec(domain).make_task()
        low, high = expert.parameter_range

        def sample_goal_and_phi(rng: np.random.Generator) -> tuple[tuple[Layout, float], float]:
            layout, truth = expert.sample_layout(rng), float(rng.uniform(low, high))
            return (layout, truth), estimate_around(rng, truth, low, high, imitation.estimate_spread)

        def collect(world: tuple[Layout, float], phi: float, perturb: Perturb) -> Demonstration:
            layout, truth = world
            return expert.demonstrate(truth, layout, perturb, estimate=phi)

        return collect_demonstrations(sample_goal_and_phi, collect, expert.control_period, imitation, count)

    return cached_prefix(
        f"imitation_data_{domain}",
        spec,
        imitation.iterations,
        build,
        check=lambda item: isinstance(item, Demonstration),
        cache_dir=cache_dir,
    )


def learned_policy(domain: str, imitation: ImitationConfig, cache_dir: CacheDir = None) -> ImitationResult:
    """Algorithm 3 in `domain`: pi^l learnt by imitation of the analytic stack on `demonstrations`; built
    once per config and cached in `cache_dir` (None: the running sweep's, else the default directory)."""

    def build() -> ImitationResult:
        data = demonstrations(domain, imitation, cache_dir)
        with one_thread():
            return learn_low_level_policy(data, STATE_SIZE, data[0].goals.shape[1], imitation)

    expect = Expect(
        ImitationResult,
        lambda r: (
            r.losses.ndim == 1
            and r.policy.state_size == STATE_SIZE
            and set(r.snapshots) == set(imitation.snapshots)
        ),
    )
    return cached_artefact(f"low_level_{domain}", imitation, build, cache_dir=cache_dir, expect=expect)


def make_task(
    domain: str, low_level: LowLevel = LowLevel(), cache_dir: CacheDir = None, snapshot: int | None = None
) -> Task:
    """`domain`'s task, its physics built afresh, executing `low_level`'s pi^l; for a learned one, the policy
    after `snapshot` of Algorithm 3's iterations (one of `ImitationConfig.snapshots`; None: the trained
    one)."""
    spec = domain_spec(domain)
    if low_level.kind == "admittance":
        if snapshot is not None:
            raise ValueError(f"the analytic low level has no snapshots, got snapshot={snapshot!r}")
        return spec.make_task()
    trained = learned_policy(domain, low_level.imitation, cache_dir)
    if snapshot is None:
        return spec.make_task(low_level=trained.policy)
    if snapshot not in trained.snapshots:
        raise ValueError(f"snapshot must be one of {sorted(trained.snapshots)}, got {snapshot!r}")
    return spec.make_task(low_level=trained.snapshots[snapshot])

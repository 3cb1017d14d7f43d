"""The base of every SI study (notebooks 02, 03, 04, 06, 07, 08): a fixed grid of true parameters crossed
with seeds, the paper's evaluation protocol and Algorithm 4's size."""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Annotated, Any, ClassVar

from hipref.experiments.domains import DOMAINS, domain_spec, truth_grids
from hipref.experiments.si_methods import COTEACHING_METHODS, LEARNING_METHODS
from hipref.experiments.si_pretraining import PretrainCell, PretrainData, pretrain_models
from hipref.experiments.si_run import FineTuning, SIRun, check_evaluations
from hipref.learners.pesi import LEARNING_RATE, PESIConfig
from hipref.learners.sysid import PRETRAIN_LOSSES
from hipref.sweep import CacheDir
from hipref.validation import Integer, OneOf, check_fields, check_range


@dataclass(frozen=True)
class SIStudy:
    """What the SI studies share: a fixed grid of true parameters crossed with seeds, the paper's
    evaluation protocol and Algorithm 4's size.

    Every method of a study meets the same environments (truth, seed) and the same evaluation episodes,
    so methods are compared as paired differences (`hipref.verdicts`)."""

    SEQUENCES: ClassVar[tuple[str, ...]] = ()
    """Tuple fields that are ordered values which may repeat, not grids of cells (`check_fields`)."""

    heights: tuple[float, ...] = (0.6, 0.8)
    """True desk heights in m of the wiping environments, each in [0.5, 0.9] (full profile: 5, evenly)."""
    masses: tuple[float, ...] = (11.0, 17.0)
    """True cube masses in kg of the pushing environments, each in [8, 20] (full profile: 5, evenly)."""
    seeds: Annotated[int, Integer(1)] = 1
    """Seeds per true parameter; truths x seeds is the repetitions of the paper (A.7: 15)."""
    episodes: Annotated[int, Integer(1)] = SIRun.episodes
    """Learning episodes per run, at least 1 (`SIRun.episodes`)."""
    eval_every: Annotated[int, Integer(1)] = SIRun.eval_every
    """Learning episodes between evaluations (section 5: 33, `SIRun.eval_every`), dividing `episodes`."""
    eval_episodes: Annotated[int, Integer(1)] = SIRun.eval_episodes
    """Evaluation episodes per evaluation (section 5: 10, `SIRun.eval_episodes`)."""
    eval_slices: Annotated[int, Integer(1)] = SIRun.eval_slices
    """Probing slices per evaluation episode (for the multi-slice estimate, `SIRun.eval_slices`)."""
    n_trajectories: int = 300
    """Algorithm 4 trajectories (the full profile: 3000, the study's; A.7's 100 starve SI, notebook 13)."""
    pretrain_steps: int = 500
    """Adam steps of Algorithm 4 (the full profile: 3000)."""
    pretrain_loss: Annotated[str, OneOf(PRETRAIN_LOSSES)] = "nll"
    """Algorithm 4's loss: 'nll' (the study's), or A.7's mean squared loss 'brier', 'expectation' or
    'brier_expectation' (see `PretrainData.loss`)."""
    learning_rate: Annotated[float, LEARNING_RATE] = PESIConfig.learning_rate
    """Gradient step size of SI fine-tuning (A.7: 0.01, `PESIConfig.learning_rate`)."""

    def __post_init__(self) -> None:
        # Every field of every study built on this base, by its annotation (`check_fields`).
        check_fields(self, self.SEQUENCES)
        for domain, values in truth_grids(self).items():
            name, candidates = DOMAINS[domain].truths, DOMAINS[domain].candidates
            if not values:
                raise ValueError(
                    f"{name} must hold at least one value in [{candidates.low}, {candidates.high}], got ()"
                )
            for value in values:
                check_range(name, value, candidates.low, candidates.high)
        check_evaluations(self.episodes, self.eval_every)
        self.data  # noqa: B018 - validates n_trajectories and pretrain_steps

    @property
    def data(self) -> PretrainData:
        return PretrainData(self.n_trajectories, pretrain_steps=self.pretrain_steps, loss=self.pretrain_loss)

    def truths(self, domain: str) -> tuple[float, ...]:
        """The grid of true parameters of `domain`."""
        return truth_grids(self)[domain_spec(domain).name]

    def environments(self, domain: str) -> list[tuple[float, int]]:
        """Every (ground truth, seed) of `domain`: the grid crossed with the seeds."""
        return [(truth, seed) for truth in self.truths(domain) for seed in range(self.seeds)]

    def run_cell(
        self,
        domain: str,
        method: str,
        truth: float,
        seed: int,
        fine_tuning: FineTuning | None = None,
        **setting: Any,
    ) -> SIRun:
        """One run of this protocol; `setting` holds what the study varies (noise, N). OSI learns nothing,
        so its run ignores the fine-tuning and the noise: one OSI run per environment serves every study."""
        tuning = (
            fine_tuning
            if fine_tuning is not None
            else FineTuning(PESIConfig(learning_rate=self.learning_rate))
        )
        if method not in LEARNING_METHODS:
            tuning, setting = FineTuning(), {k: v for k, v in setting.items() if k != "noise"}
        elif method not in COTEACHING_METHODS:
            # The classifier schedule means nothing without classifiers: such runs share one cache entry.
            tuning = dataclasses.replace(tuning, coteaching_schedule=FineTuning.coteaching_schedule)
        return SIRun(
            domain,
            method,
            truth,
            seed=seed,
            episodes=self.episodes,
            eval_every=self.eval_every,
            eval_episodes=self.eval_episodes,
            eval_slices=self.eval_slices,
            fine_tuning=tuning,
            data=self.data,
            **setting,
        )

    def pretrain(self, domains: Iterable[str], cache_dir: CacheDir = None, **sweep: Any) -> None:
        """Algorithm 4 once per domain of `domains`, before the study's runs (`pretrain_models`)."""
        pretrain_models([PretrainCell(domain, self.data) for domain in domains], cache_dir, **sweep)

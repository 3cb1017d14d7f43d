"""How much the SI conclusions hang on choices the paper leaves open (notebook 08).

Each *variant* changes one reading of the paper from the default (the paper's reading where it speaks, and
the study's where notebook 13 shows the paper's starves SI): Algorithm 4 as A.7 reads it (100 trajectories,
a mean squared loss), what that mean squared loss is taken over, how Algorithm 2 samples the candidates,
over what Pr of Eq. 2 is a distribution, which parameters of SI preferences fine-tune, the fine-tuning step
size, and CO-PESI's classifier schedule. The previous design of this study (expectation-only pretraining,
candidates from SI's belief, classifiers reset every co-teaching step) is kept as one more variant.

For every variant and environment of the grid the study runs OSI, PESI with perfect preferences and, for
the variants that can change the co-teaching comparison, PESI and CO-PESI at `noise`; every comparison is
paired (same truth, seed, teacher draws and evaluation episodes).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any

import pandas as pd

from hipref.experiments.domains import DOMAINS
from hipref.experiments.protocol import SIStudy
from hipref.experiments.si_pretraining import PAPER_A7, PretrainCell, pretrain_models
from hipref.experiments.si_run import FineTuning, SIRun, run_si
from hipref.learners.pesi import PESIConfig
from hipref.sweep import run_sweep
from hipref.validation import Integer, NonEmptyTuple, OneOf, Range

VARIANTS: dict[str, tuple[str, int | None, FineTuning]] = {
    "default": ("nll", None, FineTuning()),
    "paper_a7": (PAPER_A7.loss, PAPER_A7.n_trajectories, FineTuning()),
    "pretrain_expectation": ("expectation", None, FineTuning()),
    "pretrain_brier_expectation": ("brier_expectation", None, FineTuning()),
    "belief_candidates": ("nll", None, FineTuning(PESIConfig(candidate_sampling="belief"))),
    "pr_over_phi": ("nll", None, FineTuning(PESIConfig(pr_domain="all"))),
    "last_layer": ("nll", None, FineTuning(PESIConfig(fine_tuned="last_layer"))),
    "output_bias": ("nll", None, FineTuning(PESIConfig(fine_tuned="output_bias"))),
    "learning_rate_0.001": ("nll", None, FineTuning(PESIConfig(learning_rate=1e-3))),
    "learning_rate_0.05": ("nll", None, FineTuning(PESIConfig(learning_rate=5e-2))),
    "reset_every_step": ("nll", None, FineTuning(coteaching_schedule="reset_every_step")),
    "previous_design": (
        "expectation",
        PAPER_A7.n_trajectories,
        FineTuning(PESIConfig(candidate_sampling="belief"), coteaching_schedule="reset_every_step"),
    ),
}
"""Variant name -> (Algorithm 4's loss, its trajectories (None: the config's `n_trajectories`), how
preferences fine-tune SI). 'paper_a7' is Algorithm 4 as A.7 reads (`PAPER_A7`), the study's default before
notebook 13 showed it starves SI."""

COTEACHING_VARIANTS: tuple[str, ...] = ("default", "belief_candidates", "reset_every_step", "previous_design")
"""The variants whose CO-PESI - PESI comparison is run: the classifier schedules, and the candidate
sampling that decides which pairs the classifiers see."""


@dataclass(frozen=True)
class SensitivityConfig(SIStudy):
    """The variants x domains x environments of notebook 08. The protocol's `pretrain_loss` and
    `learning_rate` are not read: each variant sets its own (VARIANTS), and its trajectories where it names
    them."""

    variants: NonEmptyTuple[Annotated[str, OneOf(VARIANTS)]] = ("default", "paper_a7")
    """Which variants to run, each a key of VARIANTS (the full profile runs them all)."""
    domains: NonEmptyTuple[Annotated[str, OneOf(DOMAINS)]] = ("wiping", "pushing")
    """Domains to run."""
    noise: Annotated[float, Range(1e-9, 0.5 - 1e-9)] = 0.2
    """Fraction of flipped preferences of the co-teaching comparison, in (0, 0.5)."""
    heights: tuple[float, ...] = (0.7,)
    """True desk heights in m of the wiping environments, each in [0.5, 0.9]."""
    masses: tuple[float, ...] = (14.0,)
    """True cube masses in kg of the pushing environments, each in [8, 20]."""
    episodes: Annotated[int, Integer(1)] = 33
    """Learning episodes per run, at least 1."""
    eval_episodes: Annotated[int, Integer(1)] = 5
    """Evaluation episodes per evaluation (section 5: 10)."""


def variant_protocol(config: SensitivityConfig, variant: str) -> tuple[SIStudy, FineTuning]:
    """The protocol (its pretraining set by the variant) and the fine-tuning of one variant."""
    loss, n_trajectories, tuning = VARIANTS[variant]
    protocol = SIStudy(
        heights=config.heights,
        masses=config.masses,
        seeds=config.seeds,
        episodes=config.episodes,
        eval_every=config.eval_every,
        eval_episodes=config.eval_episodes,
        eval_slices=config.eval_slices,
        n_trajectories=config.n_trajectories if n_trajectories is None else n_trajectories,
        pretrain_steps=config.pretrain_steps,
        pretrain_loss=loss,
    )
    return protocol, tuning


def cells(config: SensitivityConfig, variant: str) -> list[SIRun]:
    """The runs of one variant; runs equal across variants (OSI, or PESI where only the classifier schedule
    differs) are cache hits after the first."""
    protocol, tuning = variant_protocol(config, variant)
    settings: list[tuple[str, float]] = [("osi", 0.0), ("pesi", 0.0)]
    if variant in COTEACHING_VARIANTS:
        settings += [("pesi", config.noise), ("co_pesi", config.noise)]
    return [
        protocol.run_cell(domain, method, truth, seed, fine_tuning=tuning, noise=noise)
        for domain in config.domains
        for method, noise in settings
        for truth, seed in protocol.environments(domain)
    ]


def run(config: SensitivityConfig, **sweep: Any) -> pd.DataFrame:
    """Tidy rows of every run (see `run_si`) with a `variant` column.

    Every distinct run of every variant goes into one sweep (one pool of workers, each run once); the rows
    of each variant are then read back from the sweep's cache."""
    # Every variant's model of every domain, built side by side before the runs.
    models = [
        PretrainCell(domain, variant_protocol(config, variant)[0].data)
        for variant in config.variants
        for domain in config.domains
    ]
    pretrain_models(models, **sweep)
    runs = {variant: cells(config, variant) for variant in config.variants}
    distinct = list(dict.fromkeys(run for variant_runs in runs.values() for run in variant_runs))
    run_sweep(run_si, distinct, desc="SI sensitivity", **sweep)
    frames = [
        run_sweep(run_si, variant_runs, desc=variant, **sweep).assign(variant=variant)
        for variant, variant_runs in runs.items()
    ]
    return pd.concat(frames, ignore_index=True)

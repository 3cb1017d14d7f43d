"""R2: what flipped preferences do to PESI (Fig. 2e wiping, Fig. 2f pushing)."""

from __future__ import annotations

from dataclasses import dataclass

import pandas as pd

from hipref.experiments.sysid import PretrainData, SIRun, pretrained_model, run_si
from hipref.sweep import run_sweep
from hipref.validation import check_choice, check_int, check_range


@dataclass(frozen=True)
class R2Config:
    """PESI's error over episodes at several fractions of flipped preferences, in both domains."""

    noise_levels: tuple[float, ...] = (0.0, 0.3, 0.6)
    """Fractions of flipped preferences, each in [0, 1] (paper: 0, 0.1, ..., 0.6)."""
    domains: tuple[str, ...] = ("wiping", "pushing")
    """Domains to run: Fig. 2e is wiping, Fig. 2f pushing."""
    seeds: int = 2
    """Repetitions per (domain, noise) (Table 2: 15); the true parameter is drawn per seed."""
    episodes: int = 66
    """Learning episodes per run."""
    eval_every: int = 33
    """Learning episodes between evaluations (section 5: 33)."""
    eval_episodes: int = 10
    """Evaluation episodes per evaluation (section 5: 10)."""
    n_trajectories: int = 100
    """Algorithm 4 trajectories (A.7: 100)."""
    pretrain_steps: int = 3000
    """Adam steps of Algorithm 4."""

    def __post_init__(self) -> None:
        if not self.noise_levels or not self.domains:
            raise ValueError(
                f"noise_levels and domains must be non-empty, got {self.noise_levels!r} and {self.domains!r}"
            )
        for noise in self.noise_levels:
            check_range("noise_levels", noise, 0.0, 1.0)
        for domain in self.domains:
            check_choice("domains", domain, ("wiping", "pushing"))
        check_int("seeds", self.seeds, 1)
        check_int("episodes", self.episodes, 0)
        check_int("eval_every", self.eval_every, 1)
        check_int("eval_episodes", self.eval_episodes, 1)
        PretrainData(self.n_trajectories, pretrain_steps=self.pretrain_steps)


def cells(cfg: R2Config) -> list[SIRun]:
    data = PretrainData(cfg.n_trajectories, pretrain_steps=cfg.pretrain_steps)
    return [
        SIRun(
            domain,
            "pesi",
            noise=noise,
            seed=seed,
            episodes=cfg.episodes,
            eval_every=cfg.eval_every,
            eval_episodes=cfg.eval_episodes,
            data=data,
        )
        for domain in cfg.domains
        for noise in cfg.noise_levels
        for seed in range(cfg.seeds)
    ]


def run(cfg: R2Config) -> pd.DataFrame:
    """All runs, tidy (see `run_si`)."""
    # Algorithm 4 once, here, so the parallel workers load the pretrained model instead of racing to build it.
    for domain in cfg.domains:
        pretrained_model(domain, PretrainData(cfg.n_trajectories, pretrain_steps=cfg.pretrain_steps))
    return run_sweep(run_si, cells(cfg), desc="R2 noise")

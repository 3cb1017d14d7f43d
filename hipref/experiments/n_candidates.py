"""A.2: PESI with preferences over N candidates per query (Eq. 3)."""

from __future__ import annotations

from dataclasses import dataclass

import pandas as pd

from hipref.experiments.sysid import PretrainData, SIRun, pretrained_model, run_si
from hipref.sweep import run_sweep
from hipref.validation import check_choice, check_int, check_range


@dataclass(frozen=True)
class NCandidatesConfig:
    """PESI's error over episodes with N = 2 (Eq. 2) and more (Eq. 3) candidates per query."""

    n_candidates: tuple[int, ...] = (2, 3, 5)
    """Candidates per query, each >= 2."""
    domain: str = "wiping"
    """'wiping' or 'pushing'."""
    noise: float = 0.0
    """Fraction of flipped preferences, in [0, 1]."""
    seeds: int = 2
    """Repetitions per N (Table 2: 15); the true parameter is drawn per seed."""
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
        if not self.n_candidates:
            raise ValueError("n_candidates must name at least one N, got ()")
        for n in self.n_candidates:
            check_int("n_candidates", n, 2, 41)
        check_choice("domain", self.domain, ("wiping", "pushing"))
        check_range("noise", self.noise, 0.0, 1.0)
        check_int("seeds", self.seeds, 1)
        check_int("episodes", self.episodes, 0)
        check_int("eval_every", self.eval_every, 1)
        check_int("eval_episodes", self.eval_episodes, 1)
        PretrainData(self.n_trajectories, pretrain_steps=self.pretrain_steps)


def cells(cfg: NCandidatesConfig) -> list[SIRun]:
    data = PretrainData(cfg.n_trajectories, pretrain_steps=cfg.pretrain_steps)
    return [
        SIRun(
            cfg.domain,
            "pesi",
            noise=cfg.noise,
            seed=seed,
            n_candidates=n,
            episodes=cfg.episodes,
            eval_every=cfg.eval_every,
            eval_episodes=cfg.eval_episodes,
            data=data,
        )
        for n in cfg.n_candidates
        for seed in range(cfg.seeds)
    ]


def run(cfg: NCandidatesConfig) -> pd.DataFrame:
    """All runs, tidy (see `run_si`); `n_candidates` tells the runs apart."""
    # Algorithm 4 once, here, so the parallel workers load the pretrained model instead of racing to build it.
    for domain in (cfg.domain,):
        pretrained_model(domain, PretrainData(cfg.n_trajectories, pretrain_steps=cfg.pretrain_steps))
    return run_sweep(run_si, cells(cfg), desc="N candidates")

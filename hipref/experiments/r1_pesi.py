"""R1 for the low level: does fine-tuning SI with preferences beat OSI? (Fig. 2d, Fig. 4, A.8)."""

from __future__ import annotations

from dataclasses import dataclass

import pandas as pd

from hipref.experiments.sysid import PretrainData, SIRun, pretrained_model, run_si
from hipref.sweep import run_sweep
from hipref.validation import check_int


@dataclass(frozen=True)
class R1Config:
    """Fig. 2d (osi, pesi, pesi_ce at several desk heights) and Fig. 4 (PESI over episodes, both domains)."""

    heights: tuple[float, ...] = (0.6, 0.75)
    """Ground-truth desk heights in m of Fig. 2d, inside [0.5, 0.9]."""
    seeds: int = 2
    """Repetitions per (method, height) and per domain of Fig. 4 (Table 2: 15)."""
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
        if not self.heights:
            raise ValueError("heights must name at least one desk height, got ()")
        for height in self.heights:
            SIRun("wiping", "osi", ground_truth=height)  # validates the range, before any compute
        check_int("seeds", self.seeds, 1)
        check_int("episodes", self.episodes, 0)
        check_int("eval_every", self.eval_every, 1)
        check_int("eval_episodes", self.eval_episodes, 1)
        PretrainData(self.n_trajectories, pretrain_steps=self.pretrain_steps)


def cells(cfg: R1Config) -> list[SIRun]:
    """Fig. 2d: every method at every height on wiping; Fig. 4: PESI with random truths in both domains."""
    data = PretrainData(cfg.n_trajectories, pretrain_steps=cfg.pretrain_steps)
    common = dict(
        episodes=cfg.episodes, eval_every=cfg.eval_every, eval_episodes=cfg.eval_episodes, data=data
    )
    fig2d = [
        SIRun("wiping", method, seed=seed, ground_truth=height, **common)
        for height in cfg.heights
        for method in ("osi", "pesi", "pesi_ce")
        for seed in range(cfg.seeds)
    ]
    fig4 = [
        SIRun(domain, "pesi", seed=seed, **common)
        for domain in ("wiping", "pushing")
        for seed in range(cfg.seeds)
    ]
    return fig2d + fig4


def run(cfg: R1Config) -> pd.DataFrame:
    """All runs, tidy; `figure` says which panel a row belongs to."""
    # Algorithm 4 once, here, so the parallel workers load the pretrained model instead of racing to build it.
    for domain in ("wiping", "pushing"):
        pretrained_model(domain, PretrainData(cfg.n_trajectories, pretrain_steps=cfg.pretrain_steps))
    runs = cells(cfg)
    n_fig2d = len(runs) - 2 * cfg.seeds
    frames = run_sweep(run_si, runs, desc="R1 PESI")
    figure = ["fig2d" if i < n_fig2d else "fig4" for i, _ in enumerate(runs)]
    per_run = len(frames) // len(runs)
    return frames.assign(figure=[f for f in figure for _ in range(per_run)])

"""R1 for the low level: does fine-tuning SI with preferences beat OSI? (Fig. 2d, Fig. 4, A.8)."""

from __future__ import annotations

from dataclasses import dataclass

import pandas as pd

from hipref.experiments.sysid import Protocol, SIRun, run_si
from hipref.sweep import run_sweep


@dataclass(frozen=True)
class R1Config(Protocol):
    """Fig. 2d (osi, pesi, pesi_ce at several desk heights) and Fig. 4 (PESI over episodes, both domains)."""

    heights: tuple[float, ...] = (0.6, 0.75)
    """Ground-truth desk heights in m of Fig. 2d, inside [0.5, 0.9]."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.heights:
            raise ValueError("heights must name at least one desk height, got ()")
        for height in self.heights:
            SIRun("wiping", "osi", ground_truth=height)  # validates the range, before any compute


def cells(cfg: R1Config) -> list[SIRun]:
    """Fig. 2d: every method at every height on wiping; Fig. 4: PESI with random truths in both domains."""
    fig2d = [
        cfg.run_cell("wiping", method, seed, ground_truth=height)
        for height in cfg.heights
        for method in ("osi", "pesi", "pesi_ce")
        for seed in range(cfg.seeds)
    ]
    fig4 = [
        cfg.run_cell(domain, "pesi", seed) for domain in ("wiping", "pushing") for seed in range(cfg.seeds)
    ]
    return fig2d + fig4


def run(cfg: R1Config) -> pd.DataFrame:
    """All runs, tidy; `figure` says which panel a row belongs to."""
    cfg.pretrain(("wiping", "pushing"))
    runs = cells(cfg)
    n_fig2d = len(runs) - 2 * cfg.seeds
    frames = run_sweep(run_si, runs, desc="R1 PESI")
    figure = ["fig2d" if i < n_fig2d else "fig4" for i, _ in enumerate(runs)]
    per_run = len(frames) // len(runs)
    return frames.assign(figure=[f for f in figure for _ in range(per_run)])

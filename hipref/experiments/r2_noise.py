"""R2: what flipped preferences do to PESI (Fig. 2e wiping, Fig. 2f pushing)."""

from __future__ import annotations

from dataclasses import dataclass

import pandas as pd

from hipref.experiments.sysid import DOMAINS, Protocol, SIRun, run_si
from hipref.sweep import run_sweep
from hipref.validation import check_choice, check_range


@dataclass(frozen=True)
class R2Config(Protocol):
    """PESI's error over episodes at several levels of flipped preferences, in both domains."""

    noise_levels: tuple[float, ...] = (0.0, 0.3, 0.6)
    """Fractions of flipped preferences, each in [0, 1] (paper: 0, 0.1, ..., 0.6)."""
    domains: tuple[str, ...] = ("wiping", "pushing")
    """Domains to run: Fig. 2e is wiping, Fig. 2f pushing."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if not self.noise_levels or not self.domains:
            raise ValueError(
                f"noise_levels and domains must be non-empty, got {self.noise_levels!r} and {self.domains!r}"
            )
        for noise in self.noise_levels:
            check_range("noise_levels", noise, 0.0, 1.0)
        for domain in self.domains:
            check_choice("domains", domain, tuple(DOMAINS))


def cells(cfg: R2Config) -> list[SIRun]:
    return [
        cfg.run_cell(domain, "pesi", seed, noise=noise)
        for domain in cfg.domains
        for noise in cfg.noise_levels
        for seed in range(cfg.seeds)
    ]


def run(cfg: R2Config) -> pd.DataFrame:
    """All runs, tidy (see `run_si`)."""
    cfg.pretrain(cfg.domains)
    return run_sweep(run_si, cells(cfg), desc="R2 noise")

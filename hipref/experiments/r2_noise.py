"""R2: what flipped preferences do to PESI (Fig. 2e wiping, Fig. 2f pushing).

Each environment of the grid is learnt at every noise level with the same seed, and OSI is run once per
environment, so PESI at each noise level is compared with OSI (and with PESI at 0 %) as paired differences.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any

import pandas as pd

from hipref.experiments.domains import DOMAINS
from hipref.experiments.protocol import SIStudy
from hipref.experiments.si_run import SIRun, run_si
from hipref.sweep import run_sweep
from hipref.validation import NonEmptyTuple, OneOf, Range


@dataclass(frozen=True)
class R2Config(SIStudy):
    """PESI's error over episodes at several levels of flipped preferences, in both domains."""

    noise_levels: NonEmptyTuple[Annotated[float, Range(0.0, 1.0)]] = (0.0, 0.3, 0.6)
    """Fractions of flipped preferences, each in [0, 1] (paper: 0, 0.1, ..., 0.6)."""
    domains: NonEmptyTuple[Annotated[str, OneOf(DOMAINS)]] = ("wiping", "pushing")
    """Domains to run: Fig. 2e is wiping, Fig. 2f pushing."""


def cells(cfg: R2Config) -> list[SIRun]:
    osi = [
        cfg.run_cell(domain, "osi", truth, seed)
        for domain in cfg.domains
        for truth, seed in cfg.environments(domain)
    ]
    pesi = [
        cfg.run_cell(domain, "pesi", truth, seed, noise=noise)
        for domain in cfg.domains
        for noise in cfg.noise_levels
        for truth, seed in cfg.environments(domain)
    ]
    return osi + pesi


def run(config: R2Config, **sweep: Any) -> pd.DataFrame:
    """All runs, tidy (see `run_si`); OSI's rows have noise 0. `sweep`: `run_sweep`'s options."""
    config.pretrain(config.domains, **sweep)
    return run_sweep(run_si, cells(config), desc="R2 noise", **sweep)

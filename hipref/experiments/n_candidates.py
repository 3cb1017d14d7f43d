"""A.2: PESI with preferences over N candidates per query (Eq. 3)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any

import pandas as pd

from hipref.experiments.domains import DOMAINS
from hipref.experiments.protocol import SIStudy
from hipref.experiments.si_run import SIRun, run_si
from hipref.sweep import run_sweep
from hipref.validation import NonEmptyTuple, OneOf, Range, check_int


@dataclass(frozen=True)
class NCandidatesConfig(SIStudy):
    """PESI's error over episodes with N = 2 (Eq. 2) and more (Eq. 3) candidates per query."""

    n_candidates: NonEmptyTuple[int] = (2, 3, 5)
    """Candidates per query, each >= 2."""
    domain: Annotated[str, OneOf(DOMAINS)] = "wiping"
    """'wiping' or 'pushing'."""
    noise: Annotated[float, Range(0.0, 1.0)] = 0.0
    """Fraction of flipped preferences, in [0, 1]."""

    def __post_init__(self) -> None:
        super().__post_init__()
        for n in self.n_candidates:
            check_int("n_candidates", n, 2, DOMAINS[self.domain].candidates.size)


def cells(cfg: NCandidatesConfig) -> list[SIRun]:
    return [
        cfg.run_cell(cfg.domain, "pesi", truth, seed, noise=cfg.noise, n_candidates=n)
        for n in cfg.n_candidates
        for truth, seed in cfg.environments(cfg.domain)
    ]


def run(config: NCandidatesConfig, **sweep: Any) -> pd.DataFrame:
    """All runs, tidy (see `run_si`); `n_candidates` tells the runs apart. `sweep`: `run_sweep`'s options."""
    config.pretrain((config.domain,), **sweep)
    return run_sweep(run_si, cells(config), desc="N candidates", **sweep)

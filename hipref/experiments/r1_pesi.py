"""R1 for the low level: does fine-tuning SI with preferences beat OSI? (Fig. 2d, Fig. 4, A.8).

Every environment of the grid (true parameter x seed) is learnt by every method with the same teacher draws
and evaluated on the same episodes, so PESI - OSI and PESI - PESI-CE are paired differences.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import pandas as pd

from hipref.experiments.protocol import Protocol
from hipref.experiments.si_run import SIRun, run_si
from hipref.sweep import run_sweep

METHODS: dict[str, tuple[str, ...]] = {"wiping": ("osi", "pesi", "pesi_ce"), "pushing": ("osi", "pesi")}
"""Fig. 2d and A.8 compare the three methods on desk height; Fig. 4 adds PESI against OSI on cube mass."""


@dataclass(frozen=True)
class R1Config(Protocol):
    """Fig. 2d (OSI, PESI, PESI-CE at every desk height of the grid) and Fig. 4 (PESI against OSI over
    episodes, both domains), with perfect preferences."""


def cells(cfg: R1Config) -> list[SIRun]:
    return [
        cfg.run_cell(domain, method, truth, seed)
        for domain, methods in METHODS.items()
        for method in methods
        for truth, seed in cfg.environments(domain)
    ]


def run(config: R1Config, **sweep: Any) -> pd.DataFrame:
    """All runs, tidy (see `run_si`). `sweep`: `run_sweep`'s options."""
    config.pretrain(METHODS, **sweep)
    return run_sweep(run_si, cells(config), desc="R1 PESI", **sweep)

"""R1 for the low level: does fine-tuning SI with preferences beat OSI? (Fig. 2d, Fig. 4, A.8).

Every environment of the grid (true parameter x seed) is learnt by every method with the same teacher draws
and evaluated on the same episodes, so PESI - OSI and PESI - PESI-CE are paired differences. A held-out grid
(other truths, other seeds) reruns OSI and PESI, evaluated after the last episode only, so that the study
replicates its own headline on environments it was not designed on.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import pandas as pd

from hipref.experiments.domains import DOMAINS, truth_grids
from hipref.experiments.protocol import SIStudy
from hipref.experiments.si_run import SIRun, run_si
from hipref.sweep import run_sweep
from hipref.validation import NonEmptyTuple, check_int, check_range

METHODS: dict[str, tuple[str, ...]] = {"wiping": ("osi", "pesi", "pesi_ce"), "pushing": ("osi", "pesi")}
"""Fig. 2d and A.8 compare the three methods on desk height; Fig. 4 adds PESI against OSI on cube mass."""


HELD_OUT_METHODS: tuple[str, ...] = ("osi", "pesi")
"""The headline's methods, rerun on the held-out grid."""


def held_out_field(domain: str) -> str:
    """The field of `R1PESIConfig` holding `domain`'s held-out truths: 'held_out_' and the grid's field."""
    return f"held_out_{DOMAINS[domain].truths}"


@dataclass(frozen=True)
class R1PESIConfig(SIStudy):
    """Fig. 2d (OSI, PESI, PESI-CE at every desk height of the grid) and Fig. 4 (PESI against OSI over
    episodes, both domains), with perfect preferences; OSI and PESI again on a held-out grid."""

    held_out_heights: tuple[float, ...] = (0.66,)
    """True desk heights in m of the held-out wiping environments, each in [0.5, 0.9] and none of
    `heights` (full profile: 4)."""
    held_out_masses: tuple[float, ...] = (15.0,)
    """True cube masses in kg of the held-out pushing environments, each in [8, 20] and none of `masses`
    (full profile: 4)."""
    held_out_seeds: NonEmptyTuple[int] = (100,)
    """Seeds of the held-out environments, none below `seeds` (the grid's are 0 .. seeds - 1)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        grids, held_out = truth_grids(self), self.held_out_grids()
        for domain, values in held_out.items():
            name, candidates, grid = held_out_field(domain), DOMAINS[domain].candidates, grids[domain]
            if not values:
                low, high = candidates.low, candidates.high
                raise ValueError(f"{name} must hold at least one value in [{low}, {high}]")
            for value in values:
                check_range(name, value, candidates.low, candidates.high)
                if value in grid:
                    raise ValueError(f"{name} must hold truths outside the grid, got {value} (in the grid)")
        for seed in self.held_out_seeds:
            check_int("held_out_seeds", seed, self.seeds)

    def held_out_grids(self) -> dict[str, tuple[float, ...]]:
        """Each domain's held-out true parameters (`held_out_field`)."""
        return {domain: getattr(self, held_out_field(domain)) for domain in DOMAINS}

    def held_out(self) -> SIStudy:
        """The held-out grid as a protocol of its own, evaluated after the last episode only."""
        shared = {f.name: getattr(self, f.name) for f in dataclasses.fields(SIStudy)}
        truths = {DOMAINS[domain].truths: grid for domain, grid in self.held_out_grids().items()}
        return SIStudy(**shared | truths | {"eval_every": self.episodes})

    def held_out_environments(self, domain: str) -> list[tuple[float, int]]:
        """Every (ground truth, seed) of `domain`'s held-out grid."""
        return [(truth, seed) for truth in self.held_out().truths(domain) for seed in self.held_out_seeds]


def cells(cfg: R1PESIConfig) -> list[SIRun]:
    return [
        cfg.run_cell(domain, method, truth, seed)
        for domain, methods in METHODS.items()
        for method in methods
        for truth, seed in cfg.environments(domain)
    ]


def held_out_cells(cfg: R1PESIConfig) -> list[SIRun]:
    held_out = cfg.held_out()
    return [
        held_out.run_cell(domain, method, truth, seed)
        for domain in METHODS
        for method in HELD_OUT_METHODS
        for truth, seed in cfg.held_out_environments(domain)
    ]


def run(config: R1PESIConfig, **sweep: Any) -> pd.DataFrame:
    """All runs, tidy (see `run_si`), with a `grid` column: 'study' for the grid's runs, 'held_out' for the
    held-out grid's. `sweep`: `run_sweep`'s options."""
    config.pretrain(METHODS, **sweep)
    study, held_out = cells(config), held_out_cells(config)
    rows = run_sweep(run_si, study + held_out, desc="R1 PESI", **sweep)
    held_out_keys = {(c.domain, c.method, c.ground_truth, c.seed) for c in held_out}
    keys = zip(rows["domain"], rows["method"], rows["ground_truth"], rows["seed"], strict=True)
    return rows.assign(grid=["held_out" if key in held_out_keys else "study" for key in keys])

"""The R3 study (notebook 04): CO-PESI against PESI under noisy preferences (R3, A.6, Figs. 3 and 5).

Every (domain, noise level, seed) environment is learnt by both methods with the same seed, so both face
the same true parameter, the same teacher noise draws and the same evaluation episodes
(`hipref.experiments.si_run`): the comparison is paired. Claims are tested on the final evaluation (after
the last learning episode) with a bootstrap interval over seeds of the paired difference, not by eye.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any

import numpy as np
import pandas as pd

from hipref.experiments.domains import DOMAINS
from hipref.experiments.protocol import SIStudy
from hipref.experiments.si_methods import METHODS as SI_METHODS
from hipref.experiments.si_run import SIRun, run_si
from hipref.sweep import run_sweep
from hipref.validation import Integer, NonEmptyTuple, OneOf, Range, check_choice, check_int
from hipref.verdicts import Difference, better_on_both, combine, no_difference, paired_difference

METHODS: tuple[str, ...] = ("pesi", "co_pesi")
"""The two methods of Figs. 3 and 5; co_pesi is told the true noise level (A.7: remember rate 1 - noise)."""


@dataclass(frozen=True)
class R3Config(SIStudy):
    """Parameters of notebook 04 (the paper's values where it gives them; the sizes of the quick profile)."""

    domains: NonEmptyTuple[Annotated[str, OneOf(DOMAINS)]] = ("wiping", "pushing")
    """Domains to run: 'wiping' (Fig. 3, desk height) and 'pushing' (Fig. 5, cube mass)."""
    methods: NonEmptyTuple[Annotated[str, OneOf(SI_METHODS)]] = METHODS
    """Methods compared; Figs. 8 and 9 add 'co_pesi_estimated' and 'co_pesi_estimated_same_pair' (A.9)."""
    noise_levels: NonEmptyTuple[Annotated[float, Range(0.0, 1.0)]] = (0.1, 0.2, 0.3)
    """Fractions of flipped preferences (section 5: 10, 20 and 30%)."""
    heights: tuple[float, ...] = (0.6,)
    """True desk heights in m of the wiping environments, each in [0.5, 0.9] (full profile: 5, evenly)."""
    masses: tuple[float, ...] = (11.0,)
    """True cube masses in kg of the pushing environments, each in [8, 20] (full profile: 5, evenly)."""
    eval_episodes: Annotated[int, Integer(1)] = 5
    """Evaluation episodes per evaluation (section 5: 10)."""
    claim_episodes: tuple[int, ...] = ()
    """Learning episodes after which the claims of Figs. 3 and 5 are tested, each an evaluated one (the paper
    gives no horizon; empty: the last evaluation only; full profile: 5, from 33 to 330)."""

    def __post_init__(self) -> None:
        super().__post_init__()  # every field by its annotation (`check_fields`) first
        evaluated = range(0, self.episodes + 1, self.eval_every)
        for episode in self.claim_episodes:
            check_int("claim_episodes", episode, self.eval_every, self.episodes)
            if episode not in evaluated:
                raise ValueError(
                    "claim_episodes must hold evaluated episodes (multiples of eval_every="
                    f"{self.eval_every} up to episodes={self.episodes}), got {episode}"
                )


def cells(config: R3Config) -> list[SIRun]:
    """The sweep: domain x noise level x method x environment (truth, seed)."""
    return [
        config.run_cell(domain, method, truth, seed, noise=float(noise))
        for domain in config.domains
        for noise in config.noise_levels
        for method in config.methods
        for truth, seed in config.environments(domain)
    ]


def run(config: R3Config, **sweep: Any) -> pd.DataFrame:
    """Tidy rows of every run (see `run_si`), with the filter's precision and recall for CO-PESI."""
    config.pretrain(config.domains, **sweep)
    return run_sweep(run_si, cells(config), desc="R3: " + " vs ".join(config.methods), **sweep)


def final_difference(
    rows: pd.DataFrame,
    domain: str,
    noise: float,
    metric: str,
    *,
    method: str = "co_pesi",
    baseline: str = "pesi",
    episode: int | None = None,
    resamples: int = 5000,
    seed: int = 0,
) -> tuple[float, float, float, int]:
    """`method` minus `baseline` after `episode` learning episodes (None: the last evaluation): (mean, low,
    high, pairs).

    `hipref.verdicts.paired_difference` on the rows of `domain` at `noise`: runs are paired on domain, true
    parameter and seed, the interval is a 95% bootstrap over the pairs, and with one pair the interval is
    the point itself. A run without a partner is left out of the pairs.
    """
    at = rows[(rows["domain"] == domain) & np.isclose(rows["noise"], noise)]
    if at.empty:
        raise ValueError(f"no rows for domain={domain!r} at noise={noise!r}")
    d = paired_difference(
        at, metric=metric, method=method, baseline=baseline, episode=episode, resamples=resamples, seed=seed
    )
    return d.mean, d.low, d.high, d.n


def verdict(
    rows: pd.DataFrame,
    domain: str,
    noise: float,
    expect: str,
    *,
    method: str = "co_pesi",
    baseline: str = "pesi",
    episode: int | None = None,
) -> tuple[str, str]:
    """Test '`method` better than `baseline`' or 'no difference' on both metrics after `episode` learning
    episodes (None: the last evaluation); the paper gives no horizon, so notebook 04 tests several.

    'better' is `hipref.verdicts.better_on_both` (a lower param_error and a higher success_rate, each 95%
    interval wholly on its better side); 'no difference' is `no_difference` on both metrics (`combine`).
    Returns (verdict, the measured differences as text).
    """
    check_choice("expect", expect, ("better", "no difference"))
    at = int(rows["episode"].max()) if episode is None else episode
    error, success = (
        Difference(*final_difference(rows, domain, noise, m, method=method, baseline=baseline, episode=at))
        for m in ("param_error", "success_rate")
    )
    if expect == "better":
        held = better_on_both(error, success)
    else:
        held = combine([no_difference(error), no_difference(success)])
    text = (
        f"{method} - {baseline} after {at} episodes ({error.n} environments): error {error.mean:+.3g} "
        f"[{error.low:+.3g}, {error.high:+.3g}], "
        f"success {success.mean:+.2f} [{success.low:+.2f}, {success.high:+.2f}]"
    )
    return held, text

"""The R3 study (notebook 04): CO-PESI against PESI under noisy preferences (R3, A.6, Figs. 3 and 5).

Every (domain, noise level, seed) environment is learnt by both methods with the same seed, so both face
the same true parameter, the same teacher noise draws and the same evaluation episodes
(`hipref.experiments.sysid`): the comparison is paired. Claims are tested on the final evaluation (after
the last learning episode) with a bootstrap interval over seeds of the paired difference, not by eye.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from hipref.experiments.sysid import DOMAINS, PretrainData, SIRun, run_si
from hipref.experiments.sysid import METHODS as SI_METHODS
from hipref.sweep import run_sweep
from hipref.validation import check_choice, check_int, check_range

METHODS: tuple[str, ...] = ("pesi", "co_pesi")
"""The two methods of Figs. 3 and 5; co_pesi is told the true noise level (A.7: remember rate 1 - noise)."""


@dataclass(frozen=True)
class R3Config:
    """Parameters of notebook 04 (defaults: the quick profile; the paper's values where it gives them)."""

    domains: tuple[str, ...] = ("wiping", "pushing")
    """Domains to run: 'wiping' (Fig. 3, desk height) and 'pushing' (Fig. 5, cube mass)."""
    methods: tuple[str, ...] = METHODS
    """Methods compared; Figs. 8 and 9 add 'co_pesi_estimated' (A.9)."""
    noise_levels: tuple[float, ...] = (0.1, 0.2, 0.3)
    """Fractions of flipped preferences (section 5: 10, 20 and 30%)."""
    seeds: int = 2
    """Environments (seeds) per domain and noise level (A.7: 15 repetitions)."""
    episodes: int = 99
    """Learning episodes per run; evaluated at 0 and every `eval_every` (section 5: every 33)."""
    eval_every: int = 33
    """Learning episodes between evaluations (section 5: 33)."""
    eval_episodes: int = 5
    """Evaluation episodes per evaluation (section 5: 10)."""
    pretrain_steps: int = 3000
    """Adam steps of Algorithm 4 pretraining (shared with the other SI studies when equal)."""
    seed: int = 0
    """Root seed; the seeds of the runs derive from it."""

    def __post_init__(self) -> None:
        if not self.domains:
            raise ValueError(f"domains must name at least one of {sorted(DOMAINS)}, got {self.domains!r}")
        for domain in self.domains:
            check_choice("domains", domain, DOMAINS)
        for method in self.methods:
            check_choice("methods", method, SI_METHODS)
        if not self.noise_levels:
            raise ValueError(
                f"noise_levels must hold at least one level in [0.0, 1.0], got {self.noise_levels!r}"
            )
        for level in self.noise_levels:
            check_range("noise_levels", level, 0.0, 1.0)
        check_int("seeds", self.seeds, 1, 10_000)
        check_int("episodes", self.episodes, 1)
        check_int("eval_every", self.eval_every, 1, self.episodes)
        check_int("eval_episodes", self.eval_episodes, 1)
        check_int("pretrain_steps", self.pretrain_steps, 0)
        check_int("seed", self.seed, 0)


def run_seeds(config: R3Config) -> list[int]:
    """One seed per environment, from numpy's SeedSequence; shared by every domain, noise level and method."""
    children = np.random.SeedSequence([config.seed, 4]).spawn(config.seeds)
    return [int(child.generate_state(1)[0] % 2**31) for child in children]


def cells(config: R3Config) -> list[SIRun]:
    """The sweep: domain x noise level x method x seed."""
    data = PretrainData(pretrain_steps=config.pretrain_steps)
    return [
        SIRun(
            domain=domain,
            method=method,
            noise=float(noise),
            seed=seed,
            episodes=config.episodes,
            eval_every=config.eval_every,
            eval_episodes=config.eval_episodes,
            data=data,
        )
        for domain in config.domains
        for noise in config.noise_levels
        for method in config.methods
        for seed in run_seeds(config)
    ]


def run(config: R3Config, **sweep: object) -> pd.DataFrame:
    """Tidy rows (param_error, success_rate per evaluation) of every run."""
    return run_sweep(run_si, cells(config), desc="R3: " + " vs ".join(config.methods), **sweep)


def final_difference(
    rows: pd.DataFrame,
    domain: str,
    noise: float,
    metric: str,
    *,
    method: str = "co_pesi",
    baseline: str = "pesi",
    resamples: int = 5000,
    seed: int = 0,
) -> tuple[float, float, float, int]:
    """`method` minus `baseline` at the last evaluation: the mean paired difference over seeds, its 95%
    bootstrap interval (seeds resampled with replacement) and the number of seeds. With one seed the
    interval is the point itself: no spread can be measured."""
    final = rows[(rows["domain"] == domain) & np.isclose(rows["noise"], noise) & (rows["metric"] == metric)]
    final = final[final["episode"] == final["episode"].max()]
    wide = final.pivot_table(index="seed", columns="method", values="value").dropna()
    if method not in wide or baseline not in wide:
        raise ValueError(f"no paired {baseline}/{method} runs for domain={domain!r}, noise={noise!r}")
    difference = (wide[method] - wide[baseline]).to_numpy()
    rng = np.random.default_rng(seed)
    boot = rng.choice(difference, size=(resamples, difference.size)).mean(axis=1)
    low, high = np.quantile(boot, [0.025, 0.975])
    return float(difference.mean()), float(low), float(high), int(difference.size)


def verdict(
    rows: pd.DataFrame,
    domain: str,
    noise: float,
    expect: str,
    *,
    method: str = "co_pesi",
    baseline: str = "pesi",
) -> tuple[str, str]:
    """Test '`method` better than `baseline`' or 'no difference' at the final evaluation on both metrics.

    Better means a lower param_error and a higher success_rate, each with a 95% interval excluding zero:
    'yes' if both, 'partly' if one. No difference: 'yes' if both intervals contain zero, 'partly' if one.
    Returns (verdict, the measured differences as text).
    """
    check_choice("expect", expect, ("better", "no difference"))
    results = {
        m: final_difference(rows, domain, noise, m, method=method, baseline=baseline)
        for m in ("param_error", "success_rate")
    }
    error, success = results["param_error"], results["success_rate"]
    if expect == "better":
        passed = [error[2] < 0, success[1] > 0]
    else:
        passed = [error[1] <= 0 <= error[2], success[1] <= 0 <= success[2]]
    held = "yes" if all(passed) else "partly" if any(passed) else "no"
    text = (
        f"{method} - {baseline} at the last evaluation ({error[3]} seeds): error {error[0]:+.3g} "
        f"[{error[1]:+.3g}, {error[2]:+.3g}], "
        f"success {success[0]:+.2f} [{success[1]:+.2f}, {success[2]:+.2f}]"
    )
    return held, text

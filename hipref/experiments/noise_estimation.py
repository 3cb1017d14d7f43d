"""The noise-estimation study (notebook 06): paper A.9 / Table 3, Algorithm 5 on random preferences.

For every true noise level, `repetitions` datasets of `n_preferences` random pairwise preferences are
drawn (`random_preferences`: a true parameter uniform over the candidate range, random pairs of distinct
candidates, each label flipped with probability equal to the true noise) and Algorithm 5 estimates the
fraction of flipped labels. Table 3 is the mean estimate per true noise level.

Each dataset takes a fraction of a millisecond, so the whole table (7 x 100 datasets) runs in this process
in well under a second; a parallel sweep would cost more in process start-up than it saves.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from hipref.learners.noise_estimation import estimate_noise, random_preferences
from hipref.learners.sysid import CUBE_MASS, DESK_HEIGHT, CandidateSet
from hipref.validation import check_choice, check_int, check_range

PAPER_TABLE3: dict[float, float] = {
    0.1: 0.19,
    0.15: 0.23,
    0.2: 0.27,
    0.25: 0.32,
    0.3: 0.35,
    0.35: 0.38,
    0.4: 0.44,
}
"""Table 3 of the paper: true noise -> Algorithm 5's mean estimate over 100 datasets of 256 preferences."""

PAPER_OVERESTIMATE = 0.06
"""A.9: 'the algorithm often tends to overestimate the noise by about 6%' (absolute, in noise fraction)."""

CANDIDATES: dict[str, CandidateSet] = {"wiping": DESK_HEIGHT, "pushing": CUBE_MASS}
"""The candidate set each domain's preferences compare (A.9's example is desk height)."""

TABLE3_COLUMNS = ("true_noise", "estimated_noise", "estimated_noise_std", "paper_estimated_noise")
"""Columns of `table3`; `estimated_noise_std` is the standard deviation over repetitions."""


@dataclass(frozen=True)
class NoiseEstimationConfig:
    """Parameters of Table 3 (defaults: the paper's values, which are also the quick profile)."""

    n_preferences: int = 256
    """|D|, preferences per random dataset (A.9: 256)."""
    repetitions: int = 100
    """Random datasets per true noise level (A.9: 100)."""
    noise_levels: tuple[float, ...] = (0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4)
    """True fractions of flipped labels (Table 3: 0.10 to 0.40 in steps of 0.05)."""
    domain: str = "wiping"
    """Whose candidate set the preferences compare: 'wiping' (desk height, A.9's example) or 'pushing'."""
    seed: int = 0
    """Root seed; each dataset's generator derives from it, the noise level and the repetition."""

    def __post_init__(self) -> None:
        check_int("n_preferences", self.n_preferences, 2, 100_000)
        check_int("repetitions", self.repetitions, 1, 100_000)
        if not self.noise_levels:
            raise ValueError(
                f"noise_levels must hold at least one level in [0.0, 1.0], got {self.noise_levels!r}"
            )
        for level in self.noise_levels:
            check_range("noise_levels", level, 0.0, 1.0)
        check_choice("domain", self.domain, CANDIDATES)
        check_int("seed", self.seed, 0)


def dataset_rng(seed: int, true_noise: float, repetition: int) -> np.random.Generator:
    """The generator of one dataset. Keyed by the noise value (not its position) so that adding or
    dropping a level leaves every other level's datasets unchanged."""
    return np.random.default_rng(np.random.SeedSequence([seed, round(true_noise * 10_000), repetition]))


def run(config: NoiseEstimationConfig) -> pd.DataFrame:
    """Tidy rows: per dataset, `estimated_noise` (Algorithm 5) and `true_noise` (the flip probability).

    `seed` is the repetition number; with `config.seed` it determines the dataset (`dataset_rng`).
    """
    candidates = CANDIDATES[config.domain]
    rows = []
    for true_noise in config.noise_levels:
        for repetition in range(config.repetitions):
            rng = dataset_rng(config.seed, true_noise, repetition)
            preferences = random_preferences(config.n_preferences, true_noise, candidates, rng)
            estimate = estimate_noise(preferences)
            for metric, value in (("estimated_noise", estimate), ("true_noise", true_noise)):
                rows.append(
                    {
                        "domain": config.domain,
                        "method": "algorithm5",
                        "noise": float(true_noise),
                        "seed": repetition,
                        "episode": 0,
                        "metric": metric,
                        "value": float(value),
                    }
                )
    return pd.DataFrame(rows)


def summarise(rows: pd.DataFrame) -> pd.DataFrame:
    """Table 3 from tidy rows: mean and standard deviation of the estimate per true noise level."""
    estimates = rows[rows["metric"] == "estimated_noise"].groupby("noise")["value"]
    table = pd.DataFrame(
        {"estimated_noise": estimates.mean(), "estimated_noise_std": estimates.std(ddof=1)}
    ).reset_index(names="true_noise")
    table["paper_estimated_noise"] = [
        next((v for k, v in PAPER_TABLE3.items() if np.isclose(k, t)), np.nan) for t in table["true_noise"]
    ]
    return table[list(TABLE3_COLUMNS)]


def table3(config: NoiseEstimationConfig) -> pd.DataFrame:
    """Table 3 regenerated: columns `TABLE3_COLUMNS`, one row per true noise level."""
    return summarise(run(config))


def overestimate(rows: pd.DataFrame, *, resamples: int = 2000, seed: int = 0) -> tuple[float, float, float]:
    """Mean of (estimate - true noise) over all datasets and levels, with a 95% bootstrap interval over
    datasets resampled within each level (so every level keeps its weight)."""
    bias = _per_dataset(rows, relative=False)
    rng = np.random.default_rng(seed)
    groups = [g.to_numpy() for _, g in bias.groupby(level="noise")]
    boot = np.mean([rng.choice(g, size=(resamples, len(g))).mean(axis=1) for g in groups], axis=0)
    mean = float(np.mean([g.mean() for g in groups]))
    low, high = np.quantile(boot, [0.025, 0.975])
    return mean, float(low), float(high)


def error_trend(rows: pd.DataFrame, *, relative: bool = True) -> tuple[float, float, float]:
    """Least-squares slope of the per-dataset error on the true noise, with its 95% interval
    (normal approximation). `relative`: (estimate - true) / true; otherwise the absolute error
    |estimate - true|. A negative slope means the estimate gets better as the true noise grows."""
    error = _per_dataset(rows, relative=relative)
    if not relative:
        error = error.abs()
    x = error.index.get_level_values("noise").to_numpy(dtype=float)
    y = error.to_numpy(dtype=float)
    if np.unique(x).size < 2:
        raise ValueError("error_trend needs at least two noise levels")
    design = np.column_stack([np.ones_like(x), x])
    coef, *_ = np.linalg.lstsq(design, y, rcond=None)
    residual = y - design @ coef
    sigma2 = residual @ residual / max(len(y) - 2, 1)
    se = float(np.sqrt(sigma2 * np.linalg.inv(design.T @ design)[1, 1]))
    slope = float(coef[1])
    return slope, slope - 1.96 * se, slope + 1.96 * se


def _per_dataset(rows: pd.DataFrame, *, relative: bool) -> pd.Series:
    """estimate - true (or divided by true) per dataset, indexed by (noise, seed)."""
    wide = rows.pivot_table(index=["noise", "seed"], columns="metric", values="value")
    if relative:
        # A relative error is undefined at zero true noise.
        wide = wide[wide["true_noise"] > 0]
    error = wide["estimated_noise"] - wide["true_noise"]
    return error / wide["true_noise"] if relative else error

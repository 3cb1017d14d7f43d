"""The noise-estimation study (notebook 06): paper A.9 / Table 3, Algorithm 5 on random preferences.

For every true noise level, `repetitions` datasets of `n_preferences` random pairwise preferences are
drawn (`random_preferences`: a true parameter uniform over the candidate range, random pairs of distinct
candidates, each label flipped with probability equal to the true noise) and Algorithm 5 estimates the
fraction of flipped labels under each reading of a conflict (`hipref.learners.noise_estimation.CONFLICTS`),
on the same datasets. Table 3 is the mean estimate per true noise level, one column per reading. Two
estimators beside Algorithm 5 (`hipref.learners.noise_rate`: the maximum marginal likelihood and the
repeated-pair disagreement) estimate from the same datasets; `accuracy` gives each method's bias and error
per level.

The candidates are those of A.9's only example ("0.5m ... than 0.6m"), 0.1 m apart on [0.5, 0.9] m, unless
`candidate_spacing` says otherwise: how often two preferences compare the same pair, hence how many
conflicts the same-pair reading finds, depends on how many candidates there are.

Each dataset takes about a millisecond, so the whole table (7 x 100 datasets, four estimates each) runs in
this process in a few seconds: a pool of workers would cost more in process start-up than it saves.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated, Any

import numpy as np
import pandas as pd

from hipref.experiments.domains import DOMAINS
from hipref.learners.noise_estimation import CONFLICTS, PreferenceSet, estimate_noise
from hipref.learners.noise_rate import likelihood_noise, repeated_pair_noise
from hipref.learners.sysid import CandidateSet
from hipref.results import tidy_rows
from hipref.sweep import run_sweep
from hipref.teachers.preference import pair_labels
from hipref.validation import (
    Integer,
    NonEmptyTuple,
    OneOf,
    Range,
    check_choice,
    check_fields,
    check_int,
    check_range,
)
from hipref.verdicts import bootstrap_mean, trend

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

PAPER_EXAMPLE_SPACING = 0.1
"""A.9's example compares 0.5 m with 0.6 m: desk heights 0.1 m apart, 5 candidates on [0.5, 0.9] m."""

METHODS: dict[str, str] = {conflict: f"algorithm5_{conflict}" for conflict in CONFLICTS}
"""The `method` of the rows of each reading of a conflict."""

ESTIMATED_NOISE_METHODS: dict[str, str] = {
    "co_pesi_estimated": "no_common_parameter",
    "co_pesi_estimated_same_pair": "same_pair",
}
"""Figs. 8-9: the SI methods whose noise level Algorithm 5 estimates (CO-PESI,
`hipref.experiments.si_methods`), each with its reading of a conflict; the paper does not say which one its
figures used."""

ESTIMATORS: dict[str, Callable[[PreferenceSet, CandidateSet], float]] = {
    "marginal_likelihood": lambda preferences, grid: likelihood_noise(preferences, grid.low, grid.high),
    "repeated_pair": lambda preferences, grid: repeated_pair_noise(preferences),
}
"""The estimators beside Algorithm 5 (`hipref.learners.noise_rate`), by the `method` of their rows: they
estimate from the same datasets."""

TABLE3_COLUMNS: tuple[str, ...] = (
    "true_noise",
    "paper_estimated_noise",
    *(f"estimated_noise_{conflict}" for conflict in CONFLICTS),
    *(f"estimated_noise_{conflict}_std" for conflict in CONFLICTS),
)
"""Columns of `table3`: the paper's mean estimate, then this study's under each reading, then the standard
deviations over the repetitions."""


@dataclass(frozen=True)
class NoiseEstimationConfig:
    """Parameters of Table 3 (defaults: the paper's values, which are also the quick profile)."""

    n_preferences: Annotated[int, Integer(2, 100_000)] = 256
    """|D|, preferences per random dataset (A.9: 256)."""
    repetitions: Annotated[int, Integer(1, 100_000)] = 100
    """Random datasets per true noise level (A.9: 100)."""
    noise_levels: NonEmptyTuple[Annotated[float, Range(0.0, 1.0)]] = (0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4)
    """True fractions of flipped labels (Table 3: 0.10 to 0.40 in steps of 0.05)."""
    domain: Annotated[str, OneOf(DOMAINS)] = "wiping"
    """Whose parameter range the preferences are about: 'wiping' (desk height, A.9's example) or 'pushing'."""
    candidate_spacing: float = PAPER_EXAMPLE_SPACING
    """Spacing of the candidates over the domain's whole range, in its unit (m or kg); it must divide the
    range into whole steps. Default: A.9's example, 0.1 m (5 heights on [0.5, 0.9] m; 3.0 kg gives 5 masses
    on [8, 20] kg). The grids the learners see (`hipref.experiments.domains`) are 0.01 m (41 heights)
    and 0.25 kg (49 masses)."""
    seed: Annotated[int, Integer(0)] = 0
    """Root seed; each dataset's generator derives from it, the noise level and the repetition."""

    def __post_init__(self) -> None:
        check_fields(self)
        grid = DOMAINS[self.domain].candidates
        span = grid.high - grid.low
        spacing = self.candidate_spacing
        ok = isinstance(spacing, int | float) and not isinstance(spacing, bool) and 0 < spacing <= span
        if not ok or abs(span / spacing - round(span / spacing)) > 1e-6:
            raise ValueError(
                f"candidate_spacing must be a number in (0, {span:g}] dividing the {self.domain} "
                f"range [{grid.low:g}, {grid.high:g}] into whole steps, got {spacing!r}"
            )

    @property
    def candidates(self) -> CandidateSet:
        """The candidates the random pairs are drawn from."""
        grid = DOMAINS[self.domain].candidates
        return CandidateSet(low=grid.low, high=grid.high, resolution=float(self.candidate_spacing))


def dataset_rng(seed: int, true_noise: float, repetition: int) -> np.random.Generator:
    """The generator of one dataset. Keyed by the noise value (not its position) so that adding or
    dropping a level leaves every other level's datasets unchanged."""
    return np.random.default_rng(np.random.SeedSequence([seed, round(true_noise * 10_000), repetition]))


def random_preferences(
    n: int, true_noise: float, candidates: CandidateSet, rng: np.random.Generator
) -> PreferenceSet:
    """The A.9 / Table 3 dataset: n random pairs of distinct candidates, labelled by nearness to a true
    parameter drawn uniformly from the candidate range, each label flipped with probability true_noise.

    The labels follow the scripted teacher's rule (`pair_labels`, ties broken at random), on all pairs at
    once.
    """
    check_int("n", n, 1)
    check_range("true_noise", true_noise, 0.0, 1.0)
    values = candidates.values
    first_index = rng.integers(len(values), size=n)
    # Uniform over the other len(values) - 1 candidates: draw from one fewer and skip first_index.
    second_index = rng.integers(len(values) - 1, size=n)
    second_index += second_index >= first_index
    first, second = values[first_index], values[second_index]
    true_parameter = rng.uniform(candidates.low, candidates.high)
    nearer, tied = pair_labels(first, second, true_parameter)
    tie_break = np.where(rng.random(n) < 0.5, 1, -1)
    label = np.where(tied, tie_break, nearer)
    flipped = rng.random(n) < true_noise
    label[flipped] *= -1
    return PreferenceSet(first=first, second=second, label=label)


@dataclass(frozen=True)
class NoiseLevelCell:
    """The datasets of one true noise level (a sweep cell)."""

    config: NoiseEstimationConfig
    true_noise: float


def run_noise_level(cell: NoiseLevelCell) -> pd.DataFrame:
    """Tidy rows of one true noise level: per dataset and reading of a conflict, `estimated_noise`
    (Algorithm 5) and `true_noise`. `seed` is the repetition number; with `config.seed` it determines the
    dataset (`dataset_rng`); `n_candidates` is the size of the grid."""
    config, true_noise = cell.config, cell.true_noise
    candidates = config.candidates
    rows = []
    for repetition in range(config.repetitions):
        rng = dataset_rng(config.seed, true_noise, repetition)
        preferences = random_preferences(config.n_preferences, true_noise, candidates, rng)
        estimates = {method: estimate_noise(preferences, conflict) for conflict, method in METHODS.items()}
        estimates |= {method: estimate(preferences, candidates) for method, estimate in ESTIMATORS.items()}
        for method, estimate in estimates.items():
            for metric, value in (("estimated_noise", estimate), ("true_noise", true_noise)):
                rows.append((method, float(true_noise), repetition, metric, float(value)))
    return tidy_rows(
        rows,
        ("method", "noise", "seed", "metric", "value"),
        domain=config.domain,
        episode=0,
        n_candidates=candidates.size,
    )


def run(config: NoiseEstimationConfig, **sweep: Any) -> pd.DataFrame:
    """Every true noise level's rows (`run_noise_level`); both readings (`METHODS`) estimate from the same
    datasets. A level takes a fraction of a second, so the sweep runs in this process unless `sweep` asks
    for workers."""
    cells = [NoiseLevelCell(config, float(level)) for level in config.noise_levels]
    return run_sweep(run_noise_level, cells, desc="Table 3", **{"workers": 1, **sweep})


def summarise(rows: pd.DataFrame) -> pd.DataFrame:
    """Table 3 from tidy rows: per true noise level, the mean and standard deviation of each reading's
    estimate (NaN for a reading the rows lack), beside the paper's mean estimate."""
    estimates = rows[rows["metric"] == "estimated_noise"].groupby(["noise", "method"])["value"]
    stats = pd.DataFrame({"mean": estimates.mean(), "std": estimates.std(ddof=1)}).unstack("method")
    table = pd.DataFrame({"true_noise": stats.index.to_numpy(dtype=float)})
    table["paper_estimated_noise"] = [
        next((v for k, v in PAPER_TABLE3.items() if np.isclose(k, t)), np.nan) for t in table["true_noise"]
    ]
    for conflict, method in METHODS.items():
        for stat, suffix in (("mean", ""), ("std", "_std")):
            column = stats[stat].get(method, np.nan)
            table[f"estimated_noise_{conflict}{suffix}"] = np.asarray(column, dtype=float)
    return table[list(TABLE3_COLUMNS)]


ACCURACY_COLUMNS: tuple[str, ...] = (
    "true_noise",
    "method",
    "bias",
    "bias_low",
    "bias_high",
    "rmse",
    "datasets",
)
"""Columns of `accuracy`."""


def accuracy(rows: pd.DataFrame, *, resamples: int = 2000, seed: int = 0) -> pd.DataFrame:
    """Per method and true noise level: the bias (mean of estimate - true noise over the datasets) with a
    95% bootstrap interval, and the root mean squared error. A dataset an estimator cannot read (the
    repeated-pair estimator without a repeated pair) is left out of its method's figures."""
    table = []
    for (method, noise), group in rows.groupby(["method", "noise"], sort=True):
        error = _per_dataset(group, relative=False).dropna().to_numpy()
        if len(error) == 0:
            continue
        bias = bootstrap_mean(error, resamples=resamples, seed=seed)
        rmse = float(np.sqrt(np.mean(error**2)))
        table.append((float(noise), method, bias.mean, bias.low, bias.high, rmse, len(error)))
    return pd.DataFrame(table, columns=list(ACCURACY_COLUMNS))


def table3(config: NoiseEstimationConfig) -> pd.DataFrame:
    """Table 3 regenerated: columns `TABLE3_COLUMNS`, one row per true noise level."""
    return summarise(run(config))


def paper_distance(table: pd.DataFrame) -> dict[str, float]:
    """Per reading of a conflict, the mean over the paper's noise levels of |study - paper| in Table 3."""
    listed = table[table["paper_estimated_noise"].notna()]
    if listed.empty:
        raise ValueError(f"table holds none of the paper's noise levels {sorted(PAPER_TABLE3)}")
    paper = listed["paper_estimated_noise"].to_numpy()
    return {
        conflict: float(np.mean(np.abs(listed[f"estimated_noise_{conflict}"].to_numpy() - paper)))
        for conflict in CONFLICTS
    }


def overestimate(
    rows: pd.DataFrame, *, method: str | None = None, resamples: int = 2000, seed: int = 0
) -> tuple[float, float, float]:
    """Mean of (estimate - true noise) over all datasets and levels, with a 95% bootstrap interval over
    datasets resampled within each level, so every level keeps its weight (`hipref.verdicts.bootstrap_mean`).

    `method`: the reading whose estimates are used (a value of `METHODS`); None if the rows hold one only.
    """
    bias = _per_dataset(_one_method(rows, method), relative=False)
    result = bootstrap_mean(
        bias.to_numpy(),
        strata=bias.index.get_level_values("noise").to_numpy(),
        resamples=resamples,
        seed=seed,
    )
    return result.mean, result.low, result.high


def error_trend(
    rows: pd.DataFrame,
    *,
    relative: bool = True,
    method: str | None = None,
    resamples: int = 2000,
    seed: int = 0,
) -> tuple[float, float, float]:
    """Least-squares slope of the per-dataset error on the true noise, with its 95% bootstrap interval
    (`hipref.verdicts.trend`: datasets resampled within each level). `relative`: (estimate - true) / true;
    otherwise the absolute error |estimate - true|. A negative slope means the estimate gets better as the
    true noise grows. `method` as in `overestimate`."""
    error = _per_dataset(_one_method(rows, method), relative=relative)
    if not relative:
        error = error.abs()
    frame = error.rename("error").reset_index()
    result = trend(
        frame,
        x="noise",
        y="error",
        units=("noise", "seed"),
        strata=("noise",),
        resamples=resamples,
        seed=seed,
    )
    return result.slope, result.low, result.high


def _one_method(rows: pd.DataFrame, method: str | None) -> pd.DataFrame:
    """The rows of one reading; refuses to mix readings, whose estimates differ on the same datasets."""
    present = sorted(rows["method"].unique()) if "method" in rows.columns else []
    if method is None:
        if len(present) > 1:
            raise ValueError(
                f"rows hold several readings {present}; choose one with method=, one of {present}"
            )
        return rows
    check_choice("method", method, present)
    return rows[rows["method"] == method]


def _per_dataset(rows: pd.DataFrame, *, relative: bool) -> pd.Series:
    """estimate - true (or divided by true) per dataset, indexed by (noise, seed)."""
    wide = rows.pivot_table(index=["noise", "seed"], columns="metric", values="value")
    if relative:
        # A relative error is undefined at zero true noise.
        wide = wide[wide["true_noise"] > 0]
    error = wide["estimated_noise"] - wide["true_noise"]
    return error / wide["true_noise"] if relative else error

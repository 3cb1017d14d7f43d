"""The README's findings on noisy preferences (notebooks 04, 06 and 11): CO-PESI against PESI, the flip
rate's estimators, learners robust to other teachers and Table 3, each number and verdict read from `results/`
and decided by `hipref.verdicts` as the notebooks decide it."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from hipref import verdicts
from hipref.experiments.noise_estimation import ESTIMATED_NOISE_METHODS, overestimate, paper_distance
from hipref.experiments.r3_copesi import final_difference
from hipref.experiments.robustness import NOISE_TOLERANCE, best_learner, noise_table
from hipref.readme_format import FINE_UNITS, UNITS, WORDS, csv, interval, percent, signed


def _final(
    rows: pd.DataFrame, domain: str, noise: float, metric: str, baseline: str = "pesi"
) -> verdicts.Difference:
    """CO-PESI minus `baseline` at the last evaluation (`final_difference`)."""
    return verdicts.Difference(*final_difference(rows, domain, noise, metric, baseline=baseline))


PAPER_LEVELS: tuple[float, ...] = (0.1, 0.2)
"""The flip rates at which the paper says CO-PESI beats PESI (Figs. 3, 5)."""

CONFLICT_WORDS: dict[str, str] = {
    "no_common_parameter": "two preferences no parameter satisfies",
    "same_pair": "opposite answers to the same pair",
}
"""Each reading of a conflict (`hipref.learners.noise_estimation.CONFLICTS`) in words."""

FLIP_BIAS = 0.02
"""Notebook 06's bar: a flip rate estimator's bias within this at every level."""


def _levels(
    rows: pd.DataFrame, domain: str, metric: str, baseline: str = "pesi"
) -> dict[float, verdicts.Difference]:
    """CO-PESI minus `baseline` at the last evaluation, per flip rate of `domain`."""
    at = rows[rows["domain"] == domain]
    return {
        float(e): _final(at, domain, float(e), metric, baseline)
        for e in sorted(at["noise"].unique())
        if e > 0
    }


HORIZONS: tuple[int, ...] = (99, 198, 330)
"""The learning episodes after which the README reads CO-PESI against PESI (the paper gives no horizon)."""


def _horizons(rows: pd.DataFrame) -> str:
    """Per domain and flip rate, 'CO-PESI lowers the error' read after each of HORIZONS that was evaluated."""
    evaluated = [n for n in HORIZONS if n in set(rows["episode"])]
    parts = []
    for domain in UNITS:
        at = rows[rows["domain"] == domain]
        cells = []
        for level in sorted(e for e in at["noise"].unique() if e > 0):
            said = [
                verdicts.better(
                    verdicts.Difference(*final_difference(at, domain, level, "param_error", episode=n)),
                    lower_is_better=True,
                )
                for n in evaluated
            ]
            cells.append(f"at {percent(level)} {' / '.join(said)}")
        parts.append(f"in {domain} " + ", ".join(cells))
    return f"read after {' / '.join(map(str, evaluated))} episodes, is " + "; ".join(parts)


def _copesi(results: Path) -> dict[str, str]:
    rows = csv(results, "data/04_r3_copesi.csv")
    filters = csv(results, "tables/04_filter_quality.csv")
    estimated = csv(results, "data/06_copesi_estimated.csv")
    out: dict[str, str] = {}
    held = []
    for domain, (unit, scale, digits) in UNITS.items():
        errors, success = _levels(rows, domain, "param_error"), _levels(rows, domain, "success_rate")
        cells = []
        for level, d in errors.items():
            better = verdicts.better(d, lower_is_better=True)
            if any(abs(level - e) < 1e-9 for e in PAPER_LEVELS):
                held.append(better)
            cells.append(
                f"at {percent(level)} {interval(d, unit, digits + 1, scale)}: {better} "
                f"(success {signed(success[level].mean, 2)})"
            )
        out[f"co_{domain}"] = "; ".join(cells)
    told = []
    for baseline, conflict in ESTIMATED_NOISE_METHODS.items():
        cells = []
        for domain in sorted(estimated["domain"].unique()):
            unit, scale, digits = UNITS[domain]
            for level, d in _levels(estimated, domain, "param_error", baseline=baseline).items():
                same = verdicts.no_difference(d)
                cells.append(f"{domain} at {percent(level)} {interval(d, unit, digits + 1, scale)}: {same}")
        told.append(f"a conflict read as {CONFLICT_WORDS[conflict]}: " + "; ".join(cells))
    return {
        **out,
        "co_verdict": WORDS[verdicts.combine(held)],
        "co_paper_levels": " and ".join(percent(e) for e in PAPER_LEVELS),
        "co_episodes": str(int(rows["episode"].max())),
        "co_horizons": _horizons(rows),
        "precision_low": f"{filters['filter_precision'].min():.2f}",
        "precision_high": f"{filters['filter_precision'].max():.2f}",
        "recall_low": f"{filters['filter_recall'].min():.2f}",
        "recall_high": f"{filters['filter_recall'].max():.2f}",
        "chance_low": f"{filters['noise'].min():.1f}",
        "chance_high": f"{filters['noise'].max():.1f}",
        "copesi_levels": f"{percent(filters['noise'].min())[:-2]}-{percent(filters['noise'].max())}",
        "copesi_highest": percent(filters["noise"].max()),
        "estimated_told": "; ".join(told),
        "estimated_episodes": str(int(estimated["episode"].max())),
    }


def _flip_rates(results: Path) -> dict[str, str]:
    table = csv(results, "tables/06_noise_rate_estimators.csv")
    out = {"flip_bar": f"{FLIP_BIAS:.2f}"}
    for method, name in (("marginal_likelihood", "likelihood"), ("repeated_pair", "repeated")):
        levels = table[table["method"] == method]
        within = [
            verdicts.within(
                verdicts.Difference(r.bias, r.bias_low, r.bias_high, int(r.datasets)), -FLIP_BIAS, FLIP_BIAS
            )
            for r in levels.itertuples()
        ]
        worst = levels.loc[levels["bias"].abs().idxmax()]
        d = verdicts.Difference(worst["bias"], worst["bias_low"], worst["bias_high"], int(worst["datasets"]))
        out[f"{name}_verdict"] = verdicts.combine(within)
        out[f"{name}_bias"] = interval(d, "", 3)
        out[f"{name}_level"] = f"{worst['true_noise']:.2f}"
        out["levels_low"] = f"{levels['true_noise'].min():.1f}"
        out["levels_high"] = f"{levels['true_noise'].max():.1f}"
    return out


LEARNERS = {
    "co_pesi_likelihood": "co-teaching with the likelihood rate",
    "pesi_smoothed": "label smoothing",
    "pesi_unbiased": "the unbiased loss",
    "pesi_small_loss": "the small-loss filter",
    "pesi_rime": "RIME's trust-and-flip",
}
"""How the README names notebook 11's learners."""

TIMES = {0: "never", 1: "once", 2: "twice"}


def _robust(results: Path) -> dict[str, str]:
    table = csv(results, "tables/11_teachers_and_robustness.csv")
    settings = table[["domain", "teacher"]].drop_duplicates()
    held, significant = [], []
    ahead: dict[str, float] = {}
    for domain, teacher in settings.itertuples(index=False):
        learner, verdict, _ = best_learner(table, domain, teacher)
        held.append(verdict)
        error = table[(table["domain"] == domain) & (table["teacher"] == teacher)]
        error = error[(error["method"] == learner) & (error["metric"] == "param_error")].iloc[0]
        ahead[domain] = max(ahead.get(domain, 0.0), -float(error["mean"]))
        d = verdicts.Difference(error["mean"], error["low"], error["high"], int(error["n"]))
        if verdicts.better(d, lower_is_better=True) == "yes":
            unit, scale, digits = FINE_UNITS[domain]
            setting = f"{LEARNERS[learner]} under the {teacher} teacher, {domain}"
            significant.append(f"{setting}: {interval(d, unit, digits, scale)}")
    noise = noise_table(csv(results, "data/11_teachers_and_robustness.csv"))
    recovered = noise.groupby("teacher", sort=False)["recovered"].agg(list).map(verdicts.combine)
    missed = [
        f"the {teacher} teacher's ({held}; bias "
        + ", ".join(
            f"{signed(r.bias, 3)} in {r.domain}" for r in noise[noise["teacher"] == teacher].itertuples()
        )
        + ")"
        for teacher, held in recovered.items()
        if held != verdicts.YES
    ]
    return {
        "robust_verdict": WORDS[verdicts.any_of(held)],
        "robust_teachers": str(table["teacher"].nunique()),
        "robust_learners": str(table["method"].nunique()),
        "robust_environments": str(int(table["n"].min())),
        "robust_both": f"{held.count('yes')} of {len(held)}",
        "robust_ahead_wiping": f"{1000 * ahead['wiping']:.1f}",
        "robust_ahead_pushing": f"{ahead['pushing']:.2f}",
        "robust_times": TIMES.get(len(significant), f"{len(significant)} times"),
        "robust_significant": "; ".join(significant),
        "noise_tolerance": f"{NOISE_TOLERANCE:.2f}",
        "recovered": f"{(recovered == verdicts.YES).sum()} of {len(recovered)}",
        "not_recovered": "; ".join(missed) or "none",
    }


def _table3(results: Path) -> dict[str, str]:
    rows = csv(results, "data/06_noise_estimation.csv")
    table = csv(results, "tables/table3.csv")
    means = {}
    for conflict in ("same_pair", "no_common_parameter"):
        mean, low, high = overestimate(rows, method=f"algorithm5_{conflict}")
        means[conflict] = verdicts.Difference(mean, low, high, int((rows["metric"] == "true_noise").sum()))
    same = means["same_pair"]
    listed = table[table["paper_estimated_noise"].notna()]
    miss = (listed["estimated_noise_same_pair"] - listed["paper_estimated_noise"]).abs()
    worst = listed.loc[miss.idxmax()]
    return {
        "alg5_verdict": WORDS[verdicts.within(same, 0.04, 0.08)],
        "alg5_same_pair": f"{signed(100 * same.mean, 1)} % (CI {100 * same.low:.1f}-{100 * same.high:.1f})",
        "alg5_common": f"{signed(100 * means['no_common_parameter'].mean, 1)} %",
        "alg5_distance": f"{paper_distance(table)['same_pair']:.3f}",
        "alg5_miss": signed(worst["estimated_noise_same_pair"] - worst["paper_estimated_noise"], 3),
        "alg5_miss_level": f"{worst['true_noise']:.2f}",
    }


def values(results: Path) -> dict[str, str]:
    """Every placeholder of the findings on noisy preferences."""
    return {**_copesi(results), **_flip_rates(results), **_robust(results), **_table3(results)}

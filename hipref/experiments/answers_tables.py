"""Notebook 12's tables read from its answers part: the answers each setting needs to reach one grid step
of Phi (`answers_to_step`) beside the Shannon floor (`shannon_floor`), PESI's information efficiency
(`efficiency`) and what not being told the teacher's model costs (`told_against_chosen`)."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from hipref.experiments.domains import domain_spec
from hipref.learners.answer_models import TOLD
from hipref.validation import check_int, check_range

CONSISTENT = 0.9
"""'Reaches one grid step' means: in at least this share of the environments."""


def shannon_floor(candidates: int, flip: float) -> float:
    """log2(K) / (1 - h(e)): the fewest answers, each wrong with probability e, that can single out one of K
    candidates (each answer carries at most the capacity 1 - h(e) bits of a binary symmetric channel)."""
    check_int("candidates", candidates, 2)
    check_range("flip", flip, 0.0, 0.5 - 1e-9)
    entropy = 0.0 if flip == 0 else -flip * math.log2(flip) - (1 - flip) * math.log2(1 - flip)
    return math.log2(candidates) / (1.0 - entropy)


SETTING = ["domain", "teacher", "noise", "query_rule", "told"]
"""What one curve of the answers part is the curve of."""


def answers_to_step(rows: pd.DataFrame, share: float = CONSISTENT) -> pd.DataFrame:
    """Per setting of the answers part, the answers after which the error is within one step of Phi (1 cm,
    0.25 kg) in at least `share` of the environments and stays so up to the last answer (NaN if never),
    with its 95 % interval (`low`, `high`: `answers_interval`) and the number of truths it resamples,
    beside the Shannon floor for the paper's teacher (`shannon_floor`, K = |Phi|, e its flip rate) and
    their ratio."""
    out = []
    for setting, group in answer_errors(rows).groupby(SETTING, sort=False):
        domain, teacher, noise = setting[0], setting[1], float(setting[2])
        within, counts = within_step(group, str(domain))
        reached = float(first_for_good(within[None], counts, share)[0])
        reached = reached if math.isfinite(reached) else np.nan
        low, high = answers_interval(group, share)
        truths = group["ground_truth"].nunique()
        floor = (
            shannon_floor(domain_spec(str(domain)).candidates.size, noise) if teacher == "mistake" else np.nan
        )
        out.append((*setting, len(within), truths, reached, low, high, floor, reached / floor))
    columns = [*SETTING, "environments", "truths", "answers", "low", "high", "floor", "ratio"]
    return pd.DataFrame(out, columns=columns)


def answers_interval(
    errors: pd.DataFrame, share: float = CONSISTENT, resamples: int = 2000, seed: int = 0
) -> tuple[float, float]:
    """Of one curve's `answer_errors`: a 95 % percentile interval of its answers to one step
    (`answers_to_step`), the truths resampled with replacement, each with all its seeds (`truth_draws`); a
    resample that never gets within one step counts as infinite. NaN bounds with fewer than two truths or
    where the environments are not a grid of truths x seeds (a run missing), which resampling truths whole
    needs."""
    wide = _by_environment(errors)
    within, counts = _within(wide, str(errors["domain"].iloc[0]))
    environments = _environments(wide)
    truths = [truth for truth, _ in environments]
    if len(set(truths)) < 2 or not _is_grid(truths):
        return np.nan, np.nan
    counted = first_for_good(within[truth_draws(environments, resamples, seed)], counts, share)
    low, high = np.quantile(counted, [0.025, 0.975], method="inverted_cdf")
    return float(low), float(high)


def truth_draws(environments: list[tuple[float, int]], resamples: int, seed: int) -> np.ndarray:
    """(resamples, environments) indices into `environments` ((truth, seed), in `within_step`'s order): the
    truths drawn with replacement, each with all its seeds (with perfect answers the seeds of a truth are
    copies of one environment, so resampling them apart would feign certainty)."""
    truths = np.array([truth for truth, _ in environments])
    if not _is_grid(list(truths)):
        raise ValueError("the environments must be a grid of truths x seeds (as many seeds for every truth)")
    clusters = np.stack([np.flatnonzero(truths == t) for t in np.unique(truths)])
    picked = np.random.default_rng(seed).integers(len(clusters), size=(resamples, len(clusters)))
    return clusters[picked].reshape(resamples, -1)


def _is_grid(truths: list[float]) -> bool:
    """Whether every truth of the environments has as many seeds."""
    return len(set(pd.Series(truths).value_counts())) == 1


def answer_errors(rows: pd.DataFrame) -> pd.DataFrame:
    """The answers part's rows of the estimate's error."""
    return rows[(rows["part"] == "answers") & (rows["metric"] == "param_error")]


def within_step(errors: pd.DataFrame, domain: str) -> tuple[np.ndarray, np.ndarray]:
    """Of one curve's `answer_errors`: (environments, checkpoints) whether each environment's error is within
    one step of Phi, its environments ordered by (truth, seed); and the checkpoints' answer counts."""
    return _within(_by_environment(errors), domain)


def _within(wide: pd.DataFrame, domain: str) -> tuple[np.ndarray, np.ndarray]:
    """`within_step` of a curve already as (environments, checkpoints) (`_by_environment`)."""
    step = domain_spec(domain).candidates.resolution * (1 + 1e-9)
    return wide.to_numpy() <= step, wide.columns.to_numpy(dtype=float)


def _by_environment(errors: pd.DataFrame) -> pd.DataFrame:
    """One curve's errors as (environments ordered by (truth, seed), checkpoints)."""
    return errors.pivot_table(index=["ground_truth", "seed"], columns="episode", values="value")


def first_for_good(within: np.ndarray, counts: np.ndarray, share: float = CONSISTENT) -> np.ndarray:
    """Per set of environments in (sets, environments, checkpoints) `within` (`within_step`), the answers
    after which at least `share` of them are within one step up to the last checkpoint: the count after the
    last one that falls short (inf if the last does)."""
    short = within.mean(axis=1) < share
    last_short = np.where(short.any(axis=1), short.shape[1] - 1 - np.argmax(short[:, ::-1], axis=1), -1)
    return np.append(counts, np.inf)[last_short + 1]


def efficiency(rows: pd.DataFrame) -> pd.DataFrame:
    """PESI's information efficiency: per domain and flip rate of both parts, for each checkpoint n of the
    task part, the fewest answers m after which the Bayesian learner (uniform queries, told the flip rate as
    PESI is) has a mean error at most PESI's mean error after n (same environments, uniform queries), and
    m / n."""
    task = rows[
        (rows["part"] == "task") & (rows["metric"] == "param_error") & (rows["query_rule"] == "uniform")
    ]
    answers = rows[
        (rows["part"] == "answers")
        & (rows["metric"] == "param_error")
        & (rows["teacher"] == "mistake")
        & (rows["query_rule"] == "uniform")
        & (rows["told"] == "model")
    ]
    out = []
    for (domain, noise), pesi in task[task["method"] == "pesi"].groupby(["domain", "noise"], sort=False):
        bayes = answers[(answers["domain"] == domain) & (answers["noise"] == noise)]
        if bayes.empty:
            continue
        curve = bayes.groupby("episode")["value"].mean()
        for n, error in pesi[pesi["episode"] > 0].groupby("episode")["value"].mean().items():
            matched = curve.index[curve.to_numpy() <= error]
            m = float(matched[0]) if matched.size else np.nan
            out.append((domain, noise, int(n), float(error), m, m / int(n)))
    return pd.DataFrame(
        out, columns=["domain", "noise", "answers", "pesi_error", "bayes_answers", "efficiency"]
    )


def told_against_chosen(steps: pd.DataFrame, rows: pd.DataFrame) -> pd.DataFrame:
    """Per domain, teacher and flip rate under information gain: the answers to one step (`answers_to_step`)
    and the mean error at the last answer of the learner told the teacher's kind only and of the one told
    nothing (every model weighed by its marginal likelihood), each against the learner told the true
    model: `kind_ratio`, `nothing_ratio` divide the answers (inf where only the learner not told never gets
    within one step), or where the told learner never gets there, the final errors; `kind_low`,
    `kind_high`, `nothing_low`, `nothing_high` bound each ratio (`ratio_interval`). Settings with the told
    learner alone (`blind_noise_levels`) are left out."""
    keys = ["domain", "teacher", "noise"]
    ig = steps[steps["query_rule"] == "information_gain"]
    blind = ig[ig["told"] != "model"].set_index(keys).index
    ig = ig[ig.set_index(keys).index.isin(blind)]
    answers = ig.pivot(index=keys, columns="told", values="answers")
    errors = answer_errors(rows)
    errors = errors[errors["query_rule"] == "information_gain"]
    last = errors[errors["episode"] == errors["episode"].max()]
    final = last.groupby([*keys, "told"])["value"].mean().unstack("told")
    out = answers.join(final.add_suffix("_error")).reindex(columns=[*TOLD, *(f"{t}_error" for t in TOLD)])
    reached = out["model"].notna()
    settings = dict(iter(errors.groupby(keys, sort=False)))
    for told_ in ("kind", "nothing"):
        never = reached & out[told_].isna() & out[f"{told_}_error"].notna()  # it ran, never within a step
        out[f"{told_}_ratio"] = np.where(
            never,
            np.inf,
            np.where(reached, out[told_] / out["model"], out[f"{told_}_error"] / out["model_error"]),
        )
        bounds = [
            ratio_interval(settings[key], told_, bool(by_answers)) if key in settings else (np.nan, np.nan)
            for key, by_answers in reached.items()
        ]
        out[f"{told_}_low"], out[f"{told_}_high"] = [b[0] for b in bounds], [b[1] for b in bounds]
    out["compared"] = np.where(reached, "answers", "final error")
    return out.reset_index()


def ratio_interval(
    errors: pd.DataFrame, told_: str, by_answers: bool, resamples: int = 2000, seed: int = 0
) -> tuple[float, float]:
    """Of one setting's `answer_errors` under one query rule: a 95 % percentile interval of the learner told
    `told_`'s answers to one step (`by_answers`) or mean final error over the learner told the model's. The
    truths are resampled with all their seeds (`truth_draws`), the same draw for both learners (they share
    truths, seeds and teacher draws). Counting answers, a resample where only the learner told `told_` never
    gets there counts as an infinite ratio, where only the told learner never does as zero, and where
    neither does it is left out; NaN bounds when every resample is, or without either learner."""
    model, other = errors[errors["told"] == "model"], errors[errors["told"] == told_]
    if model.empty or other.empty:
        return np.nan, np.nan
    wide_model, wide_other = _by_environment(model), _by_environment(other)
    environments = _environments(wide_model)
    if environments != _environments(wide_other):
        raise ValueError(
            f"the learners told the model and told {told_!r} must be run on the same environments"
        )
    draws = truth_draws(environments, resamples, seed)
    domain = str(errors["domain"].iloc[0])
    within_model, counts = _within(wide_model, domain)
    within_other, _ = _within(wide_other, domain)
    final_model, final_other = wide_model.to_numpy()[:, -1], wide_other.to_numpy()[:, -1]
    with np.errstate(divide="ignore", invalid="ignore"):  # neither there: NaN, left out
        if by_answers:
            ratios = first_for_good(within_other[draws], counts) / first_for_good(within_model[draws], counts)
        else:
            ratios = final_other[draws].mean(axis=1) / final_model[draws].mean(axis=1)
    ratios = ratios[~np.isnan(ratios)]
    if not ratios.size:
        return np.nan, np.nan
    low, high = np.quantile(ratios, [0.025, 0.975], method="inverted_cdf")
    return float(low), float(high)


def _environments(wide: pd.DataFrame) -> list[tuple[float, int]]:
    """The (truth, seed) of every environment of a curve as `_by_environment` gives it, in its order."""
    return [(float(truth), int(seed)) for truth, seed in wide.index]

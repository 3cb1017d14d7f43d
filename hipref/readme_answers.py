"""The README's finding of notebook 12 (what the Bayesian learner takes from the same answers as PESI), each
number and verdict read from `results/` as `hipref.readme` reads the paper's: from notebook 12's tables, and
where it prints a measurement without writing one (its task bars), recomputed from `results/data/` by the
notebook's own code path (`hipref.verdicts`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from hipref import verdicts
from hipref.experiments.answers_tables import CONSISTENT, answers_to_step, told_against_chosen
from hipref.experiments.answers_to_success import (
    MODEL_CHOICE_BOUND,
    STEP_BOUNDS,
    SUCCESS_AFTER,
    SUCCESS_BARS,
    SUCCESS_SHORTFALL,
)
from hipref.experiments.domains import DOMAINS
from hipref.readme_format import UNITS, WORDS, in_domains, interval, percent, ran_with


def _claims_verdicts(results: Path, section: str) -> list[str]:
    """The 'Holds' column of one notebook's section of `results/claims.md`."""
    text = (results / "claims.md").read_text(encoding="utf-8")
    body = text.split(f"<!-- section: {section} -->", 1)[1].split(f"<!-- end: {section} -->", 1)[0]
    lines = [line for line in body.splitlines() if line.startswith("|")][2:]
    return [line.rstrip(" |").rsplit("|", 1)[1].strip() for line in lines]


FLIPS = 0.2
"""The flip rate of the paper's teacher at which notebook 12 sets its bars beside perfect answers."""

GAP_FACTOR = 4
"""Notebook 12's bar: the Bayesian learner's error at least this many times below PESI's."""


def _count(step: pd.Series) -> str:
    """A row of `answers_to_step`: its answers to one step and their 95 % interval."""
    answers = f"{step['answers']:g}" if np.isfinite(step["answers"]) else "never"
    return f"{answers} (CI {step['low']:g}-{step['high']:g})" if np.isfinite(step["low"]) else answers


def values(results: Path) -> dict[str, str]:
    """Notebook 12: what an exact Bayesian learner takes from the same answers as PESI."""
    steps = pd.read_csv(results / "tables" / "12_answers_to_step.csv")
    efficiency = pd.read_csv(results / "tables" / "12_efficiency.csv")
    every_row = pd.read_csv(results / "data" / "12_answers_to_success.csv")
    rows, held_out = (every_row[every_row["grid"] == grid] for grid in ("study", "held_out"))
    params = ran_with(results, "12_answers_to_success")
    task = rows[(rows["part"] == "task") & rows["metric"].isin(["param_error", "success_rate"])]
    ig = steps[(steps["teacher"] == "mistake") & (steps["query_rule"] == "information_gain")]
    held = _claims_verdicts(results, "12_answers_to_success")
    checkpoint = max(c for c in params["checkpoints"] if c <= 99)
    out = {
        "nb12_met": f"{held.count(verdicts.YES)} of the {len(held)}",
        "nb12_consistent": percent(CONSISTENT),
        "nb12_environments": str(int(steps["environments"].min())),
        "nb12_checkpoint": str(checkpoint),
        "nb12_after": str(SUCCESS_AFTER),
        "nb12_factor": str(GAP_FACTOR),
        "nb12_chosen_bar": f"{MODEL_CHOICE_BOUND:g}",
        "nb12_teachers": str(steps["teacher"].nunique()),
        "nb12_step": in_domains(
            {d: f"{s.candidates.resolution * UNITS[d][1]:g}{UNITS[d][0]}" for d, s in DOMAINS.items()}
        ),
    }
    for noise, key in ((0.0, "0"), (FLIPS, "20")):
        at = ig[(ig["noise"] == noise) & (ig["told"] == "kind")].set_index("domain")
        out[f"nb12_kind{key}"] = in_domains({d: _count(at.loc[d]) for d in DOMAINS})
        out[f"nb12_floor{key}"] = in_domains({d: f"{at.loc[d, 'floor']:.1f}" for d in DOMAINS})
        out[f"nb12_ratio{key}"] = in_domains({d: f"{at.loc[d, 'ratio']:.2f}" for d in DOMAINS})
        out[f"nb12_bar{key}"] = str(STEP_BOUNDS[noise])
    out["nb12_flips"] = percent(FLIPS)
    gaps, errors, success, pesi_success, prior = [], {}, {}, {}, {}
    truth_success: dict[str, str] = {}
    truth_gap: dict[tuple[str, str], str] = {}
    for domain in DOMAINS:
        unit, scale, digits = UNITS[domain]
        perfect = task[(task["domain"] == domain) & (task["noise"] == 0.0)]
        uniform = perfect[perfect["query_rule"] == "uniform"]
        final = uniform[(uniform["metric"] == "param_error") & (uniform["episode"] == checkpoint)]
        means = final.groupby("method")["value"].mean()
        errors[domain] = f"{scale * means['bayes']:.2g}{unit} against {scale * means['pesi']:.2g}{unit}"
        scaled = uniform.assign(
            value=np.where(uniform["method"] == "bayes", GAP_FACTOR * uniform["value"], uniform["value"])
        )
        gap = verdicts.paired_difference(
            scaled, metric="param_error", method="bayes", baseline="pesi", episode=checkpoint
        )
        gaps.append(verdicts.better(gap, lower_is_better=True))
        out["nb12_gap_n"] = str(gap.n)
        share = efficiency[(efficiency["domain"] == domain) & (efficiency["noise"] == 0.0)]
        out[f"nb12_efficiency_{domain}"] = (
            f"{share.loc[share['answers'] == checkpoint, 'bayes_answers'].iloc[0]:g}"
        )
        chosen = task[(task["domain"] == domain) & (task["query_rule"] == "information_gain")]
        truth_success[domain] = _truth_success(task, domain)
        for noise, key in ((0.0, "0"), (FLIPS, "20")):
            success[(domain, key)], truth_gap[(domain, key)] = _success(task, domain, noise)
            if noise == 0.0:
                # PESI asks Algorithm 2's uniform pairs only.
                pesi = uniform[(uniform["method"] == "pesi") & (uniform["metric"] == "success_rate")]
                pesi_success[domain] = f"{pesi[pesi['episode'] == SUCCESS_AFTER]['value'].mean():.2f}"
        started = chosen[(chosen["noise"] == 0.0) & chosen["method"].isin(["bayes", "bayes_si"])]
        d = verdicts.paired_difference(
            started, metric="param_error", method="bayes_si", baseline="bayes", episode=SUCCESS_AFTER
        )
        prior[domain] = f"{interval(d, unit, digits, scale)}: {verdicts.better(d, lower_is_better=True)}"
    out["nb12_errors"] = in_domains(errors)
    out["nb12_gap"] = verdicts.combine(gaps)
    out["nb12_verdict"] = WORDS[out["nb12_gap"]]
    for key in ("0", "20"):
        out[f"nb12_success{key}"] = in_domains({d: success[(d, key)] for d in DOMAINS})
        out[f"nb12_truth_gap{key}"] = in_domains({d: truth_gap[(d, key)] for d in DOMAINS})
    out["nb12_truth_success"] = in_domains(truth_success)
    out["nb12_shortfall"] = f"{SUCCESS_SHORTFALL:.2f}"
    out["nb12_pesi_success"] = in_domains(pesi_success)
    out["nb12_prior"] = in_domains(prior)
    out.update(_model_choice(steps, rows))
    out.update(_held_out_answers(held_out[held_out["part"] == "answers"]))
    held_task = held_out[(held_out["part"] == "task") & (held_out["metric"] == "success_rate")]
    out["nb12_held_truth_success"] = in_domains({d: _truth_success(held_task, d) for d in DOMAINS})
    for noise, key in ((0.0, "0"), (FLIPS, "20")):
        read = {d: _success(held_task, d, noise) for d in DOMAINS}
        out[f"nb12_held_success{key}"] = in_domains({d: rate for d, (rate, _) in read.items()})
        out[f"nb12_held_truth_gap{key}"] = in_domains({d: gap for d, (_, gap) in read.items()})
    return out


def _truth_success(task: pd.DataFrame, domain: str) -> str:
    """The task's success rate with the true parameter on the episodes of the success bars' checkpoint."""
    exact = task[(task["domain"] == domain) & (task["method"] == "true_parameter")]
    truth = exact[(exact["metric"] == "success_rate") & (exact["episode"] == SUCCESS_AFTER)]
    return f"{truth['value'].mean():.2f}"


def _success(task: pd.DataFrame, domain: str, noise: float) -> tuple[str, str]:
    """The task part's success bars at one flip rate: the success rate with the Bayesian learner's estimate
    after SUCCESS_AFTER chosen answers against the domain's bar, and minus the true parameter's success on
    the same episodes, each with its interval and verdict."""
    chosen = task[(task["domain"] == domain) & (task["query_rule"] == "information_gain")]
    exact = task[(task["domain"] == domain) & (task["method"] == "true_parameter")]
    at = chosen[(chosen["noise"] == noise) & (chosen["episode"] == SUCCESS_AFTER)]
    rate = at[(at["method"] == "bayes") & (at["metric"] == "success_rate")]["value"].to_numpy()
    bar = SUCCESS_BARS[domain]
    margin = verdicts.bootstrap_mean(rate - bar)
    success = (
        f"{rate.mean():.2f} (CI {margin.low + bar:.2f}-{margin.high + bar:.2f}: "
        f"{verdicts.better(margin, lower_is_better=False)} against the {bar:g} bar)"
    )
    gap = verdicts.paired_difference(
        pd.concat([at, exact]),
        metric="success_rate",
        method="bayes",
        baseline="true_parameter",
        episode=SUCCESS_AFTER,
    )
    return success, f"{interval(gap, '', 2)}: {verdicts.within(gap, -SUCCESS_SHORTFALL, np.inf)}"


def _held_out_answers(held_out: pd.DataFrame) -> dict[str, str]:
    """Notebook 12's answers claims replicated on its held-out truths and seeds."""
    table = answers_to_step(held_out)
    models = told_against_chosen(table, held_out)
    steps = table.set_index(["domain", "noise", "told"])
    never = models[models["model"].notna() & models["nothing"].isna()]
    answers = int(held_out["episode"].max())
    out = {
        "nb12_held_environments": str(int(steps["environments"].min())),
        "nb12_held_choice_worst": f"{models['nothing_ratio'].max():.2f}",
        "nb12_held_never": "".join(
            f"; at {r.noise * 100:g} % flips in {r.domain} it was not within one step in 90 % of them after "
            f"{answers} answers, where the learner told the model needed {r.model:g}"
            for r in never.itertuples()
        ),
    }
    for noise, key in ((0.0, "0"), (FLIPS, "20")):
        out[f"nb12_held_kind{key}"] = in_domains({d: _count(steps.loc[(d, noise, "kind")]) for d in DOMAINS})
    return out


def _model_choice(steps: pd.DataFrame, rows: pd.DataFrame) -> dict[str, str]:
    """Told nothing of the teacher against told its model: the settings past notebook 12's bar."""
    models = told_against_chosen(steps, rows)
    past = models[models["nothing_ratio"] > MODEL_CHOICE_BOUND]
    listed = [
        f"{r.teacher} teacher at {r.noise:.0%} in {r.domain}, "
        + (
            f"final error {r.nothing_error:.3g} against {r.model_error:.3g}"
            if r.compared != "answers"
            else f"{r.nothing:g} answers against {r.model:g}"
            if np.isfinite(r.nothing)
            else f"never within one step, against {r.model:g} answers"
        )
        + f" ({r.nothing_ratio:.2f}, {r.nothing_low:.2f}-{r.nothing_high:.2f})"
        for r in past.itertuples()
    ]
    return {
        "nb12_choice_worst": f"{models['nothing_ratio'].max():.2f}",
        "nb12_choice_past": f"{len(past)} of {len(models)}",
        "nb12_choice_list": "; ".join(listed).replace("%", " %") or "none",
        "nb12_choice_surely": str(int((models["nothing_low"] > MODEL_CHOICE_BOUND).sum())),
    }

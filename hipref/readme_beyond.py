"""The README's findings beyond the paper (notebooks 10, 12 and 13, and SI against a constant guess), each
number and verdict read from `results/` as `hipref.readme` reads the paper's.

Where a notebook writes a table, its table is read; where it prints a measurement without writing one
(notebook 10's slopes, notebook 12's task bars), the measurement is recomputed from `results/data/` by the
notebook's own code path (`hipref.experiments.conditioning`, `hipref.verdicts`). How the committed results
were run (a notebook's parameters) is read from its executed copy in `results/notebooks/`, not from
`params/`, which may already hold the next run's values.
"""

from __future__ import annotations

import ast
import json
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from hipref import verdicts
from hipref.experiments.answers_tables import CONSISTENT, answers_to_step, told_against_chosen
from hipref.experiments.answers_to_success import MODEL_CHOICE_BOUND, STEP_BOUNDS
from hipref.experiments.conditioning import TOLERANCE, conditioning
from hipref.experiments.domains import DOMAINS
from hipref.experiments.si_pretraining import PAPER_A7
from hipref.readme_format import UNITS, WORDS, interval, percent, signed

LOSSES = {
    "nll": "the negative log-likelihood",
    "brier": "the squared loss over its distribution (A.7)",
    "expectation": "the squared loss over its mean",
    "brier_expectation": "the squared loss over its distribution and its mean",
}
"""How the README names Algorithm 4's losses (`PretrainData.loss`)."""

SI_STUDIES: tuple[str, ...] = (
    "02_r1_pesi",
    "03_r2_noise",
    "04_r3_copesi",
    "11_teachers_and_robustness",
)
"""The notebooks whose SI comparisons set OSI beside a constant guess and whose parameters name Algorithm 4's
reading (notebook 08 varies it: its `default` variant is the code's)."""

COVERAGE = 0.9
"""The interval whose coverage of the truth the README quotes (notebook 13's `coverage_90`)."""

REGRESSORS = {"gbt": "boosted trees", "knn": "nearest neighbours"}

SUCCESS_MARGIN = 0.10
"""Notebook 10's bar: the learned low level's success with the true parameter within this of its expert's."""

LEARNED_OUTCOMES = {
    "wiping": ("force_mean", " N/m", 1.0, 0),
    "pushing": ("goal_overshoot", " cm/kg", 100.0, 2),
}
"""Notebook 10's outcome of the estimate error per domain: metric, unit, scale from SI units, digits."""


def ran_with(results: Path, notebook: str) -> dict[str, Any]:
    """The parameters the committed results of `notebook` were run with: its executed copy's parameters
    cell, overridden by the cell papermill injected."""
    cells = json.loads((results / "notebooks" / f"{notebook}.ipynb").read_text(encoding="utf-8"))["cells"]
    out: dict[str, Any] = {}
    for tag in ("parameters", "injected-parameters"):
        for cell in cells:
            if tag not in cell.get("metadata", {}).get("tags", []):
                continue
            for node in ast.parse("".join(cell["source"])).body:
                if isinstance(node, ast.Assign | ast.AnnAssign) and node.value is not None:
                    targets = node.targets if isinstance(node, ast.Assign) else [node.target]
                    for target in targets:
                        if isinstance(target, ast.Name):
                            out[target.id] = ast.literal_eval(node.value)
    return out


def reading(n_trajectories: int, loss: str) -> str:
    """'on 3,000 trajectories with the negative log-likelihood': a reading of Algorithm 4."""
    return f"on {n_trajectories:,} trajectories with {LOSSES[loss]}"


def _difference(row: pd.Series) -> verdicts.Difference:
    return verdicts.Difference(float(row["mean"]), float(row["low"]), float(row["high"]), int(row["n"]))


def _learned_controller(results: Path) -> dict[str, str]:
    """Notebook 10: the learned low level against its expert, and SI on top of it."""
    table = pd.read_csv(results / "tables" / "10_learned_controller.csv")
    rows = pd.read_csv(results / "data" / "10_learned_controller.csv")
    params = ran_with(results, "10_learned_controller")
    spreads = [float(s) for s in params["estimate_spreads"]]
    truth, taught = f"learned, spread {spreads[0]:g}", f"learned, spread {spreads[-1]:g}"
    episodes = rows[rows["method"].isin(["admittance", "learned"]) & rows["estimate_error"].notna()].copy()
    episodes["controller"] = np.where(
        episodes["method"] == "learned",
        "learned, spread " + episodes["estimate_spread"].astype(float).map("{:g}".format),
        "expert",
    )
    comparison = episodes[
        episodes["held_out"].eq(False)
        & (episodes["route"] == "both")
        & (episodes["iterations"].isna() | (episodes["iterations"] == params["iterations"]))
    ]
    out: dict[str, str] = {
        "nb10_spread": f"{spreads[-1]:g}",
        "nb10_margin": f"{SUCCESS_MARGIN:.2f}",
        "nb10_tolerance": percent(TOLERANCE),
    }
    replaces, acts = [], []
    for domain in DOMAINS:
        at = table[(table["domain"] == domain) & (table["metric"] == "success_rate")]
        held = []
        for key, name in (("truth", truth), ("taught", taught)):
            d = _difference(at[at["comparison"] == f"held out, true parameter: {name} - expert"].iloc[0])
            held.append(verdicts.within(d, -SUCCESS_MARGIN, 1.0))
            out[f"nb10_{domain}_{key}"] = f"{interval(d, '', 2)}: {held[-1]}"
            out["nb10_held_out"] = str(d.n)
        replaces.append(verdicts.any_of(held))
        metric, unit, scale, digits = LEARNED_OUTCOMES[domain]
        part = comparison[comparison["domain"] == domain]
        uses = []
        for key, name in (("truth", truth), ("taught", taught)):
            c = conditioning(part[part["controller"].isin(["expert", name])], metric, "learned")
            uses.append(c.verdict)
            slope = verdicts.Difference(
                c.difference.slope, c.difference.low, c.difference.high, c.difference.n
            )
            out[f"nb10_{domain}_slope_{key}"] = f"{interval(slope, unit, digits, scale)}: {c.verdict}"
            out[f"nb10_{domain}_expert"] = f"{signed(scale * c.expert.slope, digits)}{unit}"
        acts.append(verdicts.any_of(uses))
        si = _difference(
            table[
                (table["domain"] == domain)
                & (table["metric"] == "param_error")
                & (table["comparison"] == "pesi - osi (learned)")
            ].iloc[0]
        )
        unit_si, scale_si, digits_si = UNITS[domain]
        out[f"nb10_si_{domain}"] = (
            f"{interval(si, unit_si, digits_si, scale_si)}: {verdicts.better(si, lower_is_better=True)}"
        )
    out["nb10_replaces"] = verdicts.combine(replaces)
    out["nb10_acts"] = verdicts.combine(acts)
    out["nb10_verdict"] = WORDS[verdicts.combine([out["nb10_replaces"], out["nb10_acts"]])]
    return out


def _claims_verdicts(results: Path, section: str) -> list[str]:
    """The 'Holds' column of one notebook's section of `results/claims.md`."""
    text = (results / "claims.md").read_text(encoding="utf-8")
    body = text.split(f"<!-- section: {section} -->", 1)[1].split(f"<!-- end: {section} -->", 1)[0]
    lines = [line for line in body.splitlines() if line.startswith("|")][2:]
    return [line.rstrip(" |").rsplit("|", 1)[1].strip() for line in lines]


FLIPS = 0.2
"""The flip rate of the paper's teacher at which notebook 12 sets its bars beside perfect answers."""

SUCCESS_BARS = {"wiping": 0.9, "pushing": 0.8}
"""Notebook 12's bars: the task's success after `SUCCESS_AFTER` chosen answers."""

SUCCESS_AFTER = 20
"""Notebook 12's checkpoint of the success bars."""

GAP_FACTOR = 4
"""Notebook 12's bar: the Bayesian learner's error at least this many times below PESI's."""


def _cells(values: dict[str, str]) -> str:
    return f"{values['wiping']} in wiping and {values['pushing']} in pushing"


def _count(step: pd.Series) -> str:
    """A row of `answers_to_step`: its answers to one step and their 95 % interval."""
    answers = f"{step['answers']:g}" if np.isfinite(step["answers"]) else "never"
    return f"{answers} (CI {step['low']:g}-{step['high']:g})" if np.isfinite(step["low"]) else answers


def _answers(results: Path) -> dict[str, str]:
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
        "nb12_step": _cells(
            {d: f"{s.candidates.resolution * UNITS[d][1]:g}{UNITS[d][0]}" for d, s in DOMAINS.items()}
        ),
    }
    for noise, key in ((0.0, "0"), (FLIPS, "20")):
        at = ig[(ig["noise"] == noise) & (ig["told"] == "kind")].set_index("domain")
        out[f"nb12_kind{key}"] = _cells({d: _count(at.loc[d]) for d in DOMAINS})
        out[f"nb12_floor{key}"] = _cells({d: f"{at.loc[d, 'floor']:.1f}" for d in DOMAINS})
        out[f"nb12_ratio{key}"] = _cells({d: f"{at.loc[d, 'ratio']:.2f}" for d in DOMAINS})
        out[f"nb12_bar{key}"] = str(STEP_BOUNDS[noise])
    out["nb12_flips"] = percent(FLIPS)
    gaps, errors, success, pesi_success, prior = [], {}, {}, {}, {}
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
        for noise, key in ((0.0, "0"), (FLIPS, "20")):
            at = chosen[(chosen["noise"] == noise) & (chosen["episode"] == SUCCESS_AFTER)]
            rate = at[(at["method"] == "bayes") & (at["metric"] == "success_rate")]["value"].to_numpy()
            margin = verdicts.bootstrap_mean(rate - SUCCESS_BARS[domain])
            bar = SUCCESS_BARS[domain]
            success[(domain, key)] = (
                f"{rate.mean():.2f} (CI {margin.low + bar:.2f}-{margin.high + bar:.2f}: "
                f"{verdicts.better(margin, lower_is_better=False)} against the {bar:g} bar)"
            )
            if noise == 0.0:
                # PESI asks Algorithm 2's uniform pairs only.
                pesi = uniform[(uniform["method"] == "pesi") & (uniform["metric"] == "success_rate")]
                pesi_success[domain] = f"{pesi[pesi['episode'] == SUCCESS_AFTER]['value'].mean():.2f}"
        started = chosen[(chosen["noise"] == 0.0) & chosen["method"].isin(["bayes", "bayes_si"])]
        d = verdicts.paired_difference(
            started, metric="param_error", method="bayes_si", baseline="bayes", episode=SUCCESS_AFTER
        )
        prior[domain] = f"{interval(d, unit, digits, scale)}: {verdicts.better(d, lower_is_better=True)}"
    out["nb12_errors"] = _cells(errors)
    out["nb12_gap"] = verdicts.combine(gaps)
    out["nb12_verdict"] = WORDS[out["nb12_gap"]]
    for key in ("0", "20"):
        out[f"nb12_success{key}"] = _cells({d: success[(d, key)] for d in DOMAINS})
    out["nb12_pesi_success"] = _cells(pesi_success)
    out["nb12_prior"] = _cells(prior)
    out.update(_model_choice(steps, rows))
    out.update(_held_out_answers(held_out))
    return out


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
        out[f"nb12_held_kind{key}"] = _cells({d: _count(steps.loc[(d, noise, "kind")]) for d in DOMAINS})
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


def _constant_guess(results: Path) -> dict[str, str]:
    """SI against a constant guess: notebook 02's OSI and notebook 13's readings of Algorithm 4."""
    table = pd.read_csv(results / "tables" / "02_against_constant_guess.csv")
    osi = table[table["method"] == "osi"].set_index("domain")
    out: dict[str, str] = {"si_episode": str(int(osi["episode"].max()))}
    for domain in DOMAINS:
        r = osi.loc[domain]
        d = verdicts.Difference(
            float(r["minus_middle"]), float(r["minus_middle_low"]), float(r["minus_middle_high"]), int(r["n"])
        )
        unit, scale, digits = UNITS[domain]
        out[f"si_osi_{domain}"] = (
            f"{scale * r['error']:.1f} against {scale * r['middle_error']:.1f}{unit}, "
            f"OSI − middle {interval(d, unit, digits, scale)}: {r['beats_middle']}"
        )
    out["si_verdict"] = WORDS[verdicts.combine(list(osi["beats_middle"]))]
    ran = {name: ran_with(results, name) for name in SI_STUDIES}
    readings = {name: reading(p["n_trajectories"], p["pretrain_loss"]) for name, p in ran.items()}
    out["si_reading_02"] = readings["02_r1_pesi"]
    groups: dict[str, list[str]] = {}
    for name, text in readings.items():
        groups.setdefault(text, []).append(name[:2])
    out["si_studies"] = "; ".join(
        (f"notebook {n[0]} pretrains" if len(n) == 1 else f"notebooks {', '.join(n)} pretrain") + f" OSI {t}"
        for t, n in groups.items()
    )
    out.update(_tau(results))
    return out


SETTINGS = {
    "n_trajectories": "{} trajectories",
    "history": "h = {}",
    "cut": "slices cut {}",
    "columns": "columns: {}",
}
"""Notebook 13's factors as the README names a setting of each."""


def _tau(results: Path) -> dict[str, str]:
    """Notebook 13: a regressor and each OSI reading against the range's middle, and OSI's coverage."""
    table = pd.read_csv(results / "tables" / "13_osi_against_baselines.csv").set_index("domain")
    calibration = pd.read_csv(results / "tables" / "13_osi_calibration.csv").set_index(["domain", "reading"])
    data = pd.read_csv(results / "data" / "13_what_tau_tells.csv")
    params = ran_with(results, "13_what_tau_tells")
    environments = data[data["metric"] == "param_error"].groupby("domain")["ground_truth"].nunique()
    n_largest = max(*params["n_trajectories"], params["base_trajectories"], PAPER_A7.n_trajectories)
    out = {
        "tau_environments": str(int(environments.min())),
        "tau_regressors": ", ".join(sorted({REGRESSORS[b] for b in table["best_regressor"]})),
        "tau_fitted": " and ".join(REGRESSORS[r] for r in params["regressors"]),
        "tau_level": percent(COVERAGE),
        "tau_a7_reading": reading(PAPER_A7.n_trajectories, PAPER_A7.loss),
        "tau_more_reading": reading(n_largest, "nll"),
    }
    for key, column in (("best", None), ("a7", "osi_paper_a7"), ("more", "osi_nll_more_data")):
        cells, held = {}, []
        for domain in DOMAINS:
            name = column or f"{table.loc[domain, 'best_regressor']}"
            r = table.loc[domain]
            d = verdicts.Difference(
                float(r[f"{name}_minus_middle"]),
                float(r[f"{name}_minus_middle_low"]),
                float(r[f"{name}_minus_middle_high"]),
                int(environments[domain]),
            )
            held.append(verdicts.better(d, lower_is_better=True))
            unit, scale, digits = UNITS[domain]
            cells[domain] = f"{interval(d, unit, digits, scale)}: {held[-1]}"
            if column:
                out[f"tau_{key}_coverage_{domain}"] = (
                    f"{calibration.loc[(domain, column), f'coverage_{round(100 * COVERAGE)}']:.2f}"
                )
        out[f"tau_{key}"] = _cells(cells)
    strongest = {}
    for domain in DOMAINS:
        r = table.loc[domain]
        unit, scale, digits = UNITS[domain]
        osi, best = float(r["osi_nll_more_data_error"]), float(r["strongest_error"])
        strongest[domain] = (
            f"{scale * osi:.{digits}f} against {scale * best:.{digits}f}{unit}, {osi / best:.2f} times "
            f"({REGRESSORS[r['strongest_regressor']]}, "
            f"{SETTINGS[r['strongest_factor']].format(str(r['strongest_level']).replace('_', ' '))})"
        )
    out["tau_strongest"] = _cells(strongest)
    return out


def values(results: Path) -> dict[str, str]:
    """Every placeholder of the findings beyond the paper."""
    return {**_learned_controller(results), **_answers(results), **_constant_guess(results)}

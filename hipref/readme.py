"""The README's findings, their numbers and verdicts computed from `results/`, never typed.

`make readme` (`python -m hipref.readme`) rewrites each section of README.md between
`<!-- generated: NAME -->` and `<!-- end: NAME -->` from the committed results; `python -m hipref.readme
--check` (and `tests/test_readme.py`) fails when a section differs from what `results/` gives. The text
of a section lives in `hipref/readme_<name>.md`; every number and verdict in it is a placeholder filled by
`values`, each read from `results/data/` and `results/tables/` and decided by `hipref.verdicts`, as the
notebooks do (the findings on noisy preferences in `hipref.readme_noise`, those beyond the paper in
`hipref.readme_beyond` and, notebook 12's, `hipref.readme_answers`).
"""

from __future__ import annotations

import argparse
import functools
import re
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from hipref import verdicts
from hipref.envs.gridworld import WipingGrid
from hipref.intervals import CONFIDENCE
from hipref.readme_answers import values as answers
from hipref.readme_beyond import values as beyond
from hipref.readme_format import (
    UNITS,
    WORDS,
    csv,
    interval,
    percent,
    ran_with,
    significant_steps,
    slope_text,
)
from hipref.readme_noise import values as noise_values
from hipref.results import repo_root

SECTIONS: tuple[str, ...] = ("findings", "copesi")
"""The generated sections: each one's text is `hipref/readme_<name>.md`, with a placeholder for every
number and verdict."""


def _differences(rows: pd.DataFrame, domain: str) -> pd.DataFrame:
    """PESI − OSI per environment and checkpoint: columns ground_truth, seed, episode, difference."""
    at = rows[(rows["domain"] == domain) & (rows["metric"] == "param_error")]
    keys = ["ground_truth", "seed", "episode"]
    pesi, osi = at[at["method"] == "pesi"], at[at["method"] == "osi"]
    paired = pesi[[*keys, "value"]].merge(osi[[*keys, "value"]], on=keys, suffixes=("", "_osi"))
    return paired.assign(difference=paired["value"] - paired["value_osi"])


def _controllers(results: Path) -> dict[str, str]:
    rows = csv(results, "data/05_controllers.csv")
    force = rows[rows["metric"] == "force_mean"].groupby(["method", "desired_height"])["value"].mean()
    adm, spd = force["admittance"], force["spd"]
    seeds = rows.loc[rows["metric"] == "force_mean", "seed"].nunique()
    held = verdicts.holds_in_all(bool((adm < spd).all()), environments=seeds)
    return {
        "fig7_verdict": WORDS[held],
        **{f"adm_{k}": f"{f(adm):.0f}" for k, f in (("low", np.min), ("high", np.max))},
        **{f"spd_{k}": f"{f(spd):.0f}" for k, f in (("low", np.min), ("high", np.max))},
    }


def _feedback(results: Path, root: Path) -> dict[str, str]:
    rows = csv(results, "data/01_r1_feedback.csv")
    per_seed = rows.pivot_table(index=["method", "seed"], columns="episode", values="value")
    window = min(10, per_seed.shape[1] // 2)
    first = per_seed.iloc[:, :window].mean(axis=1).unstack("method")
    last = per_seed.iloc[:, -window:].mean(axis=1).unstack("method")
    tabular = verdicts.bootstrap_mean(last["tabular_coach"] - first["tabular_coach"])
    pretrained = verdicts.bootstrap_mean(last["pretrained_coach"] - first["pretrained_coach"])
    held = verdicts.combine(
        [verdicts.better(tabular, lower_is_better=False), verdicts.better(pretrained, lower_is_better=True)]
    )
    params = yaml.safe_load((root / "params" / "full" / "01_r1_feedback.yaml").read_text())
    return {
        "fig2c_verdict": WORDS[held],
        "grid_cells": str(WipingGrid().n_states),
        "window": str(window),
        "demos": f"{params['demos']:,}",
        "tabular_last": f"{last['tabular_coach'].mean():.0f}",
        "pretrained_first": f"{first['pretrained_coach'].mean():.1f}",
        "pretrained_last": f"{last['pretrained_coach'].mean():.1f}",
        "pretrained_change": interval(pretrained, "", 1),
        "coach_seeds": str(pretrained.n),
    }


def _pesi(results: Path) -> dict[str, str]:
    rows = csv(results, "data/02_r1_pesi.csv")
    out: dict[str, str] = {}
    final, over_time = [], []
    for domain, (unit, scale, digits) in UNITS.items():
        d = verdicts.paired_difference(
            rows[rows["domain"] == domain], metric="param_error", method="pesi", baseline="osi"
        )
        final.append(verdicts.better(d, lower_is_better=True))
        out[f"pesi_{domain}"] = interval(d, unit, digits, scale)
        differences = _differences(rows, domain)
        slope = verdicts.trend(differences, x="episode", y="difference", units=("ground_truth", "seed"))
        over_time.append(verdicts.decreases(slope))
        out[f"time_slope_{domain}"] = slope_text(slope, unit, digits, 100 * scale)
        steps = verdicts.steps(differences, x="episode", y="difference", units=("ground_truth", "seed"))
        out[f"time_steps_{domain}"] = significant_steps(steps, increasing=False)
    held_out = csv(results, "data/02_r1_pesi_held_out.csv")
    replicated = []
    for domain, (unit, scale, digits) in UNITS.items():
        mine = held_out[held_out["domain"] == domain]
        d = verdicts.paired_difference(mine, metric="param_error", method="pesi", baseline="osi")
        replicated.append(verdicts.better(d, lower_is_better=True))
        out[f"held_out_{domain}"] = interval(d, unit, digits, scale)
        out[f"held_out_truths_{domain}"] = ", ".join(f"{t:g}" for t in sorted(mine["ground_truth"].unique()))
    out["held_out_seeds"] = ", ".join(str(s) for s in sorted(held_out["seed"].unique()))
    out["held_out_verdict"] = WORDS[verdicts.combine(replicated)]
    wiping = rows[rows["domain"] == "wiping"]
    ce = verdicts.paired_difference(wiping, metric="param_error", method="pesi", baseline="pesi_ce")
    environments = wiping[["ground_truth", "seed"]].drop_duplicates()
    return {
        **out,
        "environments": str(len(environments)),
        "truths": str(environments["ground_truth"].nunique()),
        "seeds": str(environments["seed"].nunique()),
        "pesi_episodes": str(int(rows["episode"].max())),
        "confidence": percent(CONFIDENCE),
        "fig2d_verdict": WORDS[verdicts.combine(final)],
        "time_verdict": WORDS[verdicts.combine(over_time)],
        "ce_verdict": WORDS[verdicts.better(ce, lower_is_better=True)],
        "ce_wiping": interval(ce, " cm", 1, 100.0),
    }


def _noise(results: Path) -> dict[str, str]:
    rows = csv(results, "data/03_r2_noise.csv")
    errors = rows[rows["metric"] == "param_error"]
    out: dict[str, str] = {}
    grows, unlearns = [], []
    highest = float(rows["noise"].max())
    for domain, (unit, scale, digits) in UNITS.items():
        pesi = errors[(errors["domain"] == domain) & (errors["method"] == "pesi")]
        final = pesi[pesi["episode"] == pesi["episode"].max()]
        slope = verdicts.trend(final, x="noise", units=("ground_truth", "seed"))
        grows.append(verdicts.increases(slope))
        out[f"noise_slope_{domain}"] = slope_text(slope, unit, digits, scale)
        steps = verdicts.steps(final, x="noise", units=("ground_truth", "seed"))
        out[f"noise_steps_{domain}"] = significant_steps(steps, increasing=True)
        high = _differences(rows[(rows["noise"] == highest) | (rows["method"] == "osi")], domain)
        over_time = verdicts.trend(high, x="episode", y="difference", units=("ground_truth", "seed"))
        unlearns.append(verdicts.increases(over_time))
        out[f"unlearn_{domain}"] = slope_text(over_time, unit, digits, 100 * scale)
    return {
        **out,
        "noise_verdict": WORDS[verdicts.combine(grows)],
        "unlearn_verdict": WORDS[verdicts.combine(unlearns)],
        "unlearn_level": percent(highest),
    }


def _readings(results: Path) -> dict[str, str]:
    """Notebook 08's readings and the pushing gain's first significant checkpoint in notebook 02."""
    table = csv(results, "tables/08_si_sensitivity.csv")
    readings = table[table["variant"] != "previous_design"]
    rows = csv(results, "data/08_si_sensitivity.csv")
    out = {
        "readings_episodes": str(int(rows["episode"].max())),
        "readings_environments": str(
            len(rows[rows["domain"] == "wiping"][["ground_truth", "seed"]].drop_duplicates())
        ),
    }
    for domain in UNITS:
        at = readings[readings["domain"] == domain]
        wins = at[at["pesi_minus_osi_high"] < 0]
        out[f"readings_{domain}"] = f"{len(wins)} of {len(at)}"
        out[f"readings_{domain}_names"] = ", ".join(wins["variant"]) or "none"
        co = table[(table["domain"] == domain) & (table["copesi_minus_pesi_high"] < 0)]
        out[f"readings_copesi_{domain}"] = str(len(co))
    curve = csv(results, "tables/02_pesi_minus_osi.csv")
    pushing = curve[(curve["domain"] == "pushing") & (curve["metric"] == "param_error") & (curve["high"] < 0)]
    out["pushing_first"] = str(int(pushing["episode"].min()))
    noise = csv(results, "data/03_r2_noise.csv")
    final = noise[
        (noise["method"] == "pesi") & (noise["metric"] == "param_error") & (noise["domain"] == "wiping")
    ]
    final = final[final["episode"] == final["episode"].max()].groupby("noise")["value"].mean()
    out["noise_episodes"] = str(int(noise["episode"].max()))
    highest = float(csv(results, "tables/04_filter_quality.csv")["noise"].max())
    out["noise_w0"], out["noise_w_high"] = f"{100 * final[0.0]:.1f}", f"{100 * final[highest]:.1f}"
    out["noise_lowest"] = percent(0.0)
    out["readings_noise"] = percent(ran_with(results, "08_si_sensitivity")["noise"])
    return out


def values(results: Path, root: Path) -> dict[str, str]:
    """Every placeholder of `SECTIONS`, computed from the results directory `results`."""
    return {
        **_controllers(results),
        **_feedback(results, root),
        **_pesi(results),
        **_noise(results),
        **_readings(results),
        **noise_values(results),
        **beyond(results),
        **answers(results),
    }


def render(results: Path, root: Path) -> dict[str, str]:
    """Each section's text as `results` gives it."""
    filled = values(results, root)
    here = Path(__file__).parent
    return {
        name: (here / f"readme_{name}.md").read_text(encoding="utf-8").format(**filled) for name in SECTIONS
    }


def _pattern(name: str) -> re.Pattern[str]:
    return re.compile(rf"(<!-- generated: {name} -->\n)(.*?)(<!-- end: {name} -->)", re.S)


def _replaced(match: re.Match[str], text: str) -> str:
    return match[1] + text + match[3]


def update(readme: str, sections: dict[str, str]) -> str:
    """`readme` with each generated section replaced; a section without its markers is refused."""
    for name, text in sections.items():
        pattern = _pattern(name)
        if not pattern.search(readme):
            raise ValueError(f"README lacks the markers of section {name!r}")
        readme = pattern.sub(functools.partial(_replaced, text=text), readme)
    return readme


def differences(readme: str, sections: dict[str, str]) -> list[str]:
    """The lines of `readme`'s generated sections that differ from `sections`, each as both lines."""
    out = []
    for name, text in sections.items():
        found = _pattern(name).search(readme)
        if not found:
            out.append(f"section {name!r}: markers missing")
            continue
        have, want = found[2].splitlines(), text.splitlines()
        out += [f"README:  {a}\nresults: {b}" for a, b in zip(have, want, strict=False) if a != b]
        if len(have) != len(want):
            out.append(f"section {name!r}: {len(have)} lines in the README, {len(want)} from results/")
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--check", action="store_true", help="fail if README.md differs from results/")
    parser.add_argument("--readme", type=Path, default=None, help="the README to write or check")
    args = parser.parse_args(argv)
    root = repo_root()
    if root is None:
        raise SystemExit("hipref.readme needs the source checkout (README.md and results/)")
    path = args.readme or root / "README.md"
    sections = render(root / "results", root)
    text = path.read_text(encoding="utf-8")
    if args.check:
        wrong = differences(text, sections)
        print("\n".join(wrong) or f"{path.name}: every generated number matches results/")
        return 1 if wrong else 0
    path.write_text(update(text, sections), encoding="utf-8")
    return 0


if __name__ == "__main__":
    sys.exit(main())

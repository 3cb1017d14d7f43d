"""What not knowing the teacher's model costs the Bayesian learner (notebook 12's answers part, no physics).

`python -m hipref.bench.model_choice --grid heldout` runs the learner under information gain, told the
teacher's model, told only its kind (the kind's parameters weighed) and told nothing (every answer model
weighed by its marginal likelihood), under every teacher of notebook 12's claim (the paper's at 0 and 20 %
flips, and notebook 11's others without flips), on notebook 12's full-profile environments ('study': its five
truths x seeds 0-1), on held-out ones ('heldout': truths it does not use x seeds 100-104) or on two wider
held-out grids of 40 environments per domain ('wide' and 'wide2': 8 truths across the range x seeds 700-704
and 800-804, where the estimate's readings were compared, `hipref.learners.estimates`; `--episodes 200`), or
on every candidate of Phi as a truth ('every': x seeds 900-901, 82 environments in wiping and 98 in pushing,
where the count to 90 % depends least on which truths are drawn). It
prints `told_against_chosen` (answers to one step of Phi in 90 % of the environments, or final errors where
the told learner never gets there), the myopic teacher's floor (the error of the best estimate from its
remembered pictures themselves, `picture_floor`, against which no learner of its answers can be within one
step in 90 % of environments) and the mean wall time of one run of
each. Nothing is written to disk.

`--family teachers` gives the learner told nothing only the answer models of the benchmark's own seven
teachers (`teacher_family`) instead of `model_family()`'s 32: every teacher it meets and no other, so what it
still needs beyond told the model is not the cost of models no teacher follows (the learner told the kind,
the same under either family, is then not run).

`--split` tells instead where not knowing costs: the learner told nothing reading the answers to the queries
the learner told the model chooses, and the reverse, each beside the two whole learners (answers to one step).

`--blocks K` tells how far the ratio moves with the environments drawn: both learners on K blocks of the
grid's truths, each block with as many seeds as the grid, the next seeds after the block before (block 0 is
the grid's own). Per setting it prints each block's answers to one step of each learner, the share of ordered
pairs of two blocks (i, j) where told the model needs over 1.25 times as many answers on i as on j (the bar
applied to a learner against itself), the share of blocks where told nothing needs over 1.25 times told the
model's answers, and each learner's answers to one step over all the blocks' environments at once.
"""

from __future__ import annotations

import argparse
import itertools
import math
import time

import numpy as np
import pandas as pd
from scipy.stats import norm

from hipref.experiments.answers_tables import (
    CONSISTENT,
    answers_to_step,
    told_against_chosen,
)
from hipref.experiments.answers_to_success import (
    MODEL_CHOICE_BOUND,
    AnswersCell,
    run_answers,
)
from hipref.experiments.domains import domain_spec
from hipref.learners.answer_models import AnswerModel, hypotheses, told
from hipref.teachers.models import TeacherModel, picture_floor

STUDY: dict[str, tuple[float, ...]] = {
    "wiping": (0.54, 0.62, 0.7, 0.78, 0.86),
    "pushing": (9.25, 11.5, 14.0, 16.5, 18.75),
}
HELDOUT: dict[str, tuple[float, ...]] = {
    "wiping": (0.58, 0.66, 0.74, 0.82),
    "pushing": (10.0, 13.0, 15.0, 17.5),
}
WIDE: dict[str, tuple[float, ...]] = {
    "wiping": (0.525, 0.575, 0.625, 0.675, 0.725, 0.775, 0.825, 0.875),
    "pushing": (8.4, 10.0, 11.6, 13.2, 14.8, 16.4, 18.0, 19.6),
}
WIDE2: dict[str, tuple[float, ...]] = {
    "wiping": (0.51, 0.5643, 0.6186, 0.6729, 0.7271, 0.7814, 0.8357, 0.89),
    "pushing": (8.2, 9.857, 11.514, 13.171, 14.829, 16.486, 18.143, 19.8),
}
EVERY: dict[str, tuple[float, ...]] = {
    domain: tuple(float(v) for v in domain_spec(domain).candidates.values) for domain in ("wiping", "pushing")
}
GRIDS: dict[str, tuple[dict[str, tuple[float, ...]], range]] = {
    "study": (STUDY, range(2)),
    "heldout": (HELDOUT, range(100, 105)),
    "wide": (WIDE, range(700, 705)),
    "wide2": (WIDE2, range(800, 805)),
    "every": (EVERY, range(900, 902)),
}
TEACHERS = (
    ("mistake", 0.0),
    ("mistake", 0.2),
    ("stochastic", 0.0),
    ("skip", 0.0),
    ("equal", 0.0),
    ("myopic", 0.0),
    ("distance", 0.0),
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grid", choices=tuple(GRIDS), default="heldout")
    parser.add_argument("--episodes", type=int, default=330)
    parser.add_argument(
        "--family",
        choices=("all", "teachers"),
        default="all",
        help="the answer models told nothing weighs: model_family()'s 32, or the seven teachers' own",
    )
    instead = parser.add_mutually_exclusive_group()
    instead.add_argument(
        "--blocks",
        type=int,
        help="instead, both learners on this many blocks of the grid's seeds (at least 2)",
    )
    instead.add_argument(
        "--split",
        action="store_true",
        help="instead, each learner's queries read by the other's posterior (told the model, told nothing)",
    )
    args = parser.parse_args()
    truths, seeds = GRIDS[args.grid]
    family = teacher_family() if args.family == "teachers" else None
    if args.split:
        print(split_table(truths, seeds, args.episodes, family).to_string(index=False))
        return
    if args.blocks is not None:
        if args.blocks < 2:
            parser.error(f"--blocks must be at least 2, got {args.blocks}")
        table = block_table(truths, seeds, args.episodes, args.blocks, family)
        print(table.to_string(index=False, float_format=lambda v: f"{v:.2f}"))
        return
    frames: list[pd.DataFrame] = []
    # Told the kind, the learner weighs that kind's models whatever the family: run once, with the full one.
    levels = ("model", "kind", "nothing") if family is None else ("model", "nothing")
    seconds: dict[str, list[float]] = {level: [] for level in levels}
    for domain, values in truths.items():
        for teacher, noise in TEACHERS:
            for level in seconds:
                for truth in values:
                    for seed in seeds:
                        cell = AnswersCell(
                            domain, truth, seed, teacher, noise, "information_gain", level, args.episodes
                        )
                        start = time.perf_counter()
                        frames.append(run_answers(cell, family if level == "nothing" else None))
                        seconds[level].append(time.perf_counter() - start)
    rows = pd.concat(frames, ignore_index=True)
    table = told_against_chosen(answers_to_step(rows), rows)
    columns = ["domain", "teacher", "noise", "model", "kind", "nothing", "model_error", "nothing_error"]
    columns += ["kind_ratio", "kind_low", "kind_high"]
    columns += ["nothing_ratio", "nothing_low", "nothing_high", "compared"]
    print(table[columns].to_string(index=False))
    print(
        myopic_floor(tuple(truths), args.episodes).to_string(index=False, float_format=lambda v: f"{v:.3g}")
    )
    for level, times in seconds.items():
        print(f"told {level}: {sum(times) / len(times):.2f} s per run of {args.episodes} answers")


def split_table(
    truths: dict[str, tuple[float, ...]],
    seeds: range,
    episodes: int,
    family: tuple[AnswerModel, ...] | None,
) -> pd.DataFrame:
    """Per domain and teacher, the answers to one step of the learners told the model and told nothing, and
    of each one's queries read by the other's posterior: `model_asks_nothing_reads` (what the posterior
    not told the model makes of the told learner's queries) and `nothing_asks_model_reads`."""
    frames: list[pd.DataFrame] = []
    for domain, values in truths.items():
        for teacher, noise in TEACHERS:
            given = hypotheses(TeacherModel(teacher), noise, "model")
            blind = family if family is not None else hypotheses(TeacherModel(teacher), noise, "nothing")
            pairings = (
                ("model", "model", given, None),
                ("nothing", "nothing", blind, None),
                ("model", "nothing", given, blind),
                ("nothing", "model", blind, given),
            )
            for truth, seed in itertools.product(values, seeds):
                # The cell's `told` is unused: each pairing gives its asker's and reader's models.
                cell = AnswersCell(domain, truth, seed, teacher, noise, "information_gain", "model", episodes)
                for asks, reads, models, reader in pairings:
                    rows = run_answers(cell, models, reader)
                    frames.append(rows.assign(told=f"{asks}_asks_{reads}_reads"))
    steps = answers_to_step(pd.concat(frames, ignore_index=True))
    table = steps.pivot(index=["domain", "teacher", "noise"], columns="told", values="answers")
    return table.reset_index().rename_axis(columns=None)


def block_table(
    truths: dict[str, tuple[float, ...]],
    seeds: range,
    episodes: int,
    blocks: int,
    family: tuple[AnswerModel, ...] | None,
) -> pd.DataFrame:
    """Per domain and teacher that the told learner brings within one step, the answers to one step of the
    learners told the model and told nothing on each of `blocks` blocks of environments (`model`, `nothing`:
    one per block, NaN where never; block b holds `truths` x the len(seeds) seeds from seeds.start +
    b len(seeds)), `model_over`: the share of ordered pairs of distinct blocks (i, j) with model_i over
    MODEL_CHOICE_BOUND times model_j, `nothing_over`: the share of blocks b with nothing_b over it times
    model_b, and `model_pooled`, `nothing_pooled`: the answers to one step over all the blocks' environments
    at once. A count that never gets within one step is over any that does; pairs where neither does are
    left out of a share (`share_over`)."""
    rule = "information_gain"
    out = []
    for domain, values in truths.items():
        for teacher, noise in TEACHERS:
            if teacher == "myopic":  # neither learner gets within one step
                continue
            answers: dict[str, list[float]] = {"model": [], "nothing": []}
            pooled: dict[str, float] = {}
            for level, per_block in answers.items():
                models = family if level == "nothing" else None
                every: list[pd.DataFrame] = []
                for block in range(blocks):
                    start = seeds.start + block * len(seeds)
                    frames = []
                    for truth, seed in itertools.product(values, range(start, start + len(seeds))):
                        cell = AnswersCell(domain, truth, seed, teacher, noise, rule, level, episodes)
                        frames.append(run_answers(cell, models))
                    per_block.append(steps_of(frames))
                    every += frames
                pooled[level] = steps_of(every)
            model, nothing = answers["model"], answers["nothing"]
            pairs = [(model[i], model[j]) for i in range(blocks) for j in range(blocks) if i != j]
            row = (model, nothing, share_over(pairs), share_over(list(zip(nothing, model, strict=True))))
            out.append((domain, teacher, noise, *row, pooled["model"], pooled["nothing"]))
    columns = ["domain", "teacher", "noise", "model", "nothing", "model_over", "nothing_over"]
    columns += ["model_pooled", "nothing_pooled"]
    return pd.DataFrame(out, columns=columns)


def steps_of(frames: list[pd.DataFrame]) -> float:
    """The answers to one step (`answers_to_step`) of one setting's runs, NaN if never."""
    return float(answers_to_step(pd.concat(frames, ignore_index=True))["answers"].iloc[0])


def share_over(pairs: list[tuple[float, float]]) -> float:
    """The share of pairs (a, b) of answers to one step (NaN: never) with a over MODEL_CHOICE_BOUND times b;
    a NaN is over any count, and pairs of two NaN are left out (NaN when every pair is)."""
    decided = [(a, b) for a, b in pairs if not (np.isnan(a) and np.isnan(b))]
    if not decided:
        return np.nan
    return float(
        np.mean([np.isnan(a) or (not np.isnan(b) and a > MODEL_CHOICE_BOUND * b) for a, b in decided])
    )


def teacher_family() -> tuple[AnswerModel, ...]:
    """The answer models of TEACHERS' scripted teachers (`told`), each once."""
    return tuple(dict.fromkeys(told(TeacherModel(kind), noise) for kind, noise in TEACHERS))


def myopic_floor(domains: tuple[str, ...], answers: int) -> pd.DataFrame:
    """Per domain, the myopic teacher's floor after `answers` answers, in the parameter's unit: the standard
    deviation of the best estimate from its pictures themselves, the mean |error| of a normal estimate of
    that spread, the share of environments it puts within one step, and the answers that share needs to
    reach CONSISTENT (90 %)."""
    model = TeacherModel("myopic")
    rows = []
    for domain in domains:
        phi = domain_spec(domain).candidates
        width, step = phi.high - phi.low, phi.resolution / (phi.high - phi.low)
        sd = picture_floor(model, answers)
        needed = next(
            n for n in range(2, 10**6) if picture_floor(model, n) <= step / norm.ppf(0.5 + CONSISTENT / 2)
        )
        within = 2.0 * norm.cdf(step / sd) - 1.0
        rows.append((domain, answers, sd * width, sd * width * math.sqrt(2 / math.pi), within, needed))
    return pd.DataFrame(
        rows,
        columns=["domain", "answers", "floor_sd", "floor_mean_error", "floor_within_step", "answers_needed"],
    )


if __name__ == "__main__":
    main()

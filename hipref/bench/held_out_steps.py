"""Notebook 12's held-out replication at a scale the notebook cannot afford (no physics).

    python -m hipref.bench.held_out_steps --truths 200

runs the Bayesian learner under information gain, answered by the paper's teacher at 0 and 20 % flips, told
the teacher's model, its kind only or nothing, on `--truths` true parameters per domain drawn uniformly over
the range by `--draw` (real numbers: none is a truth of notebook 12 or of a test) x one seed (`--seed`, 900 by
default: no notebook, test or other benchmark uses it), `--episodes` answers each (40, as notebook 12's
held-out runs). It prints `answers_to_step` (the answers after which the learner is within one step of Phi in
90 % of the environments for good, its 95 % interval from resampling the truths, and the Shannon floor) and
`told_against_chosen` (told nothing's answers over told the model's, with their paired interval): the bars of
notebook 12's held-out claims (at most 10 answers with perfect answers, 30 at 20 % flips, told the kind; told
nothing at most 1.25 times told the model) read on many more environments than its 30 per domain. The runs
share the local cores (`hipref.sweep.run_sweep`, nothing cached); nothing is written to disk.

`--family without_memory` gives the learner told nothing `model_family()` without its two myopic models with
memory (the family before `hipref.learners.pictures`), to read what those models cost on the same
environments.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import pandas as pd

from hipref.experiments.answers_tables import answers_to_step, told_against_chosen
from hipref.experiments.answers_to_success import STEP_BOUNDS, AnswersCell, run_answers
from hipref.experiments.domains import DOMAINS
from hipref.learners.answer_models import TOLD, AnswerModel, model_family
from hipref.sweep import NO_CACHE, run_sweep


def truths(domain: str, count: int, draw: int) -> tuple[float, ...]:
    """`count` true parameters of `domain` drawn uniformly over its range from the stream `draw`: real
    numbers, so none is a truth a notebook or a test names, and distinct to the 6 decimals the rows keep (a
    value that rounds to one already drawn is drawn again), so no two environments are read as one."""
    phi = DOMAINS[domain].candidates
    rng = np.random.default_rng([draw, list(DOMAINS).index(domain)])
    values = list(rng.uniform(phi.low, phi.high, count))
    while len({round(v, 6) for v in values}) < count:
        kept: dict[float, float] = {}
        for v in values:
            kept.setdefault(round(v, 6), v)
        values = [*kept.values(), *rng.uniform(phi.low, phi.high, count - len(kept))]
    return tuple(float(v) for v in sorted(values))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--truths", type=int, default=200, help="true parameters per domain (at least 2)")
    parser.add_argument("--seed", type=int, default=900, help="the environments' seed")
    parser.add_argument("--draw", type=int, default=0, help="the stream the truths are drawn from")
    parser.add_argument("--episodes", type=int, default=40, help="answers per run")
    parser.add_argument(
        "--family",
        choices=("all", "without_memory"),
        default="all",
        help="the answer models told nothing weighs: model_family()'s, or those without the myopic memory",
    )
    args = parser.parse_args()
    if args.truths < 2 or args.episodes < 1:
        parser.error(
            f"--truths must be at least 2 and --episodes at least 1, got {args.truths}, {args.episodes}"
        )
    cells = [
        AnswersCell(domain, truth, args.seed, "mistake", noise, "information_gain", told, args.episodes)
        for domain in DOMAINS
        for noise in STEP_BOUNDS
        for told in TOLD
        for truth in truths(domain, args.truths, args.draw)
    ]
    start = time.perf_counter()
    run = run_answers if args.family == "all" else run_without_memory
    rows = run_sweep(run, cells, cache_dir=NO_CACHE, desc="held-out answers")
    seconds = time.perf_counter() - start
    steps = answers_to_step(rows)
    print(f"{len(cells)} runs of {args.episodes} answers in {seconds:.0f} s; {args.truths} truths per domain")
    print(steps.round(2).to_string(index=False))
    print(told_against_chosen(steps, rows).to_string(index=False, float_format=lambda v: f"{v:.3g}"))


def without_memory() -> tuple[AnswerModel, ...]:
    """`model_family()` without the myopic models that carry the picture's memory."""
    return tuple(model for model in model_family() if not model.memory)


def run_without_memory(cell: AnswersCell) -> pd.DataFrame:
    """`run_answers`, the learner told nothing weighing `without_memory()` (a sweep's cell function)."""
    return run_answers(cell, without_memory() if cell.told == "nothing" else None)


if __name__ == "__main__":
    main()

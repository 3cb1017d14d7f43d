"""What not knowing the teacher's model costs the Bayesian learner (notebook 12's answers part, no physics).

`python -m hipref.bench.model_choice --grid heldout` runs the learner under information gain, told the
teacher's model and told nothing (every answer model weighed by its marginal likelihood), for the paper's
teacher at 20 % flips and the graded teachers of notebook 11 (stochastic, myopic, distance), on notebook 12's
full-profile environments ('study': its five truths x seeds 0-1) or on held-out ones ('heldout': truths it
does not use x seeds 100-104). It prints `told_against_chosen` (answers to one step of Phi in 90 % of the
environments, or final errors where the told learner never gets there) and the mean wall time of one run
of each. Nothing is written to disk.
"""

from __future__ import annotations

import argparse
import time

import pandas as pd

from hipref.experiments.answers_to_success import (
    AnswersCell,
    answers_to_step,
    run_answers,
    told_against_chosen,
)

STUDY: dict[str, tuple[float, ...]] = {
    "wiping": (0.54, 0.62, 0.7, 0.78, 0.86),
    "pushing": (9.25, 11.5, 14.0, 16.5, 18.75),
}
HELDOUT: dict[str, tuple[float, ...]] = {
    "wiping": (0.58, 0.66, 0.74, 0.82),
    "pushing": (10.0, 13.0, 15.0, 17.5),
}
GRIDS: dict[str, tuple[dict[str, tuple[float, ...]], range]] = {
    "study": (STUDY, range(2)),
    "heldout": (HELDOUT, range(100, 105)),
}
TEACHERS = (("mistake", 0.2), ("stochastic", 0.0), ("myopic", 0.0), ("distance", 0.0))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grid", choices=tuple(GRIDS), default="heldout")
    parser.add_argument("--episodes", type=int, default=330)
    args = parser.parse_args()
    truths, seeds = GRIDS[args.grid]
    frames: list[pd.DataFrame] = []
    seconds: dict[str, list[float]] = {"model": [], "nothing": []}
    for domain, values in truths.items():
        for teacher, noise in TEACHERS:
            for told in seconds:
                for truth in values:
                    for seed in seeds:
                        cell = AnswersCell(
                            domain, truth, seed, teacher, noise, "information_gain", told, args.episodes
                        )
                        start = time.perf_counter()
                        frames.append(run_answers(cell))
                        seconds[told].append(time.perf_counter() - start)
    rows = pd.concat(frames, ignore_index=True)
    table = told_against_chosen(answers_to_step(rows), rows)
    columns = ["domain", "teacher", "noise", "model", "nothing", "model_error", "nothing_error"]
    print(table[[*columns, "nothing_ratio", "compared"]].to_string(index=False))
    for told, times in seconds.items():
        print(f"told {told}: {sum(times) / len(times):.2f} s per run of {args.episodes} answers")


if __name__ == "__main__":
    main()

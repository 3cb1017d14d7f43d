"""Where notebook 12's time goes: the seconds of each kind of run of its sweep.

`python -m hipref.bench.answers_time` reads notebook 12's parameters of a profile (`--profile full`, the
default, or `quick`), runs every cell of its sweep in this process, one after another, and prints, per kind of
run, how many there are and the seconds they take together: the task part's runs (MuJoCo, the real
controllers) per learner, flip rate and query rule, beside the true parameter's, and the answers part's (no
physics) per query rule and what the Bayesian learner is told of the teacher, the held-out replication's (its
answers and its task runs) apart. `--part answers` times the answers part alone. The notebook runs the same
cells on two worker processes; their sum here is the work it shares between them.

The task part reads the study's cached artefacts (the pretrained SI networks, the learning clips and the
evaluation episodes that notebooks 02-04 execute) and builds what is missing, as the notebook does; no cell's
rows are read from or written to the sweep's cache, and nothing is written to `results/`.
"""

from __future__ import annotations

import argparse
import time
from typing import Any

import nbformat
import pandas as pd

from hipref.experiments.answers_to_success import AnswersCell, AnswersConfig, AtTruth, run_cell
from hipref.experiments.si_run import SIRun
from hipref.notebook import config_from_parameters
from hipref.run_notebook import ROOT, load_parameters

NAME = "12_answers_to_success"


def notebook_config(profile: str) -> AnswersConfig:
    """Notebook 12's config at `profile`, as papermill gives it: the parameters cell's defaults, then the
    profile's parameter file over them."""
    notebook = nbformat.read(ROOT / "notebooks" / f"{NAME}.ipynb", as_version=4)
    (cell,) = (c for c in notebook.cells if "parameters" in c.metadata.get("tags", ()))
    namespace: dict[str, Any] = {}
    # The notebook's own parameters cell (typed assignments of literals), its annotations evaluated as the
    # kernel evaluates them, not as strings under this module's `from __future__ import annotations`.
    exec(compile(cell.source, "parameters", "exec", dont_inherit=True), namespace)
    namespace.update(load_parameters(ROOT / "params" / profile / f"{NAME}.yaml"))
    namespace.pop("__builtins__")
    return config_from_parameters(AnswersConfig, namespace)


def kind_of_run(
    cell: SIRun | AnswersCell | AtTruth, held_out_seeds: tuple[int, ...]
) -> tuple[str, str, str, str]:
    """(part, what runs, its query rule, its flip rate or what the learner is told) of one cell."""
    if isinstance(cell, AnswersCell):
        part = "held_out" if cell.seed in held_out_seeds else "answers"
        return part, f"bayes, told {cell.told}", cell.query_rule, f"{cell.episodes} answers"
    run = cell.run if isinstance(cell, AtTruth) else cell
    part = "held_out task" if run.seed in held_out_seeds else "task"
    if isinstance(cell, AtTruth):
        return part, "true_parameter", "", "no teacher"
    return part, cell.method, cell.fine_tuning.pesi.candidate_sampling, f"{cell.noise:.0%} flips"


def time_parts(config: AnswersConfig, parts: tuple[str, ...]) -> pd.DataFrame:
    """Per kind of run (`kind_of_run`) of `parts` ('task', 'answers'; the held-out replication's runs come
    with their part), the number of runs and their seconds, run one after another."""
    cells: list[SIRun | AnswersCell | AtTruth] = []
    if "task" in parts:
        config.pretrain(config.domains)
        cells += [*config.task_cells(), *config.truth_cells(), *config.held_out_task_cells()]
    if "answers" in parts:
        cells += [*config.answers_cells(), *config.held_out_cells()]
    rows = []
    for cell in cells:
        start = time.perf_counter()
        run_cell(cell)
        rows.append((*kind_of_run(cell, config.held_out_seeds), time.perf_counter() - start))
    frame = pd.DataFrame(rows, columns=["part", "run", "query_rule", "setting", "seconds"])
    table = frame.groupby(["part", "run", "query_rule", "setting"], sort=False)["seconds"].agg(
        ["count", "sum"]
    )
    return table.rename(columns={"count": "runs", "sum": "seconds"}).reset_index()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--profile", choices=("full", "quick"), default="full")
    parser.add_argument("--part", choices=("both", "answers"), default="both")
    args = parser.parse_args()
    parts = ("task", "answers") if args.part == "both" else ("answers",)
    table = time_parts(notebook_config(args.profile), parts)
    print(
        f"notebook 12 at the {args.profile} profile: each kind of run's runs and their seconds, one after "
        "another in this process (its start-up and imports not counted); 'setting': the flip rate of a "
        "task run, the answers of an answers run"
    )
    print(table.to_string(index=False, float_format=lambda v: f"{v:.1f}"))
    for part, seconds in table.groupby("part", sort=False)["seconds"].sum().items():
        print(f"{part}: {seconds:.1f} s")
    print(f"all: {table['seconds'].sum():.1f} s")


if __name__ == "__main__":
    main()

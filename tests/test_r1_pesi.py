"""R1 for the low level (`hipref.experiments.r1_pesi`): every environment of the grid is learnt by each of
its domain's methods under identical settings, so that PESI - OSI and PESI - PESI-CE are paired
differences; the held-out grid reruns the headline's methods on other environments with the study's
settings; and a run's rows say which grid they come from."""

from __future__ import annotations

import dataclasses
from collections import defaultdict

import pandas as pd
import pytest

from hipref.experiments import r1_pesi
from hipref.experiments.r1_pesi import HELD_OUT_METHODS, METHODS, R1PESIConfig, cells, held_out_cells

CONFIG = R1PESIConfig(
    heights=(0.6, 0.8),
    masses=(11.0,),
    seeds=2,
    episodes=6,
    eval_every=3,
    eval_episodes=2,
    n_trajectories=7,
    held_out_heights=(0.7, 0.75),
    held_out_masses=(15.0,),
    held_out_seeds=(5, 9),
)

PAIRED = (
    "ground_truth",
    "seed",
    "noise",
    "n_candidates",
    "evaluated_at",
    "eval_episodes",
    "eval_slices",
    "data",
)
"""What must be the same for every method in one environment: its truth and seed (so the teacher's draws
and the evaluation episodes), perfect preferences, N, the evaluation and the pretrained model."""


@pytest.mark.parametrize("domain", list(METHODS))
def test_every_environment_is_learnt_by_each_method_of_its_domain_with_perfect_preferences(
    domain: str,
) -> None:
    by_environment = defaultdict(list)
    for cell in cells(CONFIG):
        if cell.domain == domain:
            by_environment[cell.ground_truth, cell.seed].append(cell)
    assert sorted(by_environment) == sorted(CONFIG.environments(domain))
    assert len(by_environment) == len(CONFIG.truths(domain)) * CONFIG.seeds
    for runs in by_environment.values():
        assert sorted(run.method for run in runs) == sorted(METHODS[domain])
        for name in PAIRED:
            assert len({getattr(run, name) for run in runs}) == 1, name
        assert runs[0].noise == 0.0
        assert runs[0].evaluated_at == (0, 3, 6)


def test_the_held_out_grid_keeps_the_studys_settings_but_evaluates_only_at_the_end() -> None:
    held_out = CONFIG.held_out()
    assert held_out.truths("wiping") == CONFIG.held_out_heights
    assert held_out.truths("pushing") == CONFIG.held_out_masses
    assert held_out.eval_every == CONFIG.episodes
    kept = ("episodes", "eval_episodes", "eval_slices", "n_trajectories", "pretrain_steps", "learning_rate")
    for name in kept:
        assert getattr(held_out, name) == getattr(CONFIG, name), name
    runs = held_out_cells(CONFIG)
    # The same pretrained model and evaluation as the grid's runs: only the environments differ.
    assert {run.data for run in runs} == {CONFIG.data}
    assert {run.eval_episodes for run in runs} == {CONFIG.eval_episodes}
    for domain in METHODS:
        environments = {(run.ground_truth, run.seed) for run in runs if run.domain == domain}
        assert environments == set(CONFIG.held_out_environments(domain))
        assert len(environments) == len(held_out.truths(domain)) * len(CONFIG.held_out_seeds)
        for truth, seed in environments:
            methods = {
                run.method
                for run in runs
                if (run.domain, run.ground_truth, run.seed) == (domain, truth, seed)
            }
            assert methods == set(HELD_OUT_METHODS)


def test_a_run_pretrains_first_and_labels_each_row_with_its_grid(monkeypatch) -> None:
    events: list[str] = []

    def pretrain(self, domains, **sweep):
        events.append(f"pretrain {sorted(domains)}")

    def run_sweep(fn, swept, **sweep):
        events.append("sweep")
        keys = [(cell.domain, cell.method, cell.ground_truth, cell.seed) for cell in swept]
        return pd.DataFrame(keys, columns=["domain", "method", "ground_truth", "seed"]).assign(value=1.0)

    monkeypatch.setattr(R1PESIConfig, "pretrain", pretrain)
    monkeypatch.setattr(r1_pesi, "run_sweep", run_sweep)
    rows = r1_pesi.run(CONFIG, workers=1)
    assert events == ["pretrain ['pushing', 'wiping']", "sweep"]
    held_out = {(c.domain, c.method, c.ground_truth, c.seed) for c in held_out_cells(CONFIG)}
    study = {(c.domain, c.method, c.ground_truth, c.seed) for c in cells(CONFIG)}
    keys = list(zip(rows.domain, rows.method, rows.ground_truth, rows.seed, strict=True))
    assert set(keys) == held_out | study
    assert [key in held_out for key in keys] == list(rows.grid == "held_out")
    assert (rows.grid == "study").sum() == len(study)


def test_a_held_out_environment_must_lie_outside_the_grid() -> None:
    base = dataclasses.asdict(CONFIG)
    for name, value in (("held_out_heights", (0.8,)), ("held_out_masses", (11.0,)), ("held_out_seeds", (1,))):
        with pytest.raises(ValueError, match=name):
            R1PESIConfig(**base | {name: value})

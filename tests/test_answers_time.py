"""The benchmark of where notebook 12's time goes (`hipref.bench.answers_time`)."""

from __future__ import annotations

from dataclasses import replace

from hipref.bench.answers_time import kind_of_run, notebook_config, time_parts
from hipref.experiments.answers_to_success import AnswersCell


def test_the_profiles_read_as_papermill_gives_them() -> None:
    quick, full = notebook_config("quick"), notebook_config("full")
    # The quick profile is the parameters cell's defaults; the full one sets its own grid over them.
    assert quick.heights == (0.62, 0.78) and quick.episodes == 66 and quick.teachers == ("distance",)
    assert full.heights == (0.54, 0.62, 0.7, 0.78, 0.86) and full.episodes == 330
    assert full.held_out_seeds == (300,) and len(full.held_out_heights) == 30
    assert full.eval_slices == quick.eval_slices


def test_a_task_run_is_timed_under_its_learner_query_rule_and_flip_rate() -> None:
    kinds = {kind_of_run(cell, (300,)) for cell in notebook_config("quick").task_cells()}
    assert ("task", "co_pesi", "uniform", "20% flips") in kinds
    assert ("task", "bayes", "information_gain", "20% flips") in kinds
    assert len(kinds) == 6  # PESI and CO-PESI under uniform pairs, the two Bayesian learners under both rules


def test_every_run_of_the_answers_part_is_timed_once_under_its_kind() -> None:
    config = replace(
        notebook_config("quick"),
        domains=("wiping",),
        heights=(0.7,),
        episodes=5,
        checkpoints=(0, 5),
        noise_levels=(0.2,),
        blind_noise_levels=(0.2,),
        teachers=(),
        held_out_episodes=4,
    )
    table = time_parts(config, ("answers",))
    assert table["runs"].sum() == len(config.answers_cells()) + len(config.held_out_cells())
    assert set(table["part"]) == {"answers", "held_out"}
    held_out = table[table["part"] == "held_out"]
    assert set(held_out["run"]) == {"bayes, told model", "bayes, told kind", "bayes, told nothing"}
    assert set(held_out["setting"]) == {"4 answers"} and (table["seconds"] > 0).all()
    cell = AnswersCell("wiping", 0.7, 0, "mistake", 0.2, "uniform", "model", 5)
    assert kind_of_run(cell, (300,)) == ("answers", "bayes, told model", "uniform", "5 answers")

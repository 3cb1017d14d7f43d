"""Notebook 12's study: its floor, its read-outs and the refusals of its config."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from hipref.bench.held_out_steps import truths as drawn_truths
from hipref.bench.model_choice import TEACHERS, block_table, share_over, split_table, teacher_family
from hipref.experiments.answers_tables import (
    answers_interval,
    answers_to_step,
    efficiency,
    first_for_good,
    ratio_interval,
    shannon_floor,
    told_against_chosen,
)
from hipref.experiments.answers_to_success import (
    SUCCESS_AFTER,
    AnswersCell,
    AnswersConfig,
    AtTruth,
    answer_counts,
    run_answers,
)
from hipref.experiments.domains import DOMAINS
from hipref.experiments.si_run import FineTuning, SIRun
from hipref.learners.answer_models import model_family, told
from hipref.learners.pesi import PESIConfig
from hipref.teachers.models import TeacherModel


def test_the_shannon_floor_is_log2_k_over_the_channel_capacity() -> None:
    assert shannon_floor(41, 0.0) == pytest.approx(math.log2(41))
    # The figures for the 41 desk heights: 5.4, 10.1, 19.3 and 45.1 answers at 0, 10, 20, 30 %.
    for flip, answers in [(0.0, 5.4), (0.1, 10.1), (0.2, 19.3), (0.3, 45.1)]:
        assert shannon_floor(41, flip) == pytest.approx(answers, abs=0.05)
    with pytest.raises(ValueError, match="flip"):
        shannon_floor(41, 0.5)


def _answers_rows(errors: dict[tuple[float, int], list[float]], counts: list[int]) -> pd.DataFrame:
    rows = []
    for (truth, seed), values in errors.items():
        for count, value in zip(counts, values, strict=True):
            rows.append(
                dict(
                    domain="wiping",
                    method="bayes",
                    noise=0.0,
                    seed=seed,
                    episode=count,
                    metric="param_error",
                    value=value,
                    ground_truth=truth,
                    teacher="mistake",
                    query_rule="information_gain",
                    told="model",
                    part="answers",
                )
            )
    return pd.DataFrame(rows)


def test_answers_to_step_is_where_enough_environments_are_within_a_step_for_good() -> None:
    counts = [1, 2, 3, 4]
    errors = {
        (0.6, 0): [0.05, 0.005, 0.02, 0.001],  # leaves the step at 3: counts from 4 only
        (0.7, 0): [0.05, 0.005, 0.005, 0.001],
    }
    steps = answers_to_step(_answers_rows(errors, counts))
    assert steps.loc[0, "answers"] == 4
    assert steps.loc[0, "floor"] == pytest.approx(math.log2(41))
    # 9 of 10 environments suffice: one that never gets there does not stop the count.
    errors = {(0.5 + i / 100, 0): [0.05, 0.005, 0.005, 0.005] for i in range(9)}
    errors[(0.9, 0)] = [0.05, 0.05, 0.05, 0.05]
    assert answers_to_step(_answers_rows(errors, counts)).loc[0, "answers"] == 2
    errors[(0.89, 0)] = [0.05, 0.05, 0.05, 0.05]
    assert np.isnan(answers_to_step(_answers_rows(errors, counts)).loc[0, "answers"])


def test_the_answers_interval_resamples_truths_with_all_their_seeds() -> None:
    # Twenty truths, one slow (within one step from answer 3) and nineteen fast (from 2), ten copies of each.
    # A resample of the truths holding the slow one three times or more (probability 0.075) has 30 of 200
    # environments short at answer 2 and needs 3; drawn one by one, 21 slow environments of 200 would be
    # needed (probability 0.0005), and the interval would be 2-2.
    slow, fast = [0.05, 0.05, 0.005, 0.005], [0.05, 0.005, 0.005, 0.005]
    once = {(0.5 + i / 100, 0): slow if i == 0 else fast for i in range(20)}
    copies = {(truth, seed): values for (truth, _), values in once.items() for seed in range(10)}
    rows = _answers_rows(copies, [1, 2, 3, 4])
    step = answers_to_step(rows).iloc[0]
    assert (step["answers"], step["low"], step["high"], step["truths"]) == (2, 2, 3, 20)
    assert answers_interval(rows, resamples=1000) == (2.0, 3.0)
    # Not a grid of truths x seeds (one run missing), or a single truth: no interval, the count still read.
    gap = rows[~((rows["ground_truth"] == 0.5) & (rows["seed"] == 9))]
    assert np.isnan(answers_interval(gap)).all() and answers_to_step(gap).loc[0, "answers"] == 2
    single = rows[rows["ground_truth"] == 0.51]
    assert np.isnan(answers_interval(single)).all()


def test_the_answers_to_a_step_of_many_sets_at_once_follow_the_definition() -> None:
    # The definition, checkpoint by checkpoint: the first count from which on every checkpoint has at least
    # 90 % of the environments within one step.
    def counted(within: np.ndarray, counts: np.ndarray) -> float:
        shares = within.mean(axis=0)
        return next((float(c) for k, c in enumerate(counts) if (shares[k:] >= 0.9).all()), math.inf)

    rng = np.random.default_rng(3)
    counts = np.array([1.0, 2.0, 4.0, 8.0, 16.0])
    for environments in (5, 10, 14):
        sets = rng.random((40, environments, counts.size)) < 0.85
        expected = [counted(within, counts) for within in sets]
        np.testing.assert_array_equal(first_for_good(sets, counts), expected)


def test_the_ratio_interval_pairs_the_two_learners_on_the_same_environments() -> None:
    # Two of twelve environments are slow; told nothing needs one answer more than told the model in each.
    slow, fast = [0.05, 0.05, 0.005, 0.005], [0.05, 0.005, 0.005, 0.005]
    errors = {(0.5 + i / 100, 0): slow if i % 6 == 0 else fast for i in range(12)}
    later = {key: [values[0], *values[:-1]] for key, values in errors.items()}
    rows = pd.concat(
        [_answers_rows(errors, [1, 2, 3, 4]), _answers_rows(later, [1, 2, 3, 4]).assign(told="nothing")],
        ignore_index=True,
    )
    low, high = ratio_interval(rows, "nothing", by_answers=True, resamples=400)
    # Paired, a resample with at most one slow environment gives 3 / 2, else 4 / 3. Drawn apart, the two
    # counts would also give 1 and 2.
    assert (low, high) == pytest.approx((4 / 3, 3 / 2))
    table = told_against_chosen(answers_to_step(rows), rows).iloc[0]
    assert table["nothing_ratio"] == pytest.approx(4 / 3)
    assert (table["nothing_low"], table["nothing_high"]) == pytest.approx((4 / 3, 3 / 2))


def test_the_ratio_interval_resamples_truths_with_all_their_seeds() -> None:
    # With perfect answers a truth's seeds are copies of one environment: five copies of each truth must give
    # the interval of the truths alone, not one five times as certain.
    slow, fast = [0.05, 0.05, 0.005, 0.005], [0.05, 0.005, 0.005, 0.005]
    once = {(0.5 + i / 100, 0): slow if i % 4 == 0 else fast for i in range(8)}
    copies = {(truth, seed): values for (truth, _), values in once.items() for seed in range(5)}

    def later(errors: dict[tuple[float, int], list[float]]) -> pd.DataFrame:
        shifted = {key: [values[0], *values[:-1]] for key, values in errors.items()}
        return pd.concat(
            [
                _answers_rows(errors, [1, 2, 3, 4]),
                _answers_rows(shifted, [1, 2, 3, 4]).assign(told="nothing"),
            ],
            ignore_index=True,
        )

    interval = ratio_interval(later(copies), "nothing", by_answers=True, resamples=400)
    assert interval == ratio_interval(later(once), "nothing", by_answers=True, resamples=400)
    assert interval[0] < interval[1]
    uneven = later(copies)
    uneven = uneven[~((uneven["ground_truth"] == 0.5) & (uneven["seed"] == 4))]
    with pytest.raises(ValueError, match="truths x seeds"):
        ratio_interval(uneven, "nothing", by_answers=True)


def test_where_the_learner_not_told_never_gets_there_its_ratio_is_infinite() -> None:
    errors = {(0.5 + i / 100, 0): [0.05, 0.005] for i in range(6)}
    never = {key: [0.05, 0.05] for key in errors}
    rows = pd.concat(
        [_answers_rows(errors, [1, 2]), _answers_rows(never, [1, 2]).assign(told="nothing")],
        ignore_index=True,
    )
    table = told_against_chosen(answers_to_step(rows), rows).iloc[0]
    assert table["compared"] == "answers" and np.isnan(table["nothing"])
    assert table["nothing_ratio"] == np.inf and table["nothing_low"] == table["nothing_high"] == np.inf
    assert np.isnan(table["kind_ratio"])


def test_where_the_told_learner_never_gets_there_the_interval_pairs_the_final_errors() -> None:
    # Never within one step: the ratio is of the mean final errors, the same environments drawn for both.
    errors = {(0.5 + i / 100, 0): [0.5, 0.1 + 0.1 * i] for i in range(10)}
    doubled = {key: [2 * v for v in values] for key, values in errors.items()}
    rows = pd.concat(
        [_answers_rows(errors, [1, 2]), _answers_rows(doubled, [1, 2]).assign(told="nothing")],
        ignore_index=True,
    )
    assert ratio_interval(rows, "nothing", by_answers=False) == pytest.approx((2.0, 2.0))
    table = told_against_chosen(answers_to_step(rows), rows).iloc[0]
    assert table["compared"] == "final error" and table["nothing_ratio"] == pytest.approx(2.0)
    assert (table["nothing_low"], table["nothing_high"]) == pytest.approx((2.0, 2.0))
    assert np.isnan(table["kind_low"]) and np.isnan(table["kind_high"])
    moved = rows.assign(seed=np.where(rows["told"] == "nothing", 1, rows["seed"]))
    with pytest.raises(ValueError, match="environments"):
        ratio_interval(moved, "nothing", by_answers=False)


def test_efficiency_finds_the_answers_the_bayesian_learner_needs_to_match_pesi() -> None:
    base = dict(
        domain="wiping",
        noise=0.2,
        seed=0,
        ground_truth=0.7,
        metric="param_error",
        told="model",
        teacher="mistake",
        query_rule="uniform",
    )
    rows = pd.DataFrame(
        [
            dict(base, method="pesi", part="task", episode=e, value=v)
            for e, v in [(0, 0.1), (10, 0.04), (20, 0.03)]
        ]
        + [
            dict(base, method="bayes", part="answers", episode=e, value=v)
            for e, v in [(1, 0.1), (2, 0.035), (3, 0.02)]
        ]
    )
    table = efficiency(rows)
    assert list(table.bayes_answers) == [2.0, 3.0]
    assert list(table.efficiency) == [0.2, 0.15]


def test_told_against_chosen_divides_answers_or_else_final_errors() -> None:
    steps = pd.DataFrame(
        [
            dict(
                domain="wiping", teacher=teacher, noise=0.2, query_rule="information_gain", told=t, answers=a
            )
            for teacher, answers in [("mistake", (20.0, 22.0, 30.0)), ("myopic", (np.nan, np.nan, np.nan))]
            for t, a in zip(("model", "kind", "nothing"), answers, strict=True)
        ]
        # A flip rate with the told learner alone (not among blind_noise_levels): left out.
        + [
            dict(
                domain="wiping",
                teacher="mistake",
                noise=0.4,
                query_rule="information_gain",
                told="model",
                answers=9.0,
            )
        ]
    )
    rows = pd.DataFrame(
        [
            dict(
                domain="wiping",
                teacher=teacher,
                noise=0.2,
                query_rule="information_gain",
                told=t,
                part="answers",
                metric="param_error",
                episode=330,
                seed=0,
                ground_truth=0.7,
                value=v,
            )
            for teacher in ("mistake", "myopic")
            for t, v in [("model", 0.02), ("kind", 0.03), ("nothing", 0.05)]
        ]
    )
    table = told_against_chosen(steps, rows).set_index("teacher")
    assert table.loc["mistake", "kind_ratio"] == pytest.approx(1.1)
    assert table.loc["mistake", "nothing_ratio"] == pytest.approx(1.5)
    assert table.loc["myopic", "nothing_ratio"] == pytest.approx(2.5)
    assert table.loc["myopic", "compared"] == "final error"
    assert set(table.noise) == {0.2}


def test_answer_counts_are_dense_early_and_end_at_the_last_answer() -> None:
    counts = answer_counts(333)
    assert counts[:40] == tuple(range(1, 41)) and counts[-1] == 333
    assert list(counts) == sorted(set(counts))


def test_an_answers_run_is_deterministic_and_reaches_the_truth_with_perfect_answers() -> None:
    cell = AnswersCell("pushing", 13.3, 4, "mistake", 0.0, "information_gain", "kind", 12)
    first, second = run_answers(cell), run_answers(cell)
    pd.testing.assert_frame_equal(first, second)
    errors = first[first.metric == "param_error"].set_index("episode").value
    assert errors.loc[12] <= 0.25
    assert set(first.told) == {"kind"} and set(first.part) == {"answers"}


def test_a_learner_given_only_the_true_model_answers_as_the_learner_told_it() -> None:
    # The models a run is given replace what its cell says it is told.
    cell = AnswersCell("wiping", 0.613, 5, "distance", 0.0, "information_gain", "nothing", 15)
    given = run_answers(cell, (told(TeacherModel("distance"), 0.0),))
    told_cell = run_answers(AnswersCell("wiping", 0.613, 5, "distance", 0.0, "information_gain", "model", 15))
    weighing = run_answers(cell)
    pd.testing.assert_frame_equal(given.drop(columns="told"), told_cell.drop(columns="told"))
    assert not given["value"].equals(weighing["value"])


def test_a_reader_hears_the_askers_queries_and_answers() -> None:
    # Reading with the asker's own models gives the asker's rows; reading told the model, the queries the
    # learner told nothing chose, gives neither whole learner's errors, and the final rows are the reader's.
    cell = AnswersCell("wiping", 0.613, 5, "mistake", 0.2, "information_gain", "nothing", 12)
    family, given = model_family(), (told(TeacherModel("mistake"), 0.2),)
    asker = run_answers(cell)
    pd.testing.assert_frame_equal(run_answers(cell, family, reader=family), asker)
    read = run_answers(cell, family, reader=given)
    for whole in (asker, run_answers(cell, given)):
        errors = [rows.loc[rows.metric == "param_error", "value"].to_numpy() for rows in (read, whole)]
        assert not np.array_equal(*errors)
    read_kind, asker_kind = (
        r.set_index("metric").loc["true_model_probability", "value"] for r in (read, asker)
    )
    assert read_kind == pytest.approx(1.0) and asker_kind < 0.99


def test_the_split_table_pairs_each_asker_with_each_reader() -> None:
    table = split_table({"wiping": (0.613,)}, range(5, 6), 6, None).set_index("teacher")
    pairings = {f"{a}_asks_{r}_reads" for a in ("model", "nothing") for r in ("model", "nothing")}
    assert pairings <= set(table.columns) and len(table) == len(TEACHERS)
    for level in ("model", "nothing"):
        whole = run_answers(AnswersCell("wiping", 0.613, 5, "skip", 0.0, "information_gain", level, 6))
        steps = answers_to_step(whole)
        assert table.loc["skip", f"{level}_asks_{level}_reads"] == steps["answers"].item()


def test_the_block_table_runs_the_next_seeds_and_counts_the_ratios_over_the_bar() -> None:
    table = block_table({"wiping": (0.613,)}, range(5, 7), 20, 2, None).set_index(["teacher", "noise"])
    assert "myopic" not in table.index.get_level_values("teacher") and len(table) == len(TEACHERS) - 1
    runs = {}
    for seed in (5, 6, 7, 8):  # block 0 the grid's two seeds, block 1 the next two
        cell = AnswersCell("wiping", 0.613, seed, "mistake", 0.2, "information_gain", "model", 20)
        runs[seed] = run_answers(cell)
    row = table.loc[("mistake", 0.2)]
    for block, seeds in enumerate(((5, 6), (7, 8))):
        rows = pd.concat([runs[seed] for seed in seeds], ignore_index=True)
        assert row["model"][block] == answers_to_step(rows)["answers"].item()
    assert row["model"] == [14.0, 17.0]
    assert (
        row["model_pooled"] == answers_to_step(pd.concat(runs.values(), ignore_index=True))["answers"].item()
    )
    # Told nothing needs 18 answers (over 1.25 x 14) on block 0 and never gets there on block 1.
    assert np.isnan(row["nothing"][1]) and row["nothing_over"] == 1.0 and row["model_over"] == 0.0
    # Blocks where neither learner gets within one step are left out of a share.
    distance = table.loc[("distance", 0.0)]
    assert np.isnan(distance["model_over"]) and distance["nothing_over"] == 0.0


def test_a_count_that_never_gets_there_is_over_any_that_does() -> None:
    nan = float("nan")
    assert share_over([(nan, 3.0), (3.0, nan), (nan, nan), (5.0, 4.0), (6.0, 4.0)]) == 0.5
    assert np.isnan(share_over([(nan, nan)]))


def test_the_teachers_family_holds_each_benchmark_teacher_once() -> None:
    family = teacher_family()
    assert set(family) == {told(TeacherModel(kind), noise) for kind, noise in TEACHERS}
    assert len(family) == len(set(family)) == 7
    assert {m.kind for m in family} == {"flip", "stochastic", "skip", "equal", "myopic", "distance"}


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (dict(teachers=("mistake",)), "teachers"),
        (dict(noise_levels=(0.2, 0.2)), "repeat"),
        (dict(noise_levels=(0.5,)), "noise_levels"),
        (dict(noise_levels=(0.0,), blind_noise_levels=(0.0, 0.2)), "blind_noise_levels"),
        (dict(methods=("pesi", "osi")), "methods"),
        (dict(task_rules=("bisect",)), "task_rules"),
        (dict(checkpoints=(5, 66)), "checkpoints"),
        (dict(checkpoints=(0, 20, 10, 66)), "checkpoints"),
        (dict(domains=()), "domains"),
        (dict(held_out_heights=(0.62,)), "held_out_heights"),
        (dict(held_out_masses=()), "held_out_masses"),
        (dict(held_out_seeds=(0,)), "held_out_seeds"),
        (dict(held_out_seeds=(300, 300)), "held_out_seeds"),
        (dict(held_out_episodes=0), "held_out_episodes"),
    ],
)
def test_the_config_refuses_bad_settings_by_name(change: dict[str, object], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        AnswersConfig(**change)  # type: ignore[arg-type]


def test_told_is_the_bayesian_learners_alone_and_belief_sampling_is_pesis() -> None:
    with pytest.raises(ValueError, match="told"):
        SIRun("wiping", "pesi", 0.7, told="model")
    with pytest.raises(ValueError, match="told"):
        SIRun("wiping", "bayes", 0.7, told="everything")
    with pytest.raises(ValueError, match="belief"):
        SIRun("wiping", "bayes", 0.7, fine_tuning=FineTuning(PESIConfig(candidate_sampling="belief")))
    assert SIRun("wiping", "bayes", 0.7, episodes=20, checkpoints=(0, 5, 20)).evaluated_at == (0, 5, 20)
    assert SIRun("wiping", "pesi", 0.7, episodes=66, eval_every=33).evaluated_at == (0, 33, 66)


def test_chosen_queries_and_blind_learners_run_only_where_the_config_says() -> None:
    config = AnswersConfig(
        episodes=66,
        checkpoints=(0, 5, 20),
        noise_levels=(0.0, 0.4),
        blind_noise_levels=(0.0,),
        task_noise_levels=(0.2,),
    )
    task = config.task_cells()
    rules = {(c.method, c.fine_tuning.pesi.candidate_sampling) for c in task}
    assert rules == {
        ("pesi", "uniform"),
        ("co_pesi", "uniform"),
        *((m, r) for m in ("bayes", "bayes_si") for r in ("uniform", "information_gain")),
    }
    assert {c.episodes for c in task} == {20}
    told = {(c.noise, c.query_rule, c.told) for c in config.answers_cells() if c.teacher == "mistake"}
    assert {t for e, r, t in told if e == 0.4} == {"model"}
    assert {t for e, r, t in told if e == 0.0 and r == "information_gain"} == {"model", "kind", "nothing"}
    assert {c.episodes for c in config.answers_cells()} == {66}
    # The true parameter once per task environment, on the same evaluations as the task's runs.
    truths = config.truth_cells()
    environments = {(c.domain, c.ground_truth, c.seed) for c in task}
    assert sorted((c.run.domain, c.run.ground_truth, c.run.seed) for c in truths) == sorted(environments)
    assert {(c.run.evaluated_at, c.run.eval_episodes) for c in truths} == {
        (c.evaluated_at, c.eval_episodes) for c in task
    }


def test_the_held_out_success_runs_the_blind_learner_and_the_truth_on_held_out_environments_only() -> None:
    config = AnswersConfig(
        seeds=2,
        task_noise_levels=(0.0, 0.2),
        held_out_heights=(0.57, 0.83),
        held_out_masses=(9.5,),
        held_out_seeds=(7,),
    )
    cells = config.held_out_task_cells()
    runs = [c for c in cells if isinstance(c, SIRun)]
    truths = [c.run for c in cells if isinstance(c, AtTruth)]
    held = {("wiping", 0.57, 7), ("wiping", 0.83, 7), ("pushing", 9.5, 7)}
    assert {(c.domain, c.ground_truth, c.seed) for c in runs} == held
    assert sorted((c.domain, c.ground_truth, c.seed) for c in truths) == sorted(held)
    assert {(c.method, c.told, c.fine_tuning.pesi.candidate_sampling) for c in runs} == {
        ("bayes", "nothing", "information_gain")
    }
    assert sorted(c.noise for c in runs) == sorted([0.0, 0.2] * 3)
    # Read after SUCCESS_AFTER answers, on the evaluation episodes the true parameter meets too.
    assert {(c.episodes, c.evaluated_at, c.eval_episodes) for c in runs} == {
        (c.episodes, c.evaluated_at, c.eval_episodes) for c in truths
    }
    assert {c.episodes for c in runs} == {SUCCESS_AFTER}


def test_the_held_out_replication_runs_the_claims_settings_on_its_own_environments_only() -> None:
    config = AnswersConfig(
        seeds=2,
        held_out_heights=(0.57, 0.83),
        held_out_masses=(9.5,),
        held_out_seeds=(7, 9),
        held_out_episodes=12,
    )
    cells = config.held_out_cells()
    study = {(c.domain, c.ground_truth, c.seed) for c in config.answers_cells()}
    held = {(c.domain, c.ground_truth, c.seed) for c in cells}
    assert not study & held
    assert held == {("wiping", t, s) for t in (0.57, 0.83) for s in (7, 9)} | {
        ("pushing", 9.5, s) for s in (7, 9)
    }
    assert {(c.teacher, c.noise, c.query_rule, c.told) for c in cells} == {
        ("mistake", e, "information_gain", t)
        for e in config.blind_noise_levels
        for t in ("model", "kind", "nothing")
    }
    assert {c.episodes for c in cells} == {12}


def test_the_benchmarks_held_out_truths_are_drawn_over_the_range_and_not_notebook_12s() -> None:
    params = Path(__file__).parents[1] / "params" / "full" / "12_answers_to_success.yaml"
    full = yaml.safe_load(params.read_text())
    named_in = {"wiping": ("heights", "held_out_heights"), "pushing": ("masses", "held_out_masses")}
    for domain, grids in named_in.items():
        phi = DOMAINS[domain].candidates
        named = {float(v) for grid in grids for v in full[grid]}
        drawn = drawn_truths(domain, 200, 0)
        assert drawn == drawn_truths(domain, 200, 0)  # the same draw: the same truths
        assert len(set(drawn)) == 200 and not set(drawn) & named
        assert phi.low <= min(drawn) < phi.low + 0.05 * (phi.high - phi.low)
        assert phi.high - 0.05 * (phi.high - phi.low) < max(drawn) <= phi.high
        assert not set(drawn) & set(drawn_truths(domain, 200, 1))  # another draw: other truths
    # Distinct as the rows keep them (6 decimals), so two environments are never read as one: 5,000 draws over
    # 0.4 m would round alike about 30 times without the redraw.
    many = drawn_truths("wiping", 5000, 0)
    assert len({round(v, 6) for v in many}) == len(many) == 5000

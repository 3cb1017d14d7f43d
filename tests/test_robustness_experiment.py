"""The teachers-and-robustness study's plumbing: paired cells, refused bad parameters, the PESI-paired
difference table, the best-learner verdict, the teachers' noise and the filters' scores."""

import pandas as pd
import pytest

from hipref.experiments import robustness
from hipref.experiments.robustness import (
    LEARNERS,
    NOISE_TOLERANCE,
    TEACHERS,
    RobustnessConfig,
    best_learner,
    cells,
    difference_table,
    filter_quality,
    noise_cells,
    noise_table,
)
from hipref.teachers.models import TeacherModel


def test_every_learner_meets_every_teacher_in_every_environment() -> None:
    config = RobustnessConfig(domains=("pushing",), masses=(9.25, 14.0), teachers=TEACHERS, methods=LEARNERS)
    grid = cells(config)
    assert len(grid) == len(TEACHERS) * len(LEARNERS) * 2
    for teacher in TEACHERS:
        for method in LEARNERS:
            runs = [c for c in grid if c.teacher == TeacherModel(teacher) and c.method == method]
            assert sorted((c.ground_truth, c.seed) for c in runs) == [(9.25, 0), (14.0, 0)]
            # Only the paper's teacher flips on top of its rule.
            assert {c.noise for c in runs} == {0.2 if teacher == "mistake" else 0.0}
    # The paper's teacher is the default model, so its PESI runs are notebook 04's cells.
    assert all(c.teacher == TeacherModel() for c in grid if c.noise == 0.2)
    assert len(noise_cells(config)) == len(TEACHERS) * 2


@pytest.mark.parametrize(
    ("field", "value"),
    [("teachers", ("lazy",)), ("methods", ("co_pesi",)), ("methods", ("magic",)), ("noise", 2.0)],
)
def test_a_bad_parameter_is_refused_with_its_name(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=field):
        RobustnessConfig(**{field: value})


def _rows(errors: dict[str, list[float]], successes: dict[str, list[float]]) -> pd.DataFrame:
    records = []
    for method in errors:
        for i, (e, s) in enumerate(zip(errors[method], successes[method], strict=True)):
            for metric, value in (("param_error", e), ("success_rate", s)):
                records.append(
                    dict(
                        domain="wiping",
                        method=method,
                        noise=0.0,
                        seed=0,
                        episode=99,
                        metric=metric,
                        value=value,
                        ground_truth=0.5 + 0.1 * i,
                        teacher="skip",
                    )
                )
    return pd.DataFrame(records)


def test_the_best_learner_is_the_lowest_paired_error_and_its_verdict_needs_both_metrics() -> None:
    rows = _rows(
        {
            "pesi": [0.05, 0.06, 0.07, 0.05, 0.06],
            "pesi_rime": [0.02, 0.03, 0.03, 0.02, 0.03],
            "pesi_smoothed": [0.05] * 5,
        },
        {
            "pesi": [0.4, 0.5, 0.4, 0.5, 0.4],
            "pesi_rime": [0.8, 0.9, 0.8, 0.9, 0.8],
            "pesi_smoothed": [0.4] * 5,
        },
    )
    table = difference_table(rows, resamples=500)
    assert set(table.method) == {"pesi_rime", "pesi_smoothed"} and set(table.n) == {5}
    method, held, text = best_learner(table, "wiping", "skip")
    assert (method, held) == ("pesi_rime", "yes")
    assert "pesi_rime - pesi" in text
    # A lower error but no better success: the claim is not shown.
    rows = _rows({"pesi": [0.05] * 5, "pesi_rime": [0.02] * 5}, {"pesi": [0.5] * 5, "pesi_rime": [0.5] * 5})
    assert (
        best_learner(difference_table(rows, resamples=500), "wiping", "skip")[1] == "no difference detected"
    )


def test_a_float32_rounding_difference_is_no_difference() -> None:
    # A filter that forgets nothing makes PESI's updates summed in another order: estimates ulps apart.
    rows = _rows(
        {
            "pesi": [0.05, 0.06, 0.07, 0.05, 0.06],
            "pesi_small_loss": [0.05 - 1e-8, 0.06 - 2e-8, 0.07, 0.05 - 1e-8, 0.06 - 1e-8],
        },
        {"pesi": [0.5] * 5, "pesi_small_loss": [0.5] * 5},
    )
    table = difference_table(rows, resamples=500)
    error = table[table.metric == "param_error"].iloc[0]
    assert (error["mean"], error["low"], error["high"]) == (0.0, 0.0, 0.0)
    assert best_learner(table, "wiping", "skip")[1] == "no difference detected"


def _teacher_rows(records: list[tuple[str, float, int, str, float]]) -> pd.DataFrame:
    return pd.DataFrame(
        [
            dict(
                domain="pushing",
                method="teacher",
                noise=0.0,
                seed=seed,
                episode=66,
                metric=metric,
                value=value,
                ground_truth=truth,
                teacher=teacher,
            )
            for teacher, truth, seed, metric, value in records
        ]
    )


def test_the_noise_table_pairs_estimate_and_truth_per_environment() -> None:
    records = []
    for truth, true, estimate in (
        (11.0, 0.20, 0.22),
        (14.0, 0.10, 0.13),
        (17.0, 0.30, 0.31),
        (9.0, 0.20, 0.22),
        (19.0, 0.10, 0.12),
    ):
        records += [
            ("stochastic", truth, 0, "true_noise", true),
            ("stochastic", truth, 0, "estimated_noise", estimate),
            ("stochastic", truth, 0, "unlabelled_share", 0.0),
        ]
    # A teacher that labelled nothing has only its unlabelled share, and no row in the table.
    records += [("skip", 11.0, 0, "unlabelled_share", 1.0)]
    table = noise_table(_teacher_rows(records), resamples=500)
    assert list(table.teacher) == ["stochastic"]
    row = table.iloc[0]
    assert row["n"] == 5 and row["bias"] == pytest.approx(0.02)
    assert row["bias_low"] >= 0.01 - 1e-12 and row["bias_high"] <= 0.03 + 1e-12
    assert row["true_noise"] == pytest.approx(0.18) and row["estimated_noise"] == pytest.approx(0.2)
    assert row["recovered"] == "yes" and NOISE_TOLERANCE > 0.03
    far = [
        ("myopic", truth, 0, metric, value)
        for truth in (9.0, 11.0, 14.0, 17.0, 19.0)
        for metric, value in (("true_noise", 0.3), ("estimated_noise", 0.2))
    ]
    assert noise_table(_teacher_rows(far)).iloc[0]["recovered"] == "no"
    # One environment is too few to decide whether the estimate recovers the share.
    assert noise_table(_teacher_rows(far[:2])).iloc[0]["recovered"] == "too few environments to decide"


def test_filter_quality_is_read_at_the_last_evaluation_beside_the_teachers_wrong_share() -> None:
    runs = pd.DataFrame(
        [
            dict(
                domain="pushing",
                method="co_pesi_likelihood",
                noise=0.0,
                seed=0,
                episode=episode,
                metric=metric,
                value=value,
                ground_truth=11.0,
                teacher="distance",
            )
            for episode, metric, value in (
                (33, "filter_precision", 0.9),
                (66, "filter_precision", 0.5),
                (66, "filter_recall", 0.4),
                (66, "param_error", 1.0),
            )
        ]
    )
    truth = _teacher_rows([("distance", 11.0, 0, "true_noise", 0.25)])
    table = filter_quality(pd.concat([runs, truth], ignore_index=True))
    assert table.to_dict("records") == [
        dict(
            domain="pushing",
            teacher="distance",
            method="co_pesi_likelihood",
            filter_precision=0.5,
            filter_recall=0.4,
            chance=0.25,
        )
    ]


def test_one_sweep_runs_both_kinds_of_cell(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(robustness, "run_si", lambda cell: "run")
    monkeypatch.setattr(robustness, "run_teacher_noise", lambda cell: "noise")
    config = RobustnessConfig()
    assert {robustness.run_cell(cell) for cell in cells(config)} == {"run"}
    assert {robustness.run_cell(cell) for cell in noise_cells(config)} == {"noise"}

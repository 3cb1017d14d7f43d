"""The teachers-and-robustness study's plumbing: paired cells, refused bad parameters, the PESI-paired
difference table and the best-learner verdict."""

import pandas as pd
import pytest

from hipref.experiments.robustness import (
    LEARNERS,
    TEACHERS,
    RobustnessConfig,
    best_learner,
    cells,
    difference_table,
    noise_cells,
)
from hipref.teachers.models import TeacherModel


def test_every_learner_meets_every_teacher_in_every_environment() -> None:
    config = RobustnessConfig(domains=("pushing",), masses=(9.25, 14.0))
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
            "pesi": [0.05, 0.06, 0.07, 0.05],
            "pesi_rime": [0.02, 0.03, 0.03, 0.02],
            "pesi_smoothed": [0.05] * 4,
        },
        {"pesi": [0.4, 0.5, 0.4, 0.5], "pesi_rime": [0.8, 0.9, 0.8, 0.9], "pesi_smoothed": [0.4] * 4},
    )
    table = difference_table(rows, resamples=500)
    assert set(table.method) == {"pesi_rime", "pesi_smoothed"} and set(table.n) == {4}
    method, held, text = best_learner(table, "wiping", "skip")
    assert (method, held) == ("pesi_rime", "yes")
    assert "pesi_rime - pesi" in text
    # A lower error but no better success: the claim holds partly.
    rows = _rows({"pesi": [0.05] * 4, "pesi_rime": [0.02] * 4}, {"pesi": [0.5] * 4, "pesi_rime": [0.5] * 4})
    assert best_learner(difference_table(rows, resamples=500), "wiping", "skip")[1] == "partly"

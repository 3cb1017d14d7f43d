"""The Table 3 study: deterministic, shaped by the results contract, and guarded against bad parameters."""

import dataclasses

import numpy as np
import pandas as pd
import pytest

from hipref.experiments import noise_estimation
from hipref.experiments.noise_estimation import (
    PAPER_TABLE3,
    TABLE3_COLUMNS,
    NoiseEstimationConfig,
    error_trend,
    overestimate,
    run,
    table3,
)
from hipref.results import TIDY_COLUMNS, check_tidy
from tests._clips import shown

SMALL = NoiseEstimationConfig(n_preferences=64, repetitions=5, noise_levels=(0.1, 0.25, 0.4), seed=3)


def test_table3_is_identical_for_the_same_seed_and_differs_for_another() -> None:
    first, second = table3(SMALL), table3(SMALL)
    pd.testing.assert_frame_equal(first, second, check_exact=True)
    other = table3(dataclasses.replace(SMALL, seed=4))
    assert not np.array_equal(first["estimated_noise"], other["estimated_noise"])


def test_a_levels_datasets_do_not_depend_on_the_other_levels() -> None:
    alone = table3(dataclasses.replace(SMALL, noise_levels=(0.25,)))
    together = table3(SMALL)
    assert alone["estimated_noise"].iloc[0] == together.set_index("true_noise").loc[0.25, "estimated_noise"]


def test_table3_has_the_contract_columns_and_the_papers_values() -> None:
    table = table3(SMALL)
    assert tuple(table.columns) == TABLE3_COLUMNS
    assert table["true_noise"].tolist() == [0.1, 0.25, 0.4]
    assert table["paper_estimated_noise"].tolist() == [
        PAPER_TABLE3[0.1],
        PAPER_TABLE3[0.25],
        PAPER_TABLE3[0.4],
    ]
    assert table["estimated_noise"].between(0.0, 1.0).all()


def test_rows_are_tidy_with_one_estimate_and_one_true_noise_per_dataset() -> None:
    rows = check_tidy(run(SMALL))
    assert set(TIDY_COLUMNS) <= set(rows.columns)
    assert set(rows["method"]) == {"algorithm5"} and set(rows["episode"]) == {0}
    counts = rows.groupby(["noise", "metric"]).size()
    assert (counts == SMALL.repetitions).all() and len(counts) == 2 * len(SMALL.noise_levels)
    truth = rows[rows["metric"] == "true_noise"]
    assert (truth["value"] == truth["noise"]).all()


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("n_preferences", 1),
        ("repetitions", 0),
        ("noise_levels", (0.1, 1.5)),
        ("domain", "kitchen"),
        ("seed", -1),
    ],
)
def test_a_bad_parameter_is_refused_before_any_compute(
    monkeypatch: pytest.MonkeyPatch, field: str, value: object
) -> None:
    def fail(*args: object) -> float:
        raise AssertionError("computed despite a bad parameter")

    monkeypatch.setattr(noise_estimation, "estimate_noise", fail)
    with pytest.raises(ValueError, match=field) as error:
        table3(NoiseEstimationConfig(**{field: value}))
    assert repr(value if not isinstance(value, tuple) else value[1]) in str(error.value)


def test_claim_statistics_see_a_constant_bias_and_a_falling_error() -> None:
    # The estimate is 0.1 too high everywhere, so the relative error falls as 0.1 / true noise.
    levels = [0.1, 0.2, 0.4]
    rows = pd.DataFrame(
        [
            {"noise": t, "seed": s, "metric": m, "value": v}
            for t in levels
            for s in range(4)
            for m, v in (("true_noise", t), ("estimated_noise", t + 0.1))
        ]
    )
    mean, low, high = overestimate(rows)
    assert mean == pytest.approx(0.1) and low == pytest.approx(0.1) and high == pytest.approx(0.1)
    slope, _, high_slope = error_trend(rows, relative=True)
    assert slope < 0 and high_slope < 0


def test_co_pesi_estimated_sets_its_noise_level_from_algorithm_5_on_its_buffer() -> None:
    from hipref.learners.coteaching import CoPESIConfig, EstimatedNoiseCoPESILearner
    from hipref.learners.noise_estimation import estimate_noise
    from hipref.learners.sysid import DESK_HEIGHT, SIModel
    from hipref.teachers.preference import ScriptedPreferenceTeacher

    config = CoPESIConfig(batch_size=8, start_size=8, refresh_frequency=8, history=1)
    learner = EstimatedNoiseCoPESILearner(SIModel(9, DESK_HEIGHT, hidden_sizes=(8,), seed=0), config, seed=1)
    teacher = ScriptedPreferenceTeacher(0.7, 0.3, np.random.default_rng(0))
    features = np.random.default_rng(2).normal(size=(20, 9))
    for x in features:
        query = learner.ask(shown(x))
        learner.tell(query, teacher.answer(query))
    # One estimate per co-teaching step: every preference after the first start_size.
    assert len(learner.noise_history) == len(features) - config.start_size
    assert learner.noise_level == learner.noise_history[-1] == estimate_noise(learner.buffer_preferences())

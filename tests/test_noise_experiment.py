"""The Table 3 study: deterministic, shaped by the results contract, and guarded against bad parameters."""

import dataclasses
from collections.abc import Callable

import numpy as np
import pandas as pd
import pytest

from hipref.experiments import noise_estimation
from hipref.experiments.noise_estimation import (
    ESTIMATORS,
    METHODS,
    PAPER_TABLE3,
    TABLE3_COLUMNS,
    NoiseEstimationConfig,
    error_trend,
    overestimate,
    paper_distance,
    random_preferences,
    run,
    table3,
)
from hipref.learners.noise_estimation import CONFLICTS, estimate_noise
from hipref.results import TIDY_COLUMNS, check_tidy
from hipref.sweep import NO_CACHE
from tests._clips import shown

SMALL = NoiseEstimationConfig(n_preferences=64, repetitions=5, noise_levels=(0.1, 0.25, 0.4), seed=3)


def test_table3_is_identical_for_the_same_seed_and_differs_for_another() -> None:
    first, second = table3(SMALL), table3(SMALL)
    pd.testing.assert_frame_equal(first, second, check_exact=True)
    other = table3(dataclasses.replace(SMALL, seed=4))
    column = "estimated_noise_same_pair"
    assert not np.array_equal(first[column], other[column])


def test_a_levels_datasets_do_not_depend_on_the_other_levels() -> None:
    alone = table3(dataclasses.replace(SMALL, noise_levels=(0.25,))).set_index("true_noise")
    together = table3(SMALL).set_index("true_noise")
    for conflict in CONFLICTS:
        column = f"estimated_noise_{conflict}"
        assert alone.loc[0.25, column] == together.loc[0.25, column]


def test_table3_has_one_column_per_reading_beside_the_papers() -> None:
    table = table3(SMALL)
    assert tuple(table.columns) == TABLE3_COLUMNS
    assert {
        "paper_estimated_noise",
        "estimated_noise_same_pair",
        "estimated_noise_no_common_parameter",
    } <= set(table.columns)
    assert table["true_noise"].tolist() == [0.1, 0.25, 0.4]
    assert table["paper_estimated_noise"].tolist() == [
        PAPER_TABLE3[0.1],
        PAPER_TABLE3[0.25],
        PAPER_TABLE3[0.4],
    ]
    for conflict in CONFLICTS:
        assert table[f"estimated_noise_{conflict}"].between(0.0, 1.0).all()
        assert (table[f"estimated_noise_{conflict}_std"] > 0).all()
    assert not np.array_equal(
        table["estimated_noise_same_pair"], table["estimated_noise_no_common_parameter"]
    )


def test_rows_are_tidy_with_one_estimate_and_one_true_noise_per_dataset_and_estimator() -> None:
    rows = check_tidy(run(SMALL))
    assert set(TIDY_COLUMNS) <= set(rows.columns)
    methods = {*METHODS.values(), *ESTIMATORS}
    assert set(rows["method"]) == methods and set(rows["episode"]) == {0}
    counts = rows.groupby(["noise", "method", "metric"]).size()
    assert (counts == SMALL.repetitions).all() and len(counts) == 2 * len(methods) * len(SMALL.noise_levels)
    truth = rows[rows["metric"] == "true_noise"]
    assert (truth["value"] == truth["noise"]).all()
    assert set(rows["n_candidates"]) == {5}


def test_every_estimator_estimates_the_same_datasets(monkeypatch: pytest.MonkeyPatch) -> None:
    # Every dataset drawn, and the dataset each estimator is handed, recorded by identity.
    drawn: list[object] = []
    seen: dict[str, list[int]] = {}

    def draw(*args: object) -> object:
        drawn.append(random_preferences(*args))  # type: ignore[arg-type]
        return drawn[-1]

    def spy(method: str, estimator: Callable[..., float]) -> Callable[..., float]:
        def estimate(data: object, *args: object) -> float:
            seen.setdefault(method, []).append(id(data))
            return estimator(data, *args)

        return estimate

    monkeypatch.setattr(noise_estimation, "random_preferences", draw)
    monkeypatch.setattr(
        noise_estimation,
        "estimate_noise",
        lambda data, conflict: spy(METHODS[conflict], estimate_noise)(data, conflict),
    )
    monkeypatch.setattr(noise_estimation, "ESTIMATORS", {m: spy(m, e) for m, e in ESTIMATORS.items()})
    rows = run(SMALL, cache_dir=NO_CACHE).set_index(["noise", "seed", "method", "metric"])["value"]
    assert len(drawn) == len({id(d) for d in drawn}) == SMALL.repetitions * len(SMALL.noise_levels)
    assert set(seen) == {*METHODS.values(), *ESTIMATORS}
    assert all(ids == [id(d) for d in drawn] for ids in seen.values())
    # And each method's row holds that method's estimate of its dataset (dataset k: level k // 5, seed k % 5).
    for k, data in enumerate(drawn):
        noise = SMALL.noise_levels[k // SMALL.repetitions]
        for conflict, method in METHODS.items():
            expected = estimate_noise(data, conflict)  # type: ignore[arg-type]
            assert rows[(noise, k % SMALL.repetitions, method, "estimated_noise")] == expected
        for method, estimator in ESTIMATORS.items():
            expected = estimator(data, SMALL.candidates)  # type: ignore[arg-type]
            assert rows[(noise, k % SMALL.repetitions, method, "estimated_noise")] == expected


def test_the_candidates_are_the_papers_example_unless_told_otherwise() -> None:
    assert SMALL.candidates.values.tolist() == pytest.approx([0.5, 0.6, 0.7, 0.8, 0.9])
    assert NoiseEstimationConfig(candidate_spacing=0.01).candidates.size == 41
    assert NoiseEstimationConfig(domain="pushing", candidate_spacing=0.25).candidates.size == 49
    assert NoiseEstimationConfig(domain="pushing", candidate_spacing=3.0).candidates.size == 5
    fine = run(dataclasses.replace(SMALL, candidate_spacing=0.01))
    assert set(fine["n_candidates"]) == {41}


def test_at_the_papers_scale_the_same_pair_reading_is_nearer_table3() -> None:
    # Table 3's setting (100 datasets of 256 preferences per level) on the example's 5 candidates.
    distance = paper_distance(table3(NoiseEstimationConfig()))
    assert distance["same_pair"] < 0.02 < distance["no_common_parameter"]


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("n_preferences", 1),
        ("repetitions", 0),
        ("noise_levels", (0.1, 1.5)),
        ("domain", "kitchen"),
        ("candidate_spacing", 0.15),
        ("candidate_spacing", -0.1),
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
    # The absolute error is 0.1 at every level: no trend, and an interval of exactly zero width.
    assert error_trend(rows, relative=False) == (0.0, 0.0, 0.0)


def test_claim_statistics_take_one_reading_at_a_time() -> None:
    rows = run(SMALL)
    with pytest.raises(ValueError, match="several readings"):
        overestimate(rows)
    with pytest.raises(ValueError, match="several readings"):
        error_trend(rows)
    for conflict, method in METHODS.items():
        alone = rows[rows["method"] == method]
        assert overestimate(rows, method=method) == overestimate(alone)
        bias = alone.pivot_table(index=["noise", "seed"], columns="metric", values="value")
        expected = (bias["estimated_noise"] - bias["true_noise"]).mean()
        assert overestimate(rows, method=method)[0] == pytest.approx(expected), conflict
    with pytest.raises(ValueError, match="method"):
        overestimate(rows, method="algorithm5")


def test_co_pesi_estimated_sets_its_noise_level_from_algorithm_5_on_its_buffer() -> None:
    from hipref.learners.coteaching import CoTeaching
    from hipref.learners.noise_estimation import CONFLICTS, estimate_noise
    from hipref.learners.noise_rate import Algorithm5
    from hipref.learners.pesi import PESIConfig, PESILearner
    from hipref.learners.sysid import DESK_HEIGHT, SIModel
    from hipref.teachers.preference import ScriptedPreferenceTeacher

    config = PESIConfig(batch_size=8, start_size=8, history=1)
    histories = {}
    for conflict in CONFLICTS:
        model = SIModel(9, DESK_HEIGHT, hidden_sizes=(8,), seed=0)
        learner = PESILearner(model, config, 1, CoTeaching(refresh_frequency=8), Algorithm5(conflict))
        teacher = ScriptedPreferenceTeacher(0.7, 0.3, np.random.default_rng(0))
        features = np.random.default_rng(2).normal(size=(20, 9))
        for x in features:
            query = learner.ask(shown(x))
            learner.tell(query, teacher.answer(query))
        # One estimate per co-teaching step: every preference after the first start_size.
        assert len(learner.noise_history) == len(features) - config.start_size
        estimate = estimate_noise(learner.buffer_preferences(), conflict)
        assert learner.noise_history[-1] == estimate
        histories[conflict] = learner.noise_history
    # The readings count different conflicts on the same answers, so the forget numbers differ.
    assert histories["same_pair"] != histories["no_common_parameter"]
    with pytest.raises(ValueError, match="conflict"):
        Algorithm5(conflict="pair")

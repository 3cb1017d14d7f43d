"""The scripted preference teacher and the preference label conventions of Eq. 2 and Eq. 3."""

import math

import numpy as np
import pytest

from hipref.teachers.preference import (
    PreferenceQuery,
    ScriptedPreferenceTeacher,
    preference_label_vector,
    preferred_index,
)

FEATURES = np.zeros(3)


def _random_pair_queries(rng: np.random.Generator, n: int) -> list[PreferenceQuery]:
    pairs = rng.uniform(0.5, 0.9, size=(n, 2))
    return [PreferenceQuery(candidates=(a, b), features=FEATURES) for a, b in pairs if a != b]


@pytest.mark.parametrize("noise", [0.1, 0.3])
def test_flip_rate_matches_noise_within_four_sigma(noise: float) -> None:
    rng = np.random.default_rng(0)
    queries = _random_pair_queries(rng, 20_000)
    clean = ScriptedPreferenceTeacher(0.7, 0.0, np.random.default_rng(1))
    noisy = ScriptedPreferenceTeacher(0.7, noise, np.random.default_rng(2))
    flips = sum(noisy.answer(q) != clean.answer(q) for q in queries)
    n = len(queries)
    assert abs(flips - n * noise) < 4 * math.sqrt(n * noise * (1 - noise))


def test_noise_free_teacher_always_prefers_the_closer_candidate() -> None:
    rng = np.random.default_rng(3)
    teacher = ScriptedPreferenceTeacher(0.63, 0.0, rng)
    for query in _random_pair_queries(rng, 2000):
        a, b = query.candidates
        assert teacher.answer(query) == (1 if abs(a - 0.63) < abs(b - 0.63) else -1)


def test_ties_are_broken_at_random_not_by_position() -> None:
    teacher = ScriptedPreferenceTeacher(0.7, 0.0, np.random.default_rng(4))
    answers = [teacher.answer(PreferenceQuery((0.6, 0.8), FEATURES)) for _ in range(2000)]
    assert 900 < answers.count(1) < 1100


@pytest.mark.parametrize("n_candidates", [3, 5])
def test_n_candidate_labels_are_valid_and_flips_are_uniform_over_the_others(n_candidates: int) -> None:
    teacher = ScriptedPreferenceTeacher(0.5, 0.6, np.random.default_rng(5))
    query = PreferenceQuery(tuple(0.5 + 0.1 * np.arange(n_candidates)), FEATURES)  # candidate 0 is the truth
    counts = np.zeros(n_candidates)
    n = 6000
    for _ in range(n):
        label = teacher.answer(query)
        np.testing.assert_array_equal(preference_label_vector(label, n_candidates), label)
        counts[preferred_index(label)] += 1
    expected_other = 0.6 / (n_candidates - 1)
    assert abs(counts[0] - 0.4 * n) < 4 * math.sqrt(n * 0.4 * 0.6)
    for count in counts[1:]:
        assert abs(count - expected_other * n) < 4 * math.sqrt(n * expected_other * (1 - expected_other))


def test_label_vector_conventions() -> None:
    np.testing.assert_array_equal(preference_label_vector(1, 2), [1.0, -1.0])
    np.testing.assert_array_equal(preference_label_vector(np.int64(-1), 2), [-1.0, 1.0])
    np.testing.assert_array_equal(preference_label_vector(np.array([-1, 1]), 2), [-1.0, 1.0])
    np.testing.assert_allclose(
        preference_label_vector([-1 / 3, 1, -1 / 3, -1 / 3], 4), [-1 / 3, 1, -1 / 3, -1 / 3]
    )


@pytest.mark.parametrize(
    ("label", "n_candidates"),
    [
        (0, 2),
        (2, 2),
        (0.5, 2),
        (math.nan, 2),
        (True, 2),
        ("1", 2),
        (None, 2),
        ([1, 1], 2),
        (1, 3),
        ([1, -1, -1], 3),
        ([1, -0.5, -0.5, 0], 3),
        ([1, 1, -0.5], 3),
        ([-0.5, -0.5, -0.5], 3),
    ],
)
def test_labels_outside_the_allowed_set_are_refused(label: object, n_candidates: int) -> None:
    with pytest.raises(ValueError, match="preference over"):
        preference_label_vector(label, n_candidates)


def test_queries_are_validated_and_immutable() -> None:
    with pytest.raises(ValueError, match="at least 2"):
        PreferenceQuery((0.5,), FEATURES)
    with pytest.raises(ValueError, match="distinct"):
        PreferenceQuery((0.5, 0.5), FEATURES)
    with pytest.raises(ValueError, match="features"):
        PreferenceQuery((0.5, 0.6), np.array([0.0, math.nan]))
    query = PreferenceQuery((0.5, 0.6), FEATURES)
    with pytest.raises(ValueError, match="read-only"):
        query.features[0] = 1.0


def test_teacher_arguments_are_validated() -> None:
    with pytest.raises(ValueError, match=r"noise .*\[0.0, 1.0\].*1.2"):
        ScriptedPreferenceTeacher(0.7, 1.2, np.random.default_rng())
    with pytest.raises(ValueError, match="rng"):
        ScriptedPreferenceTeacher(0.7, 0.1, None)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="true_parameter"):
        ScriptedPreferenceTeacher(math.nan, 0.1, np.random.default_rng())


def _closest(candidates: tuple[float, ...], truth: float) -> int:
    return int(np.argmin(np.abs(np.asarray(candidates) - truth)))


@pytest.mark.parametrize(("noise", "n_candidates"), [(0.2, 2), (0.35, 4)])
def test_the_recorded_flips_are_the_answers_that_disagree_with_the_truth(
    noise: float, n_candidates: int
) -> None:
    rng = np.random.default_rng(8)
    # Random candidates: ties have probability zero, so the closest candidate is the noise-free answer.
    queries = [PreferenceQuery(tuple(rng.uniform(0.5, 0.9, n_candidates)), FEATURES) for _ in range(5000)]
    teacher = ScriptedPreferenceTeacher(0.66, noise, np.random.default_rng(9))
    answers = [teacher.answer(q) for q in queries]
    assert len(teacher.flipped) == len(queries) and all(type(f) is bool for f in teacher.flipped)
    for query, answer, flipped in zip(queries, answers, teacher.flipped, strict=True):
        chosen = preferred_index(preference_label_vector(answer, n_candidates))
        assert flipped == (chosen != _closest(query.candidates, 0.66))
    n = len(queries)
    assert abs(sum(teacher.flipped) - n * noise) < 4 * math.sqrt(n * noise * (1 - noise))


def test_recording_the_flips_draws_nothing_more() -> None:
    # The draws of the paper's teacher: one uniform per answer when noise > 0, and for a flip one integer
    # choosing among the other candidates. Same rng seed, same answers and the same generator state after.
    queries = [PreferenceQuery(tuple(0.5 + 0.1 * np.arange(3)), FEATURES)] * 200
    teacher = ScriptedPreferenceTeacher(0.58, 0.4, np.random.default_rng(10))
    reference = np.random.default_rng(10)
    for query in queries:
        expected = _closest(query.candidates, 0.58)
        if reference.random() < 0.4:
            others = [i for i in range(3) if i != expected]
            expected = others[reference.integers(2)]
        assert preferred_index(teacher.answer(query)) == expected
    assert teacher.rng.bit_generator.state == reference.bit_generator.state
    clean = ScriptedPreferenceTeacher(0.58, 0.0, np.random.default_rng(11))
    for query in queries[:20]:
        clean.answer(query)
    assert clean.flipped == [False] * 20
    assert clean.rng.bit_generator.state == np.random.default_rng(11).bit_generator.state

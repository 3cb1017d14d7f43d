"""Algorithm 5: noise estimated as the fraction of preferences with at least the mean number of conflicts."""

import itertools

import numpy as np
import pytest

from hipref.experiments.noise_estimation import random_preferences
from hipref.learners.noise_estimation import (
    CONFLICTS,
    PreferenceSet,
    conflict_counts,
    estimate_noise,
)
from hipref.learners.sysid import CUBE_MASS, DESK_HEIGHT, CandidateSet

PAPER_EXAMPLE_GRID = CandidateSet(low=0.5, high=0.9, resolution=0.1)
"""A.9's example compares 0.5 m with 0.6 m: 5 heights 0.1 m apart, so random pairs often repeat."""


def _conflict(first: tuple[float, float, int], second: tuple[float, float, int]) -> bool:
    """Reference definition: no parameter is strictly nearer each preferred value than its rival."""
    grid = np.linspace(7.0, 21.0, 1401)  # 0.01 kg steps: inside any open interval between 0.125 kg midpoints

    def satisfied(pref: tuple[float, float, int]) -> np.ndarray:
        a, b, y = pref
        winner, loser = (a, b) if y == 1 else (b, a)
        return np.abs(grid - winner) < np.abs(grid - loser)

    return not np.any(satisfied(first) & satisfied(second))


def test_hand_built_dataset_gives_the_fraction_computed_by_hand() -> None:
    # Each preference bounds the true height: (a, b, y=1) means a is preferred.
    preferences = [
        (0.5, 0.6, 1),  # h < 0.55
        (0.5, 0.6, -1),  # h > 0.55: the paper's example, conflicts with the first
        (0.7, 0.8, 1),  # h < 0.75
        (0.6, 0.9, -1),  # h > 0.75
        (0.8, 0.9, -1),  # h > 0.85
        (0.5, 0.9, -1),  # h > 0.7
    ]
    # Conflicts: 0-1, 0-3, 0-4, 0-5, 2-3, 2-4 -> C = [4, 1, 2, 2, 2, 1], mean 2, four entries >= 2.
    data = PreferenceSet(*map(np.array, zip(*preferences, strict=True)))
    np.testing.assert_array_equal(conflict_counts(data), [4, 1, 2, 2, 2, 1])
    assert estimate_noise(data) == pytest.approx(4 / 6)
    # Same pair, opposite answers: only 0-1. C = [1, 1, 0, 0, 0, 0], mean 1/3, two entries >= 1/3.
    np.testing.assert_array_equal(conflict_counts(data, "same_pair"), [1, 1, 0, 0, 0, 0])
    assert estimate_noise(data, "same_pair") == pytest.approx(2 / 6)


def _pair(*preferences: tuple[float, float, int]) -> PreferenceSet:
    return PreferenceSet(*map(np.array, zip(*preferences, strict=True)))


@pytest.mark.parametrize(
    ("a", "b", "same_pair", "no_common_parameter"),
    [
        # The paper's example: 0.5 better than 0.6, and vice versa (shown either way round).
        ((0.5, 0.6, 1), (0.5, 0.6, -1), True, True),
        ((0.5, 0.6, 1), (0.6, 0.5, 1), True, True),
        # The same answer shown the other way round is no conflict.
        ((0.5, 0.6, 1), (0.6, 0.5, -1), False, False),
        # h < 0.55 and h > 0.56: no height satisfies both, but they are different pairs.
        ((0.5, 0.6, 1), (0.6, 0.52, 1), False, True),
        # h < 0.55 and h > 0.55 from different pairs with the same midpoint.
        ((0.5, 0.6, 1), (0.4, 0.7, -1), False, True),
        # h < 0.55 and h > 0.535: 0.54 satisfies both.
        ((0.5, 0.6, 1), (0.55, 0.52, 1), False, False),
    ],
)
def test_each_reading_of_a_conflict_has_its_defining_property(
    a: tuple[float, float, int], b: tuple[float, float, int], same_pair: bool, no_common_parameter: bool
) -> None:
    data = _pair(a, b)
    for conflict, expected in (("same_pair", same_pair), ("no_common_parameter", no_common_parameter)):
        np.testing.assert_array_equal(conflict_counts(data, conflict), [int(expected)] * 2, err_msg=conflict)


def test_same_pair_counts_match_the_double_loop_and_never_exceed_the_other_reading() -> None:
    data = random_preferences(60, 0.3, PAPER_EXAMPLE_GRID, np.random.default_rng(5))
    rows = list(zip(data.first, data.second, data.label.astype(int), strict=True))
    expected = np.zeros(len(rows), dtype=int)
    for i, j in itertools.combinations(range(len(rows)), 2):
        (a, b, y), (c, d, z) = rows[i], rows[j]
        if {a, b} == {c, d} and (a if y == 1 else b) != (c if z == 1 else d):
            expected[i] += 1
            expected[j] += 1
    same_pair = conflict_counts(data, "same_pair")
    np.testing.assert_array_equal(same_pair, expected)
    assert expected.sum() > 0
    assert np.all(same_pair <= conflict_counts(data, "no_common_parameter"))


def test_values_equal_but_for_rounding_are_the_same_pair() -> None:
    data = _pair((0.1 + 0.2, 0.6, 1), (0.6, 0.3, 1))
    assert 0.1 + 0.2 != 0.3
    np.testing.assert_array_equal(conflict_counts(data, "same_pair"), [1, 1])


def test_the_default_reading_is_no_common_parameter_and_others_are_refused() -> None:
    data = random_preferences(128, 0.2, DESK_HEIGHT, np.random.default_rng(6))
    assert CONFLICTS == ("same_pair", "no_common_parameter")
    np.testing.assert_array_equal(conflict_counts(data), conflict_counts(data, "no_common_parameter"))
    assert estimate_noise(data) == estimate_noise(data, "no_common_parameter")
    assert estimate_noise(data) != estimate_noise(data, "same_pair")
    for call in (conflict_counts, estimate_noise):
        with pytest.raises(ValueError, match=r"conflict must be one of .*no_common_parameter.*'opposite'"):
            call(data, "opposite")


def test_conflict_counts_match_the_pairwise_double_loop_of_the_pseudo_code() -> None:
    rng = np.random.default_rng(0)
    data = random_preferences(40, 0.3, CUBE_MASS, rng)
    rows = list(zip(data.first, data.second, data.label.astype(int), strict=True))
    expected = np.zeros(len(rows), dtype=int)
    for i, j in itertools.combinations(range(len(rows)), 2):
        if _conflict(rows[i], rows[j]):
            expected[i] += 1
            expected[j] += 1
    np.testing.assert_array_equal(conflict_counts(data), expected)
    assert expected.sum() > 0


def test_noise_free_data_has_no_conflicts_and_an_estimate_of_one() -> None:
    data = random_preferences(256, 0.0, DESK_HEIGHT, np.random.default_rng(1))
    assert not conflict_counts(data).any()
    assert estimate_noise(data) == 1.0


def test_random_preferences_flip_labels_at_the_true_noise_rate() -> None:
    rng = np.random.default_rng(2)
    flipped = []
    for _ in range(50):
        state = rng.bit_generator.state
        noisy = random_preferences(256, 0.25, DESK_HEIGHT, rng)
        rng.bit_generator.state = state
        clean = random_preferences(256, 0.0, DESK_HEIGHT, rng)
        np.testing.assert_array_equal(noisy.first, clean.first)
        assert np.all(noisy.first != noisy.second)
        flipped.append(np.mean(noisy.label != clean.label))
    n = 50 * 256
    assert abs(np.mean(flipped) - 0.25) < 4 * np.sqrt(0.25 * 0.75 / n)


def test_noisier_data_gives_higher_estimates() -> None:
    rng = np.random.default_rng(3)
    means = [
        np.mean([estimate_noise(random_preferences(256, noise, DESK_HEIGHT, rng)) for _ in range(100)])
        for noise in (0.1, 0.4)
    ]
    assert means[0] < means[1] < 1.0


def test_invalid_preference_sets_are_refused() -> None:
    with pytest.raises(ValueError, match="different values"):
        PreferenceSet(np.array([0.5]), np.array([0.5]), np.array([1]))
    with pytest.raises(ValueError, match="label"):
        PreferenceSet(np.array([0.5]), np.array([0.6]), np.array([0]))
    with pytest.raises(ValueError, match="equal length"):
        PreferenceSet(np.array([0.5, 0.6]), np.array([0.6]), np.array([1]))
    with pytest.raises(ValueError, match="at least one"):
        estimate_noise(PreferenceSet(np.array([]), np.array([]), np.array([])))
    with pytest.raises(ValueError, match=r"true_noise .*1.5"):
        random_preferences(10, 1.5, DESK_HEIGHT, np.random.default_rng())

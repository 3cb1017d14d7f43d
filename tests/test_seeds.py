"""The study's seeds (`hipref.seeds`): reproducible from the root, independent between runs and roots, and
stable when more runs are added."""

from __future__ import annotations

import numpy as np

from hipref.seeds import child_seeds, integer_seed


def test_the_same_root_gives_the_same_seeds_and_more_runs_keep_the_first_ones() -> None:
    assert child_seeds(7, 5) == child_seeds(7, 5)
    assert child_seeds(7, 12)[:5] == child_seeds(7, 5)  # adding seeds to a study leaves its runs as they were


def test_seeds_differ_between_runs_between_roots_and_between_labels_of_a_root() -> None:
    runs = child_seeds(0, 200)
    assert len(set(runs)) == 200
    roots = [set(child_seeds(root, 20)) for root in (0, 1, 2)]
    assert not (roots[0] & roots[1] or roots[0] & roots[2] or roots[1] & roots[2])
    labelled = [set(child_seeds((0, label), 20)) for label in (1, 2)]
    assert not (labelled[0] & labelled[1] or labelled[0] & roots[0])


def test_a_seed_is_a_32_bit_integer_with_the_streams_spread_over_that_range() -> None:
    seeds = np.array(child_seeds(3, 400), dtype=np.int64)
    assert all(isinstance(seed, int) for seed in child_seeds(3, 4))
    assert seeds.min() >= 0 and seeds.max() < 2**32
    # Uniform over [0, 2^32): each quarter holds a quarter of 400 seeds, within five binomial deviations.
    counts = np.bincount(seeds // 2**30, minlength=4)
    assert np.all(np.abs(counts - 100) < 5 * np.sqrt(400 * 0.25 * 0.75))


def test_an_integer_seed_depends_on_the_sequence_and_not_on_drawing_it_before() -> None:
    seq = np.random.SeedSequence(11)
    first = integer_seed(seq)
    assert integer_seed(seq) == first == integer_seed(np.random.SeedSequence(11))
    assert integer_seed(np.random.SeedSequence(12)) != first
    # A child's seed differs from its parent's: the seeds of the runs are not the root's.
    assert first not in child_seeds(11, 50)

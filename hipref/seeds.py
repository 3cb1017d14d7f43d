"""Seeds of the study's runs, all from numpy's SeedSequence: independent streams, reproducible from a root."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np


def integer_seed(seq: np.random.SeedSequence) -> int:
    """An integer seed drawn from `seq`, for what takes a plain seed (a learner, a torch generator)."""
    return int(seq.generate_state(1)[0])


def child_seeds(entropy: int | Sequence[int], count: int) -> list[int]:
    """`count` independent integer seeds from the root `entropy` (an int, or ints such as (root, label))."""
    return [integer_seed(child) for child in np.random.SeedSequence(entropy).spawn(count)]

"""A stand-in for executing the low-level policy, for learners' ask() in tests without a simulator."""

from collections.abc import Callable

import numpy as np


def shown(features: np.ndarray) -> Callable[[float], np.ndarray]:
    """An execute(phi) for ask(): every candidate's clip is one period with these features (h = 1)."""
    return lambda phi: np.reshape(np.asarray(features, dtype=float), (1, -1))

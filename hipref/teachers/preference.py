"""Preferences over candidate parameters: the query, the allowed labels and a scripted teacher (Eq. 2, 3).

A learner shows the teacher N >= 2 candidate values of the unknown parameter (in the paper, clips of the
controller run with each); the teacher says which one it prefers. For two candidates the label is
y in {-1, 1}, 1 meaning candidates[0] is preferred (Eq. 2). For N candidates it is a vector with one entry
1 (the preferred candidate) and -1/(N-1) elsewhere (Eq. 3), so the entries sum to zero.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

from hipref.teachers.models import (
    EQUAL,
    RULES,
    SKIP,
    NoLabel,
    TeacherModel,
    TeacherState,
    equally_near,
    nearest,
)
from hipref.validation import check_interval, check_parameter, check_range, is_number

__all__ = [
    "EQUAL",
    "SKIP",
    "NoLabel",
    "PreferenceQuery",
    "ScriptedPreferenceTeacher",
    "TeacherModel",
    "equally_near",
    "pair_labels",
    "preference_label_vector",
    "preferred_index",
]


@dataclass(frozen=True, eq=False)
class PreferenceQuery:
    """'Which of these parameter values is best?', asked about the SI input the candidates were drawn for."""

    candidates: tuple[float, ...]
    """The N >= 2 distinct candidate values shown, in parameter units; their order defines the label."""
    features: np.ndarray
    """tau, the (flattened, unnormalised) system-identification input the preference is about; read-only."""

    def __post_init__(self) -> None:
        candidates = tuple(float(c) for c in self.candidates)
        if len(candidates) < 2 or not all(math.isfinite(c) for c in candidates):
            raise ValueError(f"candidates must be at least 2 finite numbers, got {self.candidates!r}")
        if len(set(candidates)) != len(candidates):
            raise ValueError(f"candidates must be distinct, got {self.candidates!r}")
        features = np.array(self.features, dtype=np.float64)
        if not np.all(np.isfinite(features)):
            raise ValueError("features must be finite numbers, got a value that is NaN or infinite")
        features.flags.writeable = False
        object.__setattr__(self, "candidates", candidates)
        object.__setattr__(self, "features", features)


def preference_label_vector(label: object, n_candidates: int) -> np.ndarray:
    """Check a preference label for `n_candidates` candidates and return it in vector form.

    Two candidates: a number y in {-1, 1} (Eq. 2), returned as (y, -y); the vector form is accepted too.
    N candidates: a length-N vector with exactly one entry 1 and every other entry -1/(N-1) (Eq. 3).
    Anything else raises ValueError.
    """
    if n_candidates < 2:
        raise ValueError(f"n_candidates must be an integer >= 2, got {n_candidates!r}")
    if n_candidates == 2 and isinstance(label, numbers.Real) and not isinstance(label, bool | np.bool_):
        # An int: a float 1.0 is more likely a probability or a vector's entry than a label.
        if not isinstance(label, numbers.Integral) or label not in (-1, 1):
            raise ValueError(
                "a preference over 2 candidates must be the integer -1 or 1, "
                f"got {label!r} ({type(label).__name__})"
            )
        return np.array([float(label), -float(label)])
    other = -1.0 / (n_candidates - 1)
    allowed = f"a length-{n_candidates} vector with one entry 1 and the others {other:.4g}"
    try:
        vector = np.asarray(label, dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(
            f"a preference over {n_candidates} candidates must be {allowed}, got {label!r}"
        ) from None
    # isclose: -1/(N-1) is not exact in binary floating point, so a computed label may differ in the last bit.
    is_one = np.isclose(vector, 1.0, rtol=0.0, atol=1e-9)
    is_other = np.isclose(vector, other, rtol=0.0, atol=1e-9)
    if vector.shape != (n_candidates,) or is_one.sum() != 1 or not np.all(is_one | is_other):
        raise ValueError(f"a preference over {n_candidates} candidates must be {allowed}, got {label!r}")
    return np.where(is_one, 1.0, other)


def preferred_index(label_vector: np.ndarray) -> int:
    """Index of the preferred candidate in a label vector from `preference_label_vector`."""
    return int(np.argmax(label_vector))


def pair_labels(
    first: np.ndarray, second: np.ndarray, true_parameter: float
) -> tuple[np.ndarray, np.ndarray]:
    """The teacher's rule on pairs, before any flip: y = 1 where `first` is nearer the true parameter, -1
    where `second` is; and where the two are equally near (ties, for the caller to break at random)."""
    distance_first, distance_second = np.abs(first - true_parameter), np.abs(second - true_parameter)
    return np.where(distance_first < distance_second, 1, -1), equally_near(distance_first, distance_second)


class ScriptedPreferenceTeacher:
    """Prefers the candidate closest to the true parameter; with probability `noise` the answer is flipped.

    This is the paper's simulated teacher (section 5): noise is the fraction of flipped preferences, each
    flipped independently and uniformly. For two candidates a flip is y -> -y; for N > 2 the preferred
    candidate is replaced by one of the other N - 1, chosen uniformly.

    `model` replaces 'closest to the true parameter' by another teacher model (`hipref.teachers.models`:
    B-Pref's stochastic, skip, equal and myopic teachers, and distance-dependent confusion); the uniform flip
    of probability `noise` still comes after it. The default, 'mistake', is the paper's teacher, and draws
    exactly what it always drew. A 'skip' or 'equal' answer is `SKIP` or `EQUAL` instead of a label; it is
    never flipped.

    Ties (two candidates equally close, up to floating-point rounding) are broken uniformly at random with
    the teacher's rng rather than by position: a positional rule would make every tie favour candidates[0]
    and bias a learner whose queries put, say, the lower value first.

    `flipped[i]` records whether the i-th answer was wrong against the oracle (for the paper's teacher:
    whether it was flipped) and `labelled[i]` whether it carried a label at all; `wrong_labels` lists the
    flags of the labelled answers alone, one per preference a learner stores. That is ground truth only a
    scripted teacher knows, kept to score a noise filter against (`PESILearner.filter_precision_recall`)
    and to measure the true noise; it is never shown to the learner, which is told the label alone.
    """

    def __init__(
        self,
        true_parameter: float,
        noise: float,
        rng: np.random.Generator,
        model: TeacherModel | None = None,
        scale: float = 1.0,
        bounds: tuple[float, float] | None = None,
    ) -> None:
        """
        Args:
            true_parameter: the environment's actual parameter (desk height in m or cube mass in kg).
            noise: probability of flipping each labelled answer, in [0, 1] (0 for the 'oracle' model).
            rng: source of tie-breaking, the model's draws and flips.
            model: the teacher model (default: 'mistake', the paper's teacher).
            scale: the width R of the parameter's range, in its unit: the model's distances are fractions
                of it, r(phi) = -|phi - phi*| / R.
            bounds: the parameter's range (low, high), when known: a true parameter outside it is refused
                (the teacher would prefer the candidate at the range's end whatever it is shown).
        """
        if bounds is None:
            if not (is_number(true_parameter) and math.isfinite(true_parameter)):
                raise ValueError(f"true_parameter must be a finite number, got {true_parameter!r}")
        else:
            check_interval("bounds", bounds, -math.inf, math.inf)
            check_parameter("true_parameter", true_parameter, bounds)
        check_range("noise", noise, 0.0, 1.0)
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a numpy.random.Generator, got {rng!r}")
        model = model if model is not None else TeacherModel()
        if not isinstance(model, TeacherModel):
            raise ValueError(f"model must be a TeacherModel, got {model!r}")
        if model.kind == "oracle" and noise != 0:
            raise ValueError(f"noise must be 0 for the 'oracle' teacher model, got {noise!r}")
        check_range("scale", scale, 1e-12, math.inf)
        self.true_parameter: float = float(true_parameter)
        self.noise: float = float(noise)
        self.rng: np.random.Generator = rng
        self.model: TeacherModel = model
        self.scale: float = float(scale)
        self._state: TeacherState = TeacherState(rng)
        self.flipped: list[bool] = []
        self.labelled: list[bool] = []

    @property
    def wrong_labels(self) -> list[bool]:
        """Whether each labelled answer was wrong, in order: one flag per preference a learner stored."""
        return [wrong for wrong, labelled in zip(self.flipped, self.labelled, strict=True) if labelled]

    def closest(self, candidates: tuple[float, ...]) -> int:
        """Index of the candidate nearest the true parameter, ties broken uniformly with the rng."""
        return nearest(np.abs(np.asarray(candidates, dtype=np.float64) - self.true_parameter), self.rng)

    def answer(self, query: PreferenceQuery) -> int | np.ndarray | NoLabel:
        """y in {-1, 1} for two candidates (Eq. 2), else the Eq. 3 label vector, or SKIP / EQUAL;
        `flipped` records whether this answer was wrong and `labelled` whether it was a label."""
        n = len(query.candidates)
        values = np.asarray(query.candidates, dtype=np.float64)
        distance = np.abs(values - self.true_parameter)
        preferred = self._state_answer(values)
        if isinstance(preferred, NoLabel):
            self.flipped.append(False)
            self.labelled.append(False)
            return preferred
        base_right = bool(equally_near(distance[preferred], distance.min()))
        # No draw at zero noise, so a noise-free teacher's rng serves tie-breaking alone.
        flip = self.noise > 0 and self.rng.random() < self.noise
        if flip:
            # Uniform flip: any of the other candidates, each equally likely.
            others = [i for i in range(n) if i != preferred]
            preferred = int(others[self.rng.integers(len(others))])
        final_right = bool(equally_near(distance[preferred], distance.min()))
        # A flip of a right answer is wrong even between two equally near candidates (the paper's record).
        self.flipped.append(bool(not final_right or (flip and base_right)))
        self.labelled.append(True)
        if n == 2:
            return 1 if preferred == 0 else -1
        label = np.full(n, -1.0 / (n - 1))
        label[preferred] = 1.0
        return label

    def _state_answer(self, values: np.ndarray) -> int | NoLabel:
        offsets = (values - self.true_parameter) / self.scale
        return RULES[self.model.kind](self.model, offsets, self._state)

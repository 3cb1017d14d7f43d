"""Models of a scripted preference teacher: how it answers 'which candidate is best?' (B-Pref and beyond).

The paper's teacher prefers the candidate nearest the true parameter phi* and flips each answer with
probability e (section 5). B-Pref (Lee et al. 2021, 'B-Pref: Benchmarking Preference-Based Reinforcement
Learning') simulates less tidy teachers, each the oracle changed in one respect. Here the 'return' of a
candidate phi is its closeness to the truth,

    r(phi) = -|phi - phi*| / R,        R = the width of the parameter's range,

so that thresholds and rationalities are the same fractions in both domains (metres and kilograms). With
d_i = -r(phi_i), the distance of candidate i to the truth in units of the range, each model's rule:

- 'oracle': the nearest candidate (ties broken uniformly at random). Never wrong.
- 'mistake': the oracle, then the answer flipped with probability e (the teacher's `noise`): the paper's
  teacher and B-Pref's 'mistake' (its epsilon). Every other model can be combined with this flip too, as in
  B-Pref's SimTeacher, where the mistake is applied last.
- 'stochastic' (Bradley-Terry, B-Pref's 'noisy' teacher with finite rationality beta):
  P(candidate i) = exp(beta r_i) / sum_j exp(beta r_j); for a pair P(prefer a) = sigmoid(beta (r_a - r_b)).
- 'skip': no answer (`SKIP`) when every candidate is farther than `skip_distance` from the truth,
  min_i d_i > skip_distance (B-Pref skips queries whose segments both have a low return); else the oracle.
- 'equal': 'equally good' (`EQUAL`) when the two nearest candidates' closeness differs by less than
  `equal_margin`, d_(2) - d_(1) < equal_margin (B-Pref's 'equal' teacher); else the oracle.
- 'myopic': B-Pref's myopic teacher weighs the recent steps of a segment more, sum_t gamma^(H-t) r_t, and
  so judges by a short stretch of evidence. A candidate value here has no time steps for the teacher to
  look at; what a person does have is a picture of the truth built from what they have seen, and a myopic
  one remembers mostly the latest glimpses. Our reading: before each answer the teacher takes one glimpse
  of the truth, phi* + sigma R z (z standard normal, sigma = `glimpse_noise`), and remembers the discounted
  average m <- gamma m + (1 - gamma) glimpse (gamma = `memory`, B-Pref's 0.9 by default), started from its
  stationary spread; it then prefers the candidate nearest m. The smaller gamma, the fewer glimpses its
  picture rests on (std sigma R sqrt((1 - gamma) / (1 + gamma))), and the more often it prefers a
  candidate that is in fact farther. Its errors are correlated over consecutive answers, unlike a flip.
- 'distance': the probability of a wrong answer grows as the candidates become hard to tell apart. For a
  pair with g = |d_a - d_b| (the difference of their closeness to the truth),

      P(wrong) = confusion_max * exp(-g / confusion_width);

  g <= |phi_a - phi_b| / R and g <= max(d_a, d_b), so g shrinks both when the two candidates are near each
  other and when both are near the truth (0.61 and 0.62 m look alike). With confusion_max = 1/2 a pair the
  teacher cannot tell apart is a coin toss. Pairs only.

Whether an answer is wrong is judged against the oracle: the preferred candidate is strictly farther from
the truth than the nearest one, or (the paper's flip, kept as its record) the answer was flipped from a
correct one, which counts as wrong even when the two were equally near. SKIP and EQUAL carry no label and
are never wrong.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated

import numpy as np

from hipref.validation import Range, check_choice, check_fields, check_int


class NoLabel(enum.Enum):
    """An answer that carries no preference label: the learner stores nothing for it."""

    SKIP = "skip"
    """The teacher declined to answer (B-Pref's 'skip')."""
    EQUAL = "equal"
    """The teacher judged the candidates equally good (B-Pref's 'equal')."""


SKIP = NoLabel.SKIP
EQUAL = NoLabel.EQUAL


def equally_near(distance: np.ndarray, other: np.ndarray | float) -> np.ndarray:
    """Where two distances to the true parameter count as equal: a tie, which the teacher breaks at
    random (the candidates' grid puts some exactly midway)."""
    return np.isclose(distance, other, rtol=1e-9, atol=1e-12)


@dataclass(frozen=True)
class TeacherModel:
    """Which rule a scripted preference teacher answers by, and its parameters (module docstring).

    Distances and margins are fractions of the parameter's range R, so one model means the same in both
    domains. The uniform flip of probability e is the teacher's `noise`, applied after any rule.

    The defaults of the three models with graded errors (stochastic, myopic, distance) make each answer
    about 20% of pairs drawn uniformly from Phi wrongly (measured on the desk-height grid over truths
    0.54-0.86 m: 0.19, 0.20 and 0.20), the paper's middle noise level, so that the teachers differ in how
    their errors fall rather than in how many there are. 'skip' then leaves about 23% of such pairs
    unanswered and 'equal' about 10%."""

    kind: str = "mistake"
    """One of TEACHER_KINDS: 'oracle', 'mistake' (the paper's uniform flip), 'stochastic', 'skip',
    'equal', 'myopic' or 'distance'."""
    beta: Annotated[float, Range(0.0, math.inf)] = 7.0
    """'stochastic': the rationality beta of P(a) = sigmoid(beta (r_a - r_b)), per unit of r (a fraction of
    the range): a candidate 0.1 R nearer the truth is preferred with probability sigmoid(0.7) = 0.67."""
    skip_distance: Annotated[float, Range(0.0, 1.0)] = 0.3
    """'skip': no answer when every candidate is farther than this fraction of the range from the truth."""
    equal_margin: Annotated[float, Range(0.0, 1.0)] = 0.05
    """'equal': 'equally good' when the two nearest candidates' distances to the truth differ by less than
    this fraction of the range."""
    memory: Annotated[float, Range(0.0, 1.0 - 1e-9)] = 0.9
    """'myopic': gamma, the weight of the remembered picture of the truth against the newest glimpse, in
    [0, 1) (B-Pref's discount: 0.9)."""
    glimpse_noise: Annotated[float, Range(0.0, math.inf)] = 1.3
    """'myopic': sigma, the standard deviation of one glimpse of the truth as a fraction of the range; with
    memory 0.9 the remembered picture's spread is sigma sqrt(0.1 / 1.9) = 0.30 of the range."""
    confusion_max: Annotated[float, Range(0.0, 1.0)] = 0.5
    """'distance': the probability of a wrong answer for a pair equally near the truth, in [0, 1]."""
    confusion_width: Annotated[float, Range(1e-9, math.inf)] = 0.21
    """'distance': the difference of closeness (a fraction of the range) over which the probability of a
    wrong answer falls by a factor e."""

    def __post_init__(self) -> None:
        check_fields(self)
        # TEACHER_KINDS is read from the rules below, which take this class: no annotation can name it.
        check_choice("kind", self.kind, TEACHER_KINDS)

    @property
    def name(self) -> str:
        """The model's name in tidy rows: its kind."""
        return self.kind


class TeacherState:
    """What a teacher carries between answers: its rng, and (myopic) its remembered picture of the truth."""

    def __init__(self, rng: np.random.Generator) -> None:
        self.rng = rng
        self.memory: float | None = None


Rule = Callable[[TeacherModel, np.ndarray, TeacherState], "int | NoLabel"]
"""A model's rule: (model, offsets (phi_i - phi*) / R of the candidates, state) -> the index of the
preferred candidate, or a NoLabel. Offsets are signed: the myopic teacher compares them with a remembered
picture of the truth that may lie on either side."""


def nearest(distances: np.ndarray, rng: np.random.Generator) -> int:
    """Index of the smallest distance, ties broken uniformly with `rng` (no draw without a tie)."""
    candidates = np.flatnonzero(equally_near(distances, distances.min()))
    return int(candidates[0]) if candidates.size == 1 else int(rng.choice(candidates))


def _oracle(model: TeacherModel, offsets: np.ndarray, state: TeacherState) -> int | NoLabel:
    return nearest(np.abs(offsets), state.rng)


def _stochastic(model: TeacherModel, offsets: np.ndarray, state: TeacherState) -> int | NoLabel:
    # Bradley-Terry over r_i = -d_i: P(i) = softmax(beta r)_i, i.e. sigmoid(beta (r_a - r_b)) for a pair.
    logits = -model.beta * np.abs(offsets)
    probs = np.exp(logits - logits.max())
    return int(state.rng.choice(offsets.size, p=probs / probs.sum()))


def _skip(model: TeacherModel, offsets: np.ndarray, state: TeacherState) -> int | NoLabel:
    distances = np.abs(offsets)
    if distances.min() > model.skip_distance:
        return SKIP
    return nearest(distances, state.rng)


def _equal(model: TeacherModel, offsets: np.ndarray, state: TeacherState) -> int | NoLabel:
    distances = np.abs(offsets)
    two_nearest = np.sort(distances)[:2]
    if two_nearest[1] - two_nearest[0] < model.equal_margin:
        return EQUAL
    return nearest(distances, state.rng)


def _myopic(model: TeacherModel, offsets: np.ndarray, state: TeacherState) -> int | NoLabel:
    # The picture m of the truth, relative to it, in units of the range: m <- gamma m + (1 - gamma) glimpse.
    gamma, sigma = model.memory, model.glimpse_noise
    if state.memory is None:
        state.memory = sigma * math.sqrt((1.0 - gamma) / (1.0 + gamma)) * float(state.rng.standard_normal())
    state.memory = gamma * state.memory + (1.0 - gamma) * sigma * float(state.rng.standard_normal())
    return nearest(np.abs(offsets - state.memory), state.rng)


def _distance(model: TeacherModel, offsets: np.ndarray, state: TeacherState) -> int | NoLabel:
    if offsets.size != 2:
        raise ValueError(f"the 'distance' teacher answers pairs only, got {offsets.size} candidates")
    distances = np.abs(offsets)
    best = nearest(distances, state.rng)
    gap = abs(float(distances[0] - distances[1]))
    wrong = state.rng.random() < model.confusion_max * math.exp(-gap / model.confusion_width)
    return 1 - best if wrong else best


RULES: dict[str, Rule] = {
    "oracle": _oracle,
    "mistake": _oracle,
    "stochastic": _stochastic,
    "skip": _skip,
    "equal": _equal,
    "myopic": _myopic,
    "distance": _distance,
}
"""Each teacher model's rule before the uniform flip; 'mistake' is the oracle, its errors are the flip."""

TEACHER_KINDS: tuple[str, ...] = tuple(RULES)
"""The teacher models: B-Pref's six (oracle, mistake, stochastic, skip, equal, myopic) and 'distance'."""


def picture_floor(model: TeacherModel, answers: int) -> float:
    """The myopic teacher's limit: the standard deviation, as a fraction of the range, of the best unbiased
    estimate of phi* from the teacher's remembered pictures m_1..m_n of n consecutive answers themselves
    (real numbers, where its answers only say on which side of a midpoint the picture lies). The pictures
    are phi* plus a stationary AR(1) error of spread s = glimpse_noise sqrt((1 - gamma) / (1 + gamma)) and
    correlation gamma between consecutive answers; the generalised least-squares mean of n of them has
    variance s^2 (1 - gamma^2) / ((n - 2) (1 - gamma)^2 + 2 (1 - gamma)) (n >= 2), so no learner of the
    answers can be surer of phi* than this."""
    if model.kind != "myopic":
        raise ValueError(f"picture_floor is the myopic teacher's limit, got kind {model.kind!r}")
    check_int("answers", answers, 2)
    gamma = model.memory
    spread = model.glimpse_noise * math.sqrt((1.0 - gamma) / (1.0 + gamma))
    information = ((answers - 2) * (1.0 - gamma) ** 2 + 2.0 * (1.0 - gamma)) / (1.0 - gamma**2)
    return spread / math.sqrt(information)

"""What an answer says about phi: the likelihood of a teacher's answer given the truth (beyond the paper).

For one unknown scalar a preference between candidates says on which side of their midpoint the truth lies,
up to the teacher's errors. Each model here gives, for every hypothetical truth phi (a cell of the posterior,
`hipref.learners.bayes`) and a query's candidates, the probability of each possible answer: candidate i
preferred (i < N), 'skip' (column N) or 'equally good' (column N + 1). They mirror the scripted teachers of
`hipref.teachers.models` (d_i = |phi_i - phi| / R, R the range's width):

- 'flip': the nearest candidate, then flipped with probability e to one of the others (the paper's teacher;
  e = 0 is the oracle);
- 'stochastic': Bradley-Terry, P(i) = softmax(-beta d)_i;
- 'skip': 'skip' when min_i d_i > skip_distance, else the nearest;
- 'equal': 'equally good' when d_(2) - d_(1) < equal_margin, else the nearest;
- 'myopic': the nearest to a picture m of the truth, m ~ phi + N(0, (spread R)^2), so P(i) is the mass of
  candidate i's Voronoi interval: the law of one answer alone; with `memory`, the picture's errors follow each
  other as the myopic teacher's do, and the learner reads each answer given the ones before it
  (`hipref.learners.pictures`);
- 'distance': the nearest, wrong with probability confusion_max exp(-|d_a - d_b| / confusion_width) (pairs).

Every model but 'flip' takes the uniform flip e on top of its rule, as the scripted teacher applies it last;
'skip' and 'equally good' are never flipped. A person also slips: with probability `lapse` (a lapse rate, as
psychophysics fits one: Wichmann & Hill 2001) the answer is any of the candidates or 'equally good' (what a
person can press), each as likely, so that no answer is impossible; every scripted teacher's lapse is 0.
Flipping a uniform answer leaves it uniform, so the lapse and the flip may be applied in either order. Ties (a
truth exactly at a midpoint, or on the boundary of a rule: at exactly `skip_distance`, a margin of exactly
`equal_margin`) split evenly, as the teacher's own rounding decides them.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace
from typing import Annotated

import numpy as np
from scipy.special import ndtr

from hipref.teachers.models import TeacherModel
from hipref.validation import OneOf, Range, check_choice, check_fields, check_range

ANSWER_KINDS: tuple[str, ...] = ("flip", "stochastic", "skip", "equal", "myopic", "distance")
"""The answer models, one per kind of scripted teacher ('flip': the oracle and the paper's 'mistake')."""

SKIP_COLUMN, EQUAL_COLUMN = -2, -1
"""Where the probabilities of 'skip' and 'equally good' sit in `AnswerModel.probabilities`' last axis."""


@dataclass(frozen=True)
class AnswerModel:
    """One teacher model with its parameters: the likelihood of every answer given phi (module docstring).

    Distances are fractions of the parameter's range R, as in `hipref.teachers.models.TeacherModel`."""

    kind: Annotated[str, OneOf(ANSWER_KINDS)] = "flip"
    """One of ANSWER_KINDS."""
    flip: Annotated[float, Range(0.0, 1.0 - 1e-9)] = 0.0
    """e, the probability that a labelled answer is flipped after the rule, in [0, 1)."""
    beta: Annotated[float, Range(0.0, math.inf)] = 7.0
    """'stochastic': the rationality of P(i) = softmax(-beta d)_i."""
    skip_distance: Annotated[float, Range(0.0, 1.0)] = 0.3
    """'skip': no answer when every candidate is farther than this fraction of the range."""
    equal_margin: Annotated[float, Range(0.0, 1.0)] = 0.05
    """'equal': 'equally good' when the two nearest candidates' distances differ by less than this."""
    spread: Annotated[float, Range(1e-9, math.inf)] = 0.3
    """'myopic': the standard deviation of the teacher's picture of the truth, a fraction of the range."""
    memory: Annotated[float, Range(0.0, 1.0 - 1e-9)] = 0.0
    """'myopic': the correlation of the picture's error between consecutive answers (the myopic teacher's
    memory); 0, a fresh picture for every answer."""
    confusion_max: Annotated[float, Range(0.0, 1.0)] = 0.5
    """'distance': the probability of a wrong answer for a pair equally near the truth."""
    confusion_width: Annotated[float, Range(1e-9, math.inf)] = 0.21
    """'distance': the difference of closeness over which that probability falls by a factor e."""
    lapse: Annotated[float, Range(0.0, 1.0 - 1e-9)] = 0.0
    """The probability of an answer at random among the candidates and 'equally good', in [0, 1)."""

    def __post_init__(self) -> None:
        check_fields(self)
        if self.memory > 0 and self.kind != "myopic":
            raise ValueError(f"memory is for kind 'myopic' only, got memory={self.memory} for {self.kind!r}")

    def probabilities(self, offsets: np.ndarray) -> np.ndarray:
        """P(answer | phi) for offsets (..., N) = (phi_i - phi) / R: shape (..., N + 2), the N candidates,
        then 'skip' and 'equally good'; each row sums to one."""
        offsets = np.asarray(offsets, dtype=np.float64)
        n = offsets.shape[-1]
        if self.kind == "distance" and n != 2:
            raise ValueError(f"the 'distance' answer model is for pairs only, got {n} candidates")
        out = np.zeros((*offsets.shape[:-1], n + 2))
        distances = np.abs(offsets)
        out[..., :n] = _RULES[self.kind](self, offsets, distances, out)
        return self.after_rule(out)

    def after_rule(self, out: np.ndarray) -> np.ndarray:
        """The rule's probabilities `out` (..., N + 2) with the lapse and then the flip applied (in place
        where there is a lapse)."""
        n = out.shape[-1] - 2
        if self.lapse > 0:
            out *= 1.0 - self.lapse
            out[..., :n] += self.lapse / (n + 1)
            out[..., EQUAL_COLUMN] += self.lapse / (n + 1)
        return with_flip(out, self.flip)


@functools.lru_cache(maxsize=256)
def rule_of(model: AnswerModel) -> AnswerModel:
    """`model` without its flip: the rule it applies before flipping to one answer alone (without the myopic
    memory; kept per model, as query rules and posteriors ask for it at every answer)."""
    return replace(model, flip=0.0, memory=0.0)


def with_flip(probabilities: np.ndarray, flip: float) -> np.ndarray:
    """`AnswerModel.probabilities` of a rule, with the uniform flip e after it: the chosen candidate is
    replaced by one of the other N - 1; 'skip' and 'equally good' stay."""
    if flip == 0:
        return probabilities
    n = probabilities.shape[-1] - 2
    labelled = probabilities[..., :n]
    total = labelled.sum(axis=-1, keepdims=True)
    out = probabilities.copy()
    out[..., :n] = (1.0 - flip) * labelled + flip * (total - labelled) / (n - 1)
    return out


def nearest_probabilities(distances: np.ndarray) -> np.ndarray:
    """The oracle: one for the nearest candidate, ties shared evenly."""
    least = distances.min(axis=-1, keepdims=True)
    nearest = distances - least <= 1e-12 + 1e-9 * least  # `equally_near` of the teachers, inlined for speed
    return nearest / nearest.sum(axis=-1, keepdims=True)


def _flip(model: AnswerModel, offsets: np.ndarray, distances: np.ndarray, out: np.ndarray) -> np.ndarray:
    return nearest_probabilities(distances)


def _stochastic(
    model: AnswerModel, offsets: np.ndarray, distances: np.ndarray, out: np.ndarray
) -> np.ndarray:
    logits = -model.beta * distances
    weights = np.exp(logits - logits.max(axis=-1, keepdims=True))
    return weights / weights.sum(axis=-1, keepdims=True)


def _exceeds(values: np.ndarray, bound: float) -> np.ndarray:
    """1 where values > bound, 0 where below, 1/2 where equal up to rounding (`nearest_probabilities`'s
    tolerance): a rule's boundary, where the teacher's arithmetic decides."""
    on_bound = np.abs(values - bound) <= 1e-12 + 1e-9 * bound
    return np.where(on_bound, 0.5, (values > bound).astype(np.float64))


def _skip(model: AnswerModel, offsets: np.ndarray, distances: np.ndarray, out: np.ndarray) -> np.ndarray:
    skipped = _exceeds(distances.min(axis=-1), model.skip_distance)
    out[..., SKIP_COLUMN] = skipped
    return nearest_probabilities(distances) * (1.0 - skipped[..., None])


def _equal(model: AnswerModel, offsets: np.ndarray, distances: np.ndarray, out: np.ndarray) -> np.ndarray:
    two = np.sort(distances, axis=-1)[..., :2]
    equal = 1.0 - _exceeds(two[..., 1] - two[..., 0], model.equal_margin)  # equal: margin < equal_margin
    out[..., EQUAL_COLUMN] = equal
    return nearest_probabilities(distances) * (1.0 - equal[..., None])


def _myopic(model: AnswerModel, offsets: np.ndarray, distances: np.ndarray, out: np.ndarray) -> np.ndarray:
    # Candidate i is chosen when the picture m falls in its Voronoi interval of the sorted candidates.
    order = np.argsort(offsets, axis=-1)
    ranked = np.take_along_axis(offsets, order, axis=-1)
    bounds = (ranked[..., 1:] + ranked[..., :-1]) / 2.0
    cdf = _normal_cdf(bounds / model.spread)
    shape = (*cdf.shape[:-1], 1)
    edges = np.concatenate([np.zeros(shape), cdf, np.ones(shape)], axis=-1)
    mass = np.diff(edges, axis=-1)
    labelled = np.empty_like(mass)
    np.put_along_axis(labelled, order, mass, axis=-1)
    return labelled


def _distance(model: AnswerModel, offsets: np.ndarray, distances: np.ndarray, out: np.ndarray) -> np.ndarray:
    best = nearest_probabilities(distances)
    gap = np.abs(distances[..., 0] - distances[..., 1])
    wrong = (model.confusion_max * np.exp(-gap / model.confusion_width))[..., None]
    return (1.0 - wrong) * best + wrong * best[..., ::-1]


def _normal_cdf(x: np.ndarray) -> np.ndarray:
    return np.asarray(ndtr(x))


_RULES = {
    "flip": _flip,
    "stochastic": _stochastic,
    "skip": _skip,
    "equal": _equal,
    "myopic": _myopic,
    "distance": _distance,
}


PERSON_LAPSE = 0.05
"""The lapse rate of the models a learner weighs for a person: the top of the range Wichmann & Hill (2001)
fit to observers (0-6 %). A person presses "can't tell" where no scripted teacher would (two such answers to
pairs with far apart midpoints leave no truth every model without a lapse allows)."""


def person_family() -> tuple[AnswerModel, ...]:
    """The hypotheses of the learner a person teaches: `model_family()`, each model with PERSON_LAPSE."""
    return tuple(replace(model, lapse=PERSON_LAPSE) for model in model_family())


def told(teacher: TeacherModel, noise: float) -> AnswerModel:
    """The answer model of a scripted teacher (`hipref.teachers.models`) flipping at `noise`: what a learner
    'told the true model' uses. The myopic teacher's picture has the stationary spread of its memory,
    glimpse_noise sqrt((1 - memory) / (1 + memory)), and that memory."""
    check_range("noise", noise, 0.0, 1.0 - 1e-9)
    base = AnswerModel(flip=noise)
    if teacher.kind in ("oracle", "mistake"):
        return base
    if teacher.kind == "stochastic":
        return replace(base, kind="stochastic", beta=teacher.beta)
    if teacher.kind == "skip":
        return replace(base, kind="skip", skip_distance=teacher.skip_distance)
    if teacher.kind == "equal":
        return replace(base, kind="equal", equal_margin=teacher.equal_margin)
    if teacher.kind == "myopic":
        spread = teacher.glimpse_noise * math.sqrt((1.0 - teacher.memory) / (1.0 + teacher.memory))
        return replace(base, kind="myopic", spread=max(spread, 1e-9), memory=teacher.memory)
    return replace(
        base, kind="distance", confusion_max=teacher.confusion_max, confusion_width=teacher.confusion_width
    )


TOLD: tuple[str, ...] = ("model", "kind", "nothing")
"""What a learner is told of the teacher: its model (kind, parameters and flip rate), its kind only (the
parameters and flip rate weighed over the kind's grid in `model_family`), or nothing (every model)."""


def hypotheses(teacher: TeacherModel, noise: float, told_: str) -> tuple[AnswerModel, ...]:
    """The answer models a learner told `told_` (one of TOLD) about `teacher` flipping at `noise` weighs."""
    check_choice("told", told_, TOLD)
    if told_ == "model":
        return (told(teacher, noise),)
    family = model_family()
    if told_ == "nothing":
        return family
    kind = told(teacher, 0.0).kind
    return tuple(m for m in family if m.kind == kind)


FLIP_GRID: tuple[float, ...] = (0.0, 0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 0.35, 0.4, 0.45)
"""The flip rates a learner not told the model weighs (a uniform prior over them)."""


def model_family() -> tuple[AnswerModel, ...]:
    """The hypotheses of a learner that is not told the teacher's model: every kind over a grid of its
    parameters, each weighed by its marginal likelihood (`hipref.learners.bayes.PreferencePosterior`).

    The grids are coarse, to keep a choice of query cheap (32 models). They hold the skip and equal teachers'
    defaults (0.3 and 0.05) and the flip rates 0 and 0.2 of notebook 12's claims, so that under those teachers
    the learner told nothing weighs the true model among others, and the myopic teacher's picture spread
    nearly (0.3 against 0.298) with its memory (0.9), but not the stochastic teacher's beta 7 nor the distance
    teacher's width 0.21: flip rates of FLIP_GRID; rationalities beta 2, 8, 32; a picture's spread 0.1 and 0.3
    of the range, each a fresh picture per answer or with the myopic teacher's memory; confusion of 1/2 over
    widths 0.1-0.4; skip distances and equal margins on small grids, each with 0 or 20 % flips on top. A finer
    grid of rationalities does not bring the learner told nothing nearer the learner told the stochastic
    teacher's model (beta 7): with nine from 2 to 32 a factor sqrt(2) apart it needed 130 answers in wiping
    and 130 in pushing to be within one step in 90 % of `python -m hipref.bench.model_choice --grid wide
    --episodes 200`'s environments, against 65 and 140 with these three and 60 and 120 told the model: twice
    the answers in wiping, about the same in pushing."""
    base = AnswerModel()
    models = [replace(base, kind="flip", flip=e) for e in FLIP_GRID]
    models += [replace(base, kind="stochastic", beta=b) for b in (2.0, 8.0, 32.0)]
    memories = (0.0, TeacherModel("myopic").memory)
    models += [replace(base, kind="myopic", spread=s, memory=g) for s in (0.1, 0.3) for g in memories]
    models += [replace(base, kind="distance", confusion_width=w) for w in (0.1, 0.2, 0.4)]
    flips = (0.0, 0.2)
    models += [replace(base, kind="skip", skip_distance=s, flip=e) for s in (0.2, 0.3, 0.4) for e in flips]
    models += [replace(base, kind="equal", equal_margin=m, flip=e) for m in (0.025, 0.05, 0.1) for e in flips]
    return tuple(models)

"""Which pair to ask next: query rules over a learner's belief about phi (beyond the paper; APReL's set).

A rule sees the learner's belief as weights over hypothetical truths (cells) under one or more answer
models (`hipref.learners.answer_models`) and picks two candidates of Phi:

- 'uniform': two distinct candidates drawn uniformly (Algorithm 2; the learners draw these themselves, so
  the paper's studies keep their draws);
- 'thompson': two draws of phi from the belief, each rounded to its nearest candidate (redrawn while equal);
- 'information_gain': the pair maximising the mutual information between its answer and phi,
  I = H(sum_c w_c P(y | c)) - sum_c w_c H(P(y | c)), with P(y | c) averaged over the answer models the
  belief weighs at c (what the answer tells of phi, not of the teacher): under the flip model,
  probabilistic bisection (the pair whose midpoint is the belief's median); under the distance model,
  pairs a teacher can tell apart;
- 'volume_removal': APReL's expected volume removed, 1 - sum_y P(y)^2 (Sadigh et al. 2017), which ignores
  how noisy each answer is.

Every count below was measured with the family of 30 answer models, before the two myopic models with memory
(`hipref.learners.pictures`) joined it.

Information gain and volume removal score only the pairs whose midpoint lies within the belief's central half,
widened by half a step of Phi (`CENTRAL`, `worth_asking`). Under the flip model bisection asks at the median
anyway, and the learner told the teacher's model needs as many answers to one step as without the restriction
on notebook 12's truths with ten blocks of seeds (below) but under the skip teacher in pushing, 3 against 4
(its pairs change under the equal, skip and myopic teachers, and once its belief lies within a step). Under a
belief over many answer models the answers hardly tell the models apart (under bisection every model predicts
each answer at about 1/2): a teacher flipping 20 % leaves weight on flip rates up to 0.45 and on the myopic
teacher's models, whose wide posteriors draw the best-scoring pair into their tails (weighing the flip and
myopic models alone, (10.0, 12.0) kg asked of a truth at 18 kg in pushing). Measured as the settings where the
learner told nothing needs over 1.25 times the answers of the learner told the model (`python -m
hipref.bench.model_choice`, 12 teacher settings, 200 answers), against scoring the pairs within the central
99.8 %: on notebook 12's truths with ten blocks of seeds (`--grid study --blocks 10`, 100 environments per
domain at once) 4 of 12 against 6, only the skip and equal teachers left (5 and 4 answers against 3); on the
two wide grids (`--grid wide`, `--grid wide2`, 40 environments per domain) 2 and 2 against 2 and 4. Under the
myopic teacher, which neither learner brings within one step, told nothing's final error rose in all four
wide-grid settings (in wiping on the first grid 1.65 times told the model's, against 1.41). Within the central
98 % it was 3 on the first wide grid (99.8 %: 2) and 7 on notebook 12's grid (one block), as with 99.8 %; with
`CENTRAL` at 0.3 or 0.7, 5 and 4 of 12 on notebook 12's ten blocks, at both with the paper's teacher at 20 %
flips in pushing over (30 and 33 answers against told the model's 23; the half needs 28).

Measured before that restriction (pairs within the central 99.8 %), information gain against other ways to
choose under a learner told nothing of the teacher, as the same count (`--grid wide --episodes 200`), all with
the estimate read as points (before `hipref.learners.estimates` spread each cell over its stretch); "this
rule" is information gain over the pairs within the central 99.8 %:

- information about phi, averaged over the heaviest answer models (this rule): 3 settings;
- information about the step of Phi that holds phi: 6;
- the posterior's expected mass within one step of its best value after the answer (one-step lookahead on
  notebook 12's criterion): 6, and it slowed the told learner too (pushing at 20 % flips, 25 answers against
  19);
- information about phi and the answer model together: 10, at five times the time (it spends answers telling
  teachers apart);
- information about phi under one answer model drawn from the posterior: 8, and 8 on the second grid
  (`--grid wide2`), where this rule leaves 4;
- information about phi per kind of answer model, the pair maximising the posterior-weighted mean of the log
  of each kind's share of its own best gain (a compromise between the kinds still plausible): 3, at three
  times the time; the pair maximising the smallest share over the kinds holding 1 % of the posterior: 11 of
  notebook 12's 14 settings (`--grid study`, the myopic teacher included), where this rule leaves 10.

With the estimate read by stretches this rule leaves 2 of 12 on `--grid wide` (wiping at 20 % flips, 26
answers against 20; the skip teacher in wiping, 6 against 4) and 7 of 12 on `--grid study` (the myopic
teacher left out). Measured the same way:

- information about phi under all 30 models, not up to the six heaviest: 2 on the wide grid, in other settings
  (the stochastic teacher in wiping, 80 answers against told the model's 60; pushing at 20 % flips, 28 against
  19). On notebook 12's truths with ten blocks of seeds (`--blocks 10`, 100 environments per domain at once)
  it is over 1.25 in 4 of 12 where this rule is in 6: the stochastic teacher comes within (80 answers against
  65 in wiping, 100 against 85 in pushing), the equal teacher in pushing goes further (5 against 3), and the
  benchmark ran twice as long. Notebook 12's runs told nothing at the full profile took 1.7 times the work
  under it (206 s against 122 s, timed as `python -m hipref.bench.answers_time` times them, with the pairs
  within the central 99.8 %), enough to put the notebook over its 3 minutes on a slow day. Kept to the
  heaviest models spanning at most six rules (tables; the flip rates of one rule share theirs, `_mixed`),
  which costs what this rule does, it is over 1.25 in 5 of 12 on the same environments (200 answers each): the
  skip and equal teachers in wiping (5 and 4 answers against 3), and in pushing the paper's teacher at 20 %
  flips (33 against 23), the stochastic teacher (110 against 85) and the equal teacher (4 against 3). Each
  kind's most probable model alone, weighed by the whole kind's probability (every kind scored, none of its
  noisier parameters): 5 of 12 there too (wiping: the stochastic teacher 90 against 65, the skip and equal
  teachers 4 against 3; pushing: 20 % flips 33 against 23, the equal teacher 4 against 3);
- each model's information about phi given that model, weighed by the model's posterior, over all 30: 2 on
  the wide grid (the skip teacher, 8 answers in each domain against told the model's 4 in wiping and 5 in
  pushing);
- information about phi under the kind of highest posterior alone: 7 on the study grid, slower under the
  stochastic teacher (130 answers in wiping and 180 in pushing, against told the model's 55 and 85 and this
  rule's 85 and 140);
- two answers ahead, for the first query only (the information about phi of its answer and of the best second
  query after each answer, all 30 models): the widest pair or nearly, as this rule asks, (0.50, 0.90) m in
  wiping and (8.25, 20.0) kg in pushing (tied with (8.0, 19.75)). The pair the learner told the skip teacher
  asks first in wiping, (0.61, 0.65), is worth 0.56 nats over two answers against 0.67: no rule maximising
  the expected information of one or two answers asks it.

Ties (many pairs share a midpoint) are broken uniformly with the learner's rng. The likelihood of every
pair at every cell is computed once per (candidates, cells, model) and kept (`pair_table`), so a choice
costs a few array products over the pairs and the cells the belief holds.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import replace

import numpy as np
from scipy.special import entr

from hipref.learners.answer_models import AnswerModel, rule_of
from hipref.learners.sysid import CandidateSet
from hipref.validation import check_choice

QUERY_RULES: tuple[str, ...] = ("uniform", "thompson", "information_gain", "volume_removal")
"""The query rules; every learner takes one ('uniform', Algorithm 2's, by default)."""

CHOSEN: tuple[str, ...] = QUERY_RULES[1:]
"""The rules that choose from the belief (pairs only)."""

TIE = 1e-9
"""Scores within this of the best count as equal, and one of them is drawn."""

SUPPORT = 1e-12
"""Cells whose weight is below this share of the heaviest cell's are left out of a pair's score."""

SELECTED = 0.25
"""Pairs to score fewer than this share of all pairs have their rows selected first; more, and every pair is
scored (which costs less than selecting) and theirs kept."""

CENTRAL = 0.5
"""The chosen rules score only pairs whose midpoint lies within this central share of the belief about phi:
bisection asks at the median, and a pair far from it is asked only because some noisy answer model, still
weighed, predicts its answer poorly everywhere."""


@functools.lru_cache(maxsize=16)
def all_pairs(size: int) -> np.ndarray:
    """Every pair (i, j), i < j, of `size` candidates: shape (size (size - 1) / 2, 2); read-only, built once
    per size."""
    first, second = np.triu_indices(size, k=1)
    pairs = np.stack([first, second], axis=1)
    pairs.flags.writeable = False
    return pairs


class PairTable:
    """P(answer | cell) of every pair of Phi under one answer model, and its entropy, computed once."""

    def __init__(self, candidates: CandidateSet, cells: np.ndarray, model: AnswerModel) -> None:
        values = candidates.values
        self.pairs = all_pairs(values.size)
        offsets = (values[self.pairs][:, None, :] - cells[None, :, None]) / (candidates.high - candidates.low)
        probs = model.probabilities(offsets)  # (P, C, 4): first, second, skip, equal
        kept = probs.any(axis=(0, 1))
        self.outcomes = np.flatnonzero(kept)
        """Which of the four answers (first, second, skip, equal) the model can give."""
        self.row = np.full(4, -1)
        """Per answer column (first, second, skip, equal), its index among `outcomes`, -1 if never given."""
        self.row[self.outcomes] = np.arange(self.outcomes.size)
        self.probs = np.ascontiguousarray(probs[..., kept].transpose(0, 2, 1))  # (P, outcomes, C)
        self.entropy = entr(probs[..., kept]).sum(axis=-1)  # (P, C)
        exchanged = np.array([1, 0, 2, 3])[self.outcomes]
        self.swapped = np.ascontiguousarray(self.probs[:, np.searchsorted(self.outcomes, exchanged)])
        """`probs` with the answers 'first' and 'second' exchanged: what a flip turns them into."""


@functools.lru_cache(maxsize=256)
def _table(candidates: CandidateSet, cells: bytes, model: AnswerModel) -> PairTable:
    return PairTable(candidates, np.frombuffer(cells, dtype=np.float64), model)


def pair_table(candidates: CandidateSet, cells: np.ndarray | bytes, model: AnswerModel) -> PairTable:
    """The table of (candidates, cells, model), built on first use and kept for the process; `cells` may be
    given as their float64 bytes (`cells_key`), which a caller asking often keeps. A myopic model's memory
    leaves the law of one answer alone as it is: its table is the one without memory, so queries are scored
    with that law, not with the chain's prediction given the answers so far (`hipref.learners.pictures`)."""
    single = replace(model, memory=0.0) if model.memory else model
    return _table(candidates, cells if isinstance(cells, bytes) else cells_key(cells), single)


def cells_key(cells: np.ndarray) -> bytes:
    """The cells as `pair_table` keys its tables."""
    return np.ascontiguousarray(cells, dtype=np.float64).tobytes()


def pair_scores(
    rule: str,
    candidates: CandidateSet,
    cells: np.ndarray,
    beliefs: Sequence[tuple[AnswerModel, np.ndarray]],
    asked: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The score under `rule` ('information_gain' or 'volume_removal') of the pairs `asked` (indices into
    `all_pairs`; every pair if None), for a belief given as (answer model, weights over `cells`) terms whose
    weights sum to one over all terms: (pairs, scores).

    Information gain is about phi, not the answer model: with P(y, c) = sum_m w_mc P_m(y | c) and
    w_c = sum_m w_mc, I(y; phi) = H(sum_c P(y, c)) - sum_c w_c H(P(y, c) / w_c), where the last sum is
    -sum_yc P(y, c) log P(y, c) + sum_c w_c log w_c. Under one model it is sum_c w_c H(P(y | c)), read off
    the model's table; under several, cells the belief gives no weight are left out."""
    check_choice("rule", rule, ("information_gain", "volume_removal"))
    pairs = all_pairs(candidates.size)
    selected = asked if asked is not None and asked.size < SELECTED * pairs.shape[0] else None
    if len(beliefs) == 1:
        model, weights = beliefs[0]
        table = pair_table(candidates, cells, model)
        probs, entropy = (
            (table.probs, table.entropy)
            if selected is None
            else (table.probs[selected], table.entropy[selected])
        )
        mixture = probs @ weights
        conditional = entropy @ weights
    else:
        mixture, conditional = _mixed(candidates, cells, beliefs, selected)
    if rule == "volume_removal":
        scores = 1.0 - (mixture**2).sum(axis=1)
    else:
        scores = entr(mixture).sum(axis=1) - conditional
    if asked is None:
        return pairs, scores
    return pairs[asked], scores if selected is not None else scores[asked]


def _mixed(
    candidates: CandidateSet,
    cells: np.ndarray,
    beliefs: Sequence[tuple[AnswerModel, np.ndarray]],
    asked: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray]:
    """P(y) of each pair (over the answers some model gives) and sum_c w_c H(P(y | c)) under a belief
    over several models. A pair's answer under a rule with flips e is (1 - e) R + e R', R the rule's
    table and R' it with the two candidates' answers swapped, so the models sharing a rule cost two
    products whatever their flip rates: sum_m w_mc (1 - e_m) and sum_m w_mc e_m weigh R and R'."""
    kept: dict[AnswerModel, np.ndarray] = {}
    flipped: dict[AnswerModel, np.ndarray] = {}
    for model, weights in beliefs:
        rule = rule_of(model)
        kept[rule] = kept.get(rule, np.zeros(cells.size)) + (1.0 - model.flip) * weights
        flipped[rule] = flipped.get(rule, np.zeros(cells.size)) + model.flip * weights
    tables = {rule: pair_table(candidates, cells, rule) for rule in kept}
    outcomes = np.unique(np.concatenate([table.outcomes for table in tables.values()]))
    cell_weights = np.sum([weights for _, weights in beliefs], axis=0)
    held = np.flatnonzero(cell_weights > SUPPORT * cell_weights.max())
    size = candidates.size * (candidates.size - 1) // 2 if asked is None else asked.size
    joint = np.zeros((size, outcomes.size, held.size))
    term = np.empty_like(joint)
    for rule, table in tables.items():
        for probs, weights in ((table.probs, kept[rule]), (table.swapped, flipped[rule])):
            if not np.any(weights):
                continue
            probs = probs if asked is None else probs[asked]
            if held.size < cells.size:
                probs = probs[:, :, held]
            if table.outcomes.size == outcomes.size:  # the same answers: added in place
                joint += np.multiply(probs, weights[held], out=term)
            else:
                joint[:, np.searchsorted(outcomes, table.outcomes), :] += probs * weights[held]
    held_weights = cell_weights[held]
    conditional = entr(joint).sum(axis=(1, 2)) + held_weights @ np.log(held_weights)
    return joint.sum(axis=2), conditional


def worth_asking(
    candidates: CandidateSet, cells: np.ndarray, beliefs: Sequence[tuple[AnswerModel, np.ndarray]]
) -> np.ndarray | None:
    """Indices into `all_pairs` of the pairs whose midpoint lies within the belief's central half (`CENTRAL`),
    widened by half a step of Phi so that a belief on one cell still has a pair; None if no pair's does."""
    pairs = all_pairs(candidates.size)
    marginal = np.sum([weights for _, weights in beliefs], axis=0)
    cumulative = np.cumsum(marginal) / marginal.sum()
    low, high = (
        cells[min(int(np.searchsorted(cumulative, share)), cells.size - 1)]
        for share in ((1.0 - CENTRAL) / 2, (1.0 + CENTRAL) / 2)
    )
    midpoints = candidates.values[pairs].mean(axis=1)
    spread = candidates.resolution * (0.5 + 1e-9)  # a midpoint half a step away is in, whatever its rounding
    asked = np.flatnonzero((midpoints >= low - spread) & (midpoints <= high + spread))
    return asked if asked.size else None


def choose_pair(
    rule: str,
    candidates: CandidateSet,
    cells: np.ndarray,
    beliefs: Sequence[tuple[AnswerModel, np.ndarray]],
    rng: np.random.Generator,
) -> tuple[int, int]:
    """Indices into Phi of the pair `rule` (one of CHOSEN) asks about next."""
    check_choice("rule", rule, CHOSEN)
    if rule == "thompson":
        return _thompson(candidates, cells, beliefs, rng)
    pairs, scores = pair_scores(rule, candidates, cells, beliefs, worth_asking(candidates, cells, beliefs))
    best = np.flatnonzero(scores >= scores.max() - TIE)
    chosen = pairs[best[rng.integers(best.size)]]
    return int(chosen[0]), int(chosen[1])


def _thompson(
    candidates: CandidateSet,
    cells: np.ndarray,
    beliefs: Sequence[tuple[AnswerModel, np.ndarray]],
    rng: np.random.Generator,
    tries: int = 20,
) -> tuple[int, int]:
    weights = np.sum([w for _, w in beliefs], axis=0)
    weights = weights / weights.sum()
    values = candidates.values
    first = int(np.abs(values - cells[rng.choice(cells.size, p=weights)]).argmin())
    for _ in range(tries):
        second = int(np.abs(values - cells[rng.choice(cells.size, p=weights)]).argmin())
        if second != first:
            return first, second
    # A belief so sharp that both draws round alike: ask about the nearest neighbour.
    return first, first + 1 if first + 1 < values.size else first - 1

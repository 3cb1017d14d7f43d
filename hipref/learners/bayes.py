"""A Bayesian preference learner: the exact posterior over phi from every answer (beyond the paper).

PESI moves SI's distribution a little per answer (Eq. 2). What the answers allow is the posterior

    Pr(phi, m | answers) ∝ Pr(phi) Pr(m) prod_t P(answer_t | query_t, phi, m),

over the truth phi and the teacher's answer model m (`hipref.learners.answer_models`; a myopic model with
memory reads answer_t given the ones before, `hipref.learners.pictures`): told the model, m is fixed;
otherwise every model of `model_family()` is weighed by its marginal likelihood. Queries are scored on the
heaviest models of the posterior (`PreferencePosterior.query_beliefs`), and the estimate is read from the
whole posterior (Bayesian model averaging) by `hipref.learners.estimates`.

phi lives on a fine grid of points over the range, `refine` per step of Phi, every midpoint of two
candidates among them: with the flip model the posterior is then exact on the intervals between pair
midpoints and on the midpoints themselves (where a teacher breaks ties at random, as for a truth on the grid
of Phi).

The prior is uniform, or ('si') SI's Pr(phi | tau) on the slice the estimate is for: the answers' posterior
times SI's output on each evaluation slice, so what OSI knows is kept. The learner asks with a query rule
(`hipref.learners.queries`); under 'uniform' it draws exactly what PESILearner draws from the same seed, so
the two are paired on the same queries and answers.
"""

from __future__ import annotations

import operator
from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated

import numpy as np
import torch

from hipref.learners.answer_models import (
    EQUAL_COLUMN,
    SKIP_COLUMN,
    AnswerModel,
    model_family,
    rule_of,
    with_flip,
)
from hipref.learners.estimates import (
    ESTIMATES,
    SuccessCurve,
    cell_stretches,
    check_success_curve,
    read_estimate,
)
from hipref.learners.pictures import PictureChain
from hipref.learners.queries import QUERY_RULES, cells_key, choose_pair, pair_table
from hipref.learners.sysid import CandidateSet, SIModel
from hipref.teachers.preference import EQUAL, NoLabel, PreferenceQuery, preference_label_vector
from hipref.validation import Integer, OneOf, check_fields, check_int

PRIORS: tuple[str, ...] = ("uniform", "si")
"""The prior over phi: uniform over the range, or SI's Pr(phi | tau) on the slice estimated for."""


def answer_column(label: int | np.ndarray | NoLabel, n_candidates: int) -> int:
    """The answer as a column of `AnswerModel.probabilities`: the preferred candidate's index, or the
    'skip' / 'equally good' column; a malformed label is refused."""
    if isinstance(label, NoLabel):
        return n_candidates + (EQUAL_COLUMN if label is EQUAL else SKIP_COLUMN) + 2
    return int(np.argmax(preference_label_vector(label, n_candidates)))


class PreferencePosterior:
    """Pr(phi, m | answers) on a grid of cells over Phi's range, for answer models m (module docstring)."""

    def __init__(self, candidates: CandidateSet, models: tuple[AnswerModel, ...], refine: int = 4) -> None:
        check_int("refine", refine, 2)
        if refine % 2:
            raise ValueError(f"refine must be even (cells nest in half steps of Phi), got {refine}")
        if not models:
            raise ValueError("models must hold at least one AnswerModel, got ()")
        self.candidates = candidates
        self.models = models
        self.refine = refine
        self.cells = np.linspace(candidates.low, candidates.high, (candidates.size - 1) * refine + 1)
        """The hypothetical truths, `refine` per step of Phi, both ends and every pair midpoint included: a
        truth on a midpoint makes the teacher break a tie at random, which only that point explains."""
        half = refine // 2
        self.query_points = np.linspace(candidates.low, candidates.high, (candidates.size - 1) * 4 + 1)
        """What query rules score on: the half steps' ends (every pair midpoint) and centres. Any point inside
        a half step has the same flip-model likelihood for any pair, so its centre stands for it."""
        self._cells_key = cells_key(self.cells)
        index = np.arange(self.cells.size)
        self._query_index = 2 * (index // half) + (index % half != 0)
        self.stretches = cell_stretches(self.cells, half)
        """Per cell, the stretch of Phi its weight stands for (`hipref.learners.estimates.Stretches`): a pair
        midpoint (or an end of the range) is a point; the cells between two midpoints share the open interval
        between them (with refine 2 there are none, and every cell is a point)."""
        kinds = [m.kind for m in models]
        # Uniform over the kinds, then over each kind's parameters.
        self.log_model_prior = np.array([-np.log(len(set(kinds))) - np.log(kinds.count(k)) for k in kinds])
        self.log_likelihood = np.zeros((len(models), self.cells.size))
        self.answers: list[tuple[np.ndarray, int]] = []
        self.chains = {k: PictureChain(m, candidates, self.cells) for k, m in enumerate(models) if m.memory}
        """Per myopic model with memory, its picture's chain; the others (`_alone`) read each answer alone."""
        self._alone = [k for k in range(len(models)) if k not in self.chains]

    def _probabilities(self, candidates: np.ndarray, column: int) -> np.ndarray:
        if candidates.size == 2:
            return self._pair_probabilities(candidates, column)
        return self._computed_probabilities(candidates, column)

    def _pair_probabilities(self, candidates: np.ndarray, column: int) -> np.ndarray:
        """A pair's likelihood read from the models' tables of every pair of Phi (`pair_table`)."""
        i, j = (self.candidates.index_of(float(v)) for v in candidates)
        if i == j:
            raise ValueError(f"candidates must be distinct, got {tuple(candidates)}")
        if i > j:  # the table holds (lower, higher): the first and second answers swap
            i, j = j, i
            column = {0: 1, 1: 0}.get(column, column)
        pair = i * self.candidates.size - i * (i + 1) // 2 + (j - i - 1)
        rows = np.zeros((len(self.models), self.cells.size))
        for k in self._alone:
            table = pair_table(self.candidates, self._cells_key, self.models[k])
            if (kept := table.row[column]) >= 0:
                rows[k] = table.probs[pair, kept]
        return rows

    def _computed_probabilities(self, candidates: np.ndarray, column: int) -> np.ndarray:
        offsets = (candidates[None, :] - self.cells[:, None]) / (self.candidates.high - self.candidates.low)
        # A model's flip acts after its rule: the rule is computed once per model without the flip.
        rules: dict[AnswerModel, np.ndarray] = {}
        rows = np.zeros((len(self.models), self.cells.size))
        for k in self._alone:
            rule = rule_of(self.models[k])
            if rule not in rules:
                rules[rule] = rule.probabilities(offsets)
            rows[k] = with_flip(rules[rule], self.models[k].flip)[:, column]
        return rows

    def update(self, candidates: tuple[float, ...], column: int) -> None:
        """Multiply in the likelihood of one answer (`answer_column`) to a query over `candidates`."""
        values = np.asarray(candidates, dtype=np.float64)
        with np.errstate(divide="ignore"):
            log_p = np.log(self._probabilities(values, column))
        states = {}
        for k, chain in self.chains.items():
            log_p[k], states[k] = chain.step(values, column)
        total = self.log_likelihood + log_p
        if not np.isfinite(total.max()):
            raise ValueError(
                f"the answer {column} to {tuple(values)} is impossible under every answer model given the "
                "answers before it (a teacher model that never errs, contradicted)"
            )
        self.log_likelihood = total
        for k, state in states.items():
            self.chains[k].state = state
        self.answers.append((values, column))

    def joint(self, log_prior: np.ndarray | None = None) -> np.ndarray:
        """Pr(m, phi | answers) as (models, cells), summing to one; `log_prior` over the cells (uniform).
        Normalised as scipy.special.logsumexp normalises, to the bit (the k largest terms apart: log1p of the
        rest's sum over k, plus log k), without its array-API dispatch, which costs more than the sum."""
        log_w = self.log_likelihood + self.log_model_prior[:, None]
        if log_prior is not None:
            log_w = log_w + log_prior[None, :]
        peak = log_w.max()
        top = log_w == peak
        k = top.sum(dtype=np.float64)
        rest = np.exp(np.where(top, -np.inf, log_w) - peak).sum()
        return np.exp(log_w - (np.log1p(rest / k) + np.log(k) + peak))

    def phi(self, log_prior: np.ndarray | None = None) -> np.ndarray:
        """Pr(phi | answers) over the cells, the answer models averaged by their posterior."""
        return self.joint(log_prior).sum(axis=0)

    def model_posterior(self) -> dict[str, float]:
        """Pr(kind | answers) per answer-model kind: the marginal likelihoods, normalised."""
        per_model = self.joint().sum(axis=1)
        kinds: dict[str, float] = {}
        for model, weight in zip(self.models, per_model, strict=True):
            kinds[model.kind] = kinds.get(model.kind, 0.0) + float(weight)
        return kinds

    def chosen_model(self) -> AnswerModel:
        """The answer model (kind and parameters) of highest posterior probability."""
        return self.models[int(self.joint().sum(axis=1).argmax())]

    def wrong_probabilities(self) -> np.ndarray:
        """Per labelled answer, in order, the posterior probability that it was wrong: that its preferred
        candidate is not the nearest to the truth (a filter to score like co-teaching's)."""
        weights = self.phi()
        wrong = []
        for values, column in self.answers:
            if column >= values.size:
                continue
            distances = np.abs(values[None, :] - self.cells[:, None])
            nearest = np.isclose(distances[:, column], distances.min(axis=1), rtol=1e-9, atol=1e-12)
            wrong.append(float(weights[~nearest].sum()))
        return np.array(wrong)

    def query_beliefs(self, mass: float = 0.999, most: int = 6) -> list[tuple[AnswerModel, np.ndarray]]:
        """The belief a query rule scores: per model, its weights summed onto `query_points`, for the
        heaviest models holding `mass` of the posterior (at most `most`), renormalised."""
        joint = self.joint()
        per_model = joint.sum(axis=1)
        order = np.argsort(per_model)[::-1]
        keep = order[: max(1, min(most, int(np.searchsorted(np.cumsum(per_model[order]), mass)) + 1))]
        total = per_model[keep].sum()
        size = self.query_points.size
        return [
            (self.models[i], np.bincount(self._query_index, weights=joint[i], minlength=size) / total)
            for i in keep
        ]


@dataclass(frozen=True)
class BayesConfig:
    """The Bayesian preference learner's options."""

    n_candidates: Annotated[int, Integer(2)] = 2
    """N, candidates per query; the chosen query rules ask pairs."""
    query_rule: Annotated[str, OneOf(QUERY_RULES)] = "uniform"
    """How queries are chosen, one of QUERY_RULES (`hipref.learners.queries`)."""
    answer_models: tuple[AnswerModel, ...] | None = None
    """The answer models weighed by their marginal likelihood: one if told the teacher's model (`told`),
    a kind's grid if told its kind (`hypotheses`); None: every model of `model_family()`."""
    prior: Annotated[str, OneOf(PRIORS)] = "uniform"
    """One of PRIORS: 'uniform', or 'si' (SI's Pr(phi | tau) on the slice estimated for)."""
    estimate: Annotated[str, OneOf(ESTIMATES)] = "within_step"
    """One of ESTIMATES: 'within_step', 'median', 'mean', or 'expected_success' (needs a success curve)."""
    refine: Annotated[int, Integer(2)] = 4
    """Points of the posterior per step of Phi (even): 4 puts one on every pair midpoint and one inside
    every interval between midpoints, where the flip model's posterior is constant."""

    def __post_init__(self) -> None:
        check_fields(self)
        if self.query_rule != "uniform" and self.n_candidates != 2:
            raise ValueError(
                f"query_rule {self.query_rule!r} asks pairs: n_candidates must be 2, got {self.n_candidates}"
            )
        if self.answer_models is not None and (
            not self.answer_models or not all(isinstance(m, AnswerModel) for m in self.answer_models)
        ):
            raise ValueError(f"answer_models must be AnswerModels or None, got {self.answer_models!r}")


class BayesLearner:
    """The posterior through ask/tell, beside PESILearner: ask a query, be told the answer, estimate phi.

    `si_model` is SI (pretrained, never updated), needed for prior 'si' (its Pr(phi | tau))."""

    def __init__(
        self,
        candidates: CandidateSet,
        config: BayesConfig | None = None,
        seed: int = 0,
        si_model: SIModel | None = None,
        success_curve: SuccessCurve | None = None,
    ) -> None:
        self.config = config if config is not None else BayesConfig()
        try:
            seed = operator.index(seed)
        except TypeError:
            raise ValueError(f"seed must be an integer >= 0, got {seed!r}") from None
        check_int("seed", seed, 0)
        if self.config.estimate == "expected_success" and success_curve is None:
            raise ValueError("estimate 'expected_success' needs a success_curve (errors, success rates)")
        if success_curve is not None:
            check_success_curve(success_curve)
        if self.config.prior == "si" and si_model is None:
            raise ValueError("prior 'si' needs the SI model (si_model)")
        if si_model is not None and si_model.candidates != candidates:
            raise ValueError(f"si_model's candidates {si_model.candidates} differ from {candidates}")
        self.si_model = si_model
        self.candidates = candidates
        if self.config.n_candidates > self.candidates.size:
            raise ValueError(
                f"n_candidates must be at most |Phi| = {self.candidates.size}, got {self.config.n_candidates}"
            )
        models = self.config.answer_models if self.config.answer_models is not None else model_family()
        if self.config.n_candidates > 2:
            # The distance-dependent confusion is defined on pairs alone.
            models = tuple(m for m in models if m.kind != "distance")
            if not models:
                raise ValueError("the 'distance' answer model is for pairs only: n_candidates must be 2")
        self.posterior = PreferencePosterior(self.candidates, models, self.config.refine)
        # The same streams as PESILearner's: under 'uniform' the same queries from the same seed.
        query_seed, _, _ = np.random.SeedSequence(seed).spawn(3)
        self._query_rng = np.random.default_rng(query_seed)
        self._success = success_curve
        self.unlabelled = 0

    def __len__(self) -> int:
        """The number of labelled answers received."""
        return len(self.posterior.answers) - self.unlabelled

    def ask(
        self, observe: Callable[[float, np.random.Generator], np.ndarray] | None = None
    ) -> PreferenceQuery:
        """The next query. Under 'uniform', N distinct candidates drawn uniformly and tau observed on one,
        as PESILearner.ask; under a chosen rule, the pair the rule picks from the posterior. `observe(phi,
        rng)` executes pi^l with phi and returns a slice, taken under 'uniform' only, where it keeps the
        draws PESI's (with a replayed clip it costs nothing): the answers alone update the posterior, and a
        scripted teacher never sees a clip."""
        n = self.config.n_candidates
        size = self.candidates.size
        if self.config.query_rule == "uniform":
            chosen = self._query_rng.choice(size, size=n, replace=False, p=np.full(size, 1.0 / size))
            sliced = int(self._query_rng.integers(n))
        else:
            chosen = np.array(
                choose_pair(
                    self.config.query_rule,
                    self.candidates,
                    self.posterior.query_points,
                    self.posterior.query_beliefs(),
                    self._query_rng,
                )
            )
            sliced = 0
        candidates = tuple(float(c) for c in self.candidates.values[chosen])
        tau = np.zeros(0)
        if observe is not None and self.config.query_rule == "uniform":
            tau = np.asarray(observe(candidates[sliced], self._query_rng), dtype=np.float64)
        return PreferenceQuery(candidates, features=tau)

    def tell(self, query: PreferenceQuery, label: int | np.ndarray | NoLabel) -> None:
        """Multiply the answer's likelihood into the posterior (a malformed label is refused)."""
        if len(query.candidates) != self.config.n_candidates:
            raise ValueError(
                f"query must have n_candidates={self.config.n_candidates} candidates, "
                f"got {len(query.candidates)}"
            )
        for value in query.candidates:
            self.candidates.index_of(value)
        column = answer_column(label, self.config.n_candidates)
        self.posterior.update(query.candidates, column)
        if isinstance(label, NoLabel):
            self.unlabelled += 1

    def _log_prior(self, features: np.ndarray | None) -> np.ndarray | None:
        if self.config.prior == "uniform":
            return None
        if features is None:
            raise ValueError("prior 'si' needs the slice tau the estimate is for")
        assert self.si_model is not None
        with torch.no_grad():
            x = torch.as_tensor(np.asarray(features, dtype=np.float64), dtype=torch.float32)
            probs = self.si_model.distribution(x).double().numpy()
        # SI's mass on candidate k spread over the cells nearest it.
        nearest = np.clip(
            np.rint((self.posterior.cells - self.candidates.low) / self.candidates.resolution),
            0,
            self.candidates.size - 1,
        ).astype(int)
        counts = np.bincount(nearest, minlength=self.candidates.size)
        with np.errstate(divide="ignore"):
            return np.log(probs[nearest] / counts[nearest])

    def distribution(self, features: np.ndarray | None = None) -> np.ndarray:
        """Pr(phi | answers) over the posterior's cells, the answer models averaged (times SI's Pr(phi | tau)
        under prior 'si'): what the estimate is read from."""
        return self.posterior.phi(self._log_prior(features))

    def estimate(self, features: np.ndarray | None = None, reading: str | None = None) -> float:
        """The value the controller is given (config `estimate`), or another `reading` of the same posterior
        (one of ESTIMATES)."""
        reading = self.config.estimate if reading is None else reading
        weights = self.distribution(features)
        return read_estimate(
            reading,
            self.posterior.cells,
            weights,
            self.candidates.resolution,
            self._success,
            self.posterior.stretches,
        )

    def estimates(self, slices: np.ndarray) -> np.ndarray:
        """The estimate on each of (slices, input_dim) slices (the same for each under prior 'uniform')."""
        return np.array([self.estimate(s) for s in slices])

    def running_estimate(self, evaluation: np.ndarray) -> float:
        """What the learner gives the controller during a teaching session: its estimate (config
        `estimate`), read without the session's probing slices `evaluation`."""
        return self.estimate()

    def filter_precision_recall(self, wrong_labels: list[bool]) -> tuple[float, float]:
        """The posterior as a filter of wrong answers: an answer is flagged when Pr(wrong | answers) > 1/2.
        Precision (wrong among flagged) and recall (flagged among wrong) against the teacher's record, NaN
        where undefined, as `PESILearner.filter_precision_recall`."""
        flagged = self.posterior.wrong_probabilities() > 0.5
        wrong = np.asarray(wrong_labels, dtype=bool)
        if wrong.shape != flagged.shape:
            raise ValueError(
                f"wrong_labels must have one flag per labelled answer ({flagged.size}), got {wrong.size}"
            )
        hits = float((flagged & wrong).sum())
        precision = hits / flagged.sum() if flagged.any() else float("nan")
        recall = hits / wrong.sum() if wrong.any() else float("nan")
        return precision, recall

    def mode(self, features: np.ndarray | None = None) -> float:
        """The most probable cell."""
        return float(self.posterior.cells[int(self.distribution(features).argmax())])

"""The learner a teaching session tells, built from the session's config: notebook 12's Bayesian learner or
PESI (Algorithm 2) with the session's query rule, seeded by the session's own random streams, and the estimate
it would give the controller."""

from __future__ import annotations

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from hipref.envs.task import Task, probe_slice
from hipref.experiments.domains import domain_spec
from hipref.learners.answer_models import person_family
from hipref.learners.bayes import BayesConfig, BayesLearner
from hipref.learners.pesi import PESIConfig, PESILearner
from hipref.learners.queries import pair_table
from hipref.learners.sysid import SIModel
from hipref.seeds import integer_seed
from hipref.teach.config import TeachConfig

EVALUATION_SLICES = 3
"""Probing slices PESI's running estimate is the mean of (SI's multi-slice estimate)."""

Learner = PESILearner | BayesLearner
"""A learner a session can tell its preferences."""


class SessionStreams(NamedTuple):
    """A session's independent random streams, children of its seed."""

    learner: np.random.SeedSequence
    layouts: np.random.SeedSequence
    sides: np.random.SeedSequence
    evaluation: np.random.SeedSequence
    slices: np.random.SeedSequence
    """Where a slice is cut from a clip when the learner asked without observing one (a chosen query)."""
    display: np.random.SeedSequence
    """The layout every query's clips are shown from (`hipref.teach.clips.CandidateClips`)."""


def session_streams(config: TeachConfig) -> SessionStreams:
    # A child's stream does not depend on how many are spawned: the first five are those of sessions
    # recorded before the display layout was added.
    return SessionStreams(*np.random.SeedSequence([config.seed, 9]).spawn(6))


def bayes_learner(config: TeachConfig, model: SIModel, seed: int) -> Learner:
    """The Bayesian learner with the session's query rule, weighing every answer model with a person's
    lapse (`person_family`: no answer, however many "can't tell", is impossible to it)."""
    candidates = domain_spec(config.domain).candidates
    bayes = BayesConfig(query_rule=config.query_rule, answer_models=person_family())
    return BayesLearner(candidates, bayes, seed, si_model=model)


def pesi_learner(config: TeachConfig, model: SIModel, seed: int) -> Learner:
    """PESI with the session's query rule on the domain's batch size."""
    spec = domain_spec(config.domain)
    pesi = PESIConfig(
        batch_size=spec.batch_size, history=config.data.history, candidate_sampling=config.query_rule
    )
    return PESILearner(model, pesi, seed)


SESSION_LEARNERS: dict[str, Callable[[TeachConfig, SIModel, int], Learner]] = {
    "bayes": bayes_learner,
    "pesi": pesi_learner,
}
"""How each of `hipref.teach.config.LEARNERS` is built from the session's config, SI and seed."""


def make_learner(config: TeachConfig, model: SIModel, learner: str | None = None) -> Learner:
    """The session's learner (`config.learner`, or `learner`) with its query rule, seeded by the session."""
    seed = integer_seed(session_streams(config).learner)
    return SESSION_LEARNERS[learner or config.learner](config, model, seed)


def warm(learner: Learner) -> None:
    """Compute what telling the learner its first answer reads, before a person gives it: the Bayesian
    learner's likelihood of every pair under each answer model (`pair_table`, kept for the process; built
    when the first answer is told, it took 0.8 s, the first answer's wait). PESI reads nothing of the kind."""
    if isinstance(learner, BayesLearner):
        posterior = learner.posterior
        for model in posterior.models:
            pair_table(posterior.candidates, posterior.cells, model)


def evaluation_slices(config: TeachConfig, task: Task) -> np.ndarray:
    """The probing slices PESI's running estimate is read on (SI's multi-slice estimate)."""
    rng = np.random.default_rng(session_streams(config).evaluation)
    h = config.data.history
    return np.stack([probe_slice(task, config.true_parameter, h, rng) for _ in range(EVALUATION_SLICES)])


def running_estimate(learner: Learner, evaluation: np.ndarray) -> float:
    """What the session's learner would give the controller: the Bayesian learner's estimate, or PESI's
    SI read on the session's probing slices."""
    return learner.running_estimate(evaluation)

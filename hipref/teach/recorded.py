"""A stored session as a teacher: a person's answers re-run through the learners and the noise estimators.

`RecordedPreferenceTeacher` answers each query with the label the session stored for it, as the scripted
teachers answer theirs, after checking that the query is the one the person was shown. `replay` rebuilds a
learner of the session's environment from the stored queries and slices (no physics): PESI, as in the session,
CO-PESI with its noise level estimated (A.9), which a person's unknown flip rate calls for, or the Bayesian
learner told nothing of the teacher (`hipref.learners.bayes`), which asks the same queries from the same seed
and also reads "can't tell" (the truth near the pair's midpoint). `summary` reads
what the answers say about the person: how often they agreed with the truth, how long they took, and the
flip rate each estimator infers from the answers alone. "Can't tell" answers give PESI no label and are
left out of every count but their own.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from hipref.experiments.domains import domain_spec
from hipref.experiments.si_pretraining import pretrained_model
from hipref.learners.coteaching import CoTeaching
from hipref.learners.noise_estimation import CONFLICTS, PreferenceSet, estimate_noise
from hipref.learners.noise_rate import Algorithm5, likelihood_noise, repeated_pair_noise
from hipref.learners.pesi import PESIConfig, PESILearner
from hipref.learners.sysid import SIModel
from hipref.seeds import integer_seed
from hipref.teach.config import TeachConfig
from hipref.teach.learner import (
    Learner,
    evaluation_slices,
    make_learner,
    running_estimate,
    session_streams,
)
from hipref.teach.preferences import tell
from hipref.teach.session import SessionFile
from hipref.teachers.preference import PreferenceQuery, pair_labels
from hipref.validation import check_choice


def estimated_noise_learner(config: TeachConfig, model: SIModel) -> Learner:
    """CO-PESI with Algorithm 5's noise level (co_pesi_estimated), seeded by the session."""
    spec = domain_spec(config.domain)
    pesi = PESIConfig(batch_size=spec.batch_size, history=config.data.history, start_size=spec.batch_size)
    coteaching = CoTeaching(refresh_frequency=spec.refresh_frequency)
    seed = integer_seed(session_streams(config).learner)
    return PESILearner(model, pesi, seed, coteaching, Algorithm5())


REPLAYERS: dict[str, Callable[[TeachConfig, SIModel], Learner]] = {
    "pesi": lambda config, model: make_learner(config, model, "pesi"),
    "co_pesi_estimated": estimated_noise_learner,
    "bayes": lambda config, model: make_learner(config, model, "bayes"),
}
"""Learners a session can be replayed into, and how each is built."""

REPLAYED: tuple[str, ...] = tuple(REPLAYERS)
"""Their names."""


class RecordedPreferenceTeacher:
    """Answers the session's queries in order with the stored labels (None for "can't tell")."""

    def __init__(self, records: Sequence[dict[str, Any]]) -> None:
        self.records = list(records)
        self.asked = 0

    def answer(self, query: PreferenceQuery) -> int | None:
        """The stored label of the next query; ValueError if `query` is not the one that was shown."""
        if self.asked >= len(self.records):
            raise ValueError(
                f"the session holds {len(self.records)} answers; query {self.asked + 1} has none"
            )
        record = self.records[self.asked]
        if list(query.candidates) != record["candidates"]:
            raise ValueError(
                f"query {self.asked} asks about {list(query.candidates)}, but the person was shown "
                f"{record['candidates']}"
            )
        self.asked += 1
        return record["label"]


def replay(config: TeachConfig, records: Sequence[dict[str, Any]], method: str = "pesi") -> Learner:
    """A learner of `method` told the session's answers in order, on the stored queries and slices (no
    physics). It is told the queries the person answered, whichever learner asked them; a session's own
    learner is rebuilt exactly."""
    check_choice("method", method, REPLAYED)
    learner = REPLAYERS[method](config, pretrained_model(config.domain, config.data))
    for record in records:
        if record.get("catch", False):  # catch trials are not told (`hipref.teach.preferences`)
            continue
        # The slice the person's clip was cut from; the Bayesian learner reads only the candidates.
        features = np.array(record["clip"]["tau"])
        tell(learner, PreferenceQuery(tuple(record["candidates"]), features=features), record["label"])
    return learner


def labelled(records: Sequence[dict[str, Any]]) -> PreferenceSet:
    """The answers that carry a label, as a preference dataset (Algorithm 5's input)."""
    kept = [r for r in records if r["label"] is not None]
    return PreferenceSet(
        first=np.array([r["candidates"][0] for r in kept]),
        second=np.array([r["candidates"][1] for r in kept]),
        label=np.array([r["label"] for r in kept]),
    )


def summary(session: SessionFile, config: TeachConfig) -> dict[str, float]:
    """What the session's preference answers say: counts, agreement with the truth, answer times, the
    flip rate each estimator infers from the labels alone, and the error of the learners replayed."""
    records = session.of_kind("preference")
    if not records:
        raise ValueError(f"{session.path} holds no preference answers yet")
    data = labelled(records)
    clean, tie = pair_labels(data.first, data.second, config.true_parameter)
    judged = ~tie
    spec = domain_spec(config.domain)
    seconds = np.array([r["seconds"] for r in records])
    result: dict[str, float] = {
        "answers": float(len(records)),
        "cant_tell": float(sum(r["label"] is None for r in records)),
        "agreement_with_truth": float(np.mean(data.label[judged] == clean[judged]))
        if judged.any()
        else np.nan,
        "median_seconds": float(np.median(seconds)),
        "slowest_seconds": float(seconds.max()),
    }
    if len(data):
        for conflict in CONFLICTS:
            result[f"algorithm5_{conflict}"] = estimate_noise(data, conflict)
        result["marginal_likelihood"] = likelihood_noise(data, spec.candidates.low, spec.candidates.high)
        result["repeated_pair"] = repeated_pair_noise(data)
    for method, estimate in estimates(config, records).items():
        result[f"{method}_error"] = abs(estimate - config.true_parameter)
    return result


def estimates(config: TeachConfig, records: Sequence[dict[str, Any]]) -> dict[str, float]:
    """Each learner's estimate of the parameter from the session's preference `records`: 'osi' (the
    pretrained SI, told nothing) and every `REPLAYED` learner, read as the session reads its own
    (`running_estimate`: the Bayesian learner's estimate, SI's mean on the probing slices)."""
    evaluation = evaluation_slices(config, domain_spec(config.domain).make_task())
    osi = pretrained_model(config.domain, config.data)
    result = {"osi": float(osi.predict(evaluation).mean())}
    for method in REPLAYED:
        result[method] = running_estimate(replay(config, records, method), evaluation)
    return result

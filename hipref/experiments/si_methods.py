"""The methods of an SI run by name, and the learner each builds (`make_learner`).

Every method fine-tunes (or, for OSI, keeps) the same pretrained SI model with the same PESI settings,
which `make_learner` reads from the run once; a method's builder adds only what it needs beyond them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from hipref.experiments.domains import domain_spec
from hipref.learners.answer_models import hypotheses
from hipref.learners.bayes import BayesConfig, BayesLearner
from hipref.learners.coteaching import (
    CoPESIConfig,
    CoPESILearner,
    EstimatedNoiseCoPESILearner,
    reset_every_step_schedule,
)
from hipref.learners.pesi import PESIConfig, PESILearner
from hipref.learners.robust import (
    LabelSmoothingPESILearner,
    LikelihoodNoiseCoPESILearner,
    RobustPESIConfig,
    SmallLossPESILearner,
    TrustFlipPESILearner,
    UnbiasedPESILearner,
)
from hipref.learners.sysid import SIModel

if TYPE_CHECKING:
    from hipref.experiments.si_run import SIRun

Learner = PESILearner | BayesLearner
"""What a method's learner is: PESI (and the learners built on it) or the Bayesian learner."""

LearnerBuilder = Callable[["SIRun", SIModel, dict[str, Any], int], "Learner | None"]
"""Builds a method's learner from the cell, the pretrained model, the PESI settings every method shares
(`common`) and the learner's seed; None for a method that learns nothing."""


def _coteaching_config(cell: SIRun, common: dict[str, Any]) -> CoPESIConfig:
    spec = domain_spec(cell.domain)
    learned = cell.fine_tuning.coteaching_schedule == "learned"
    schedule = CoPESIConfig if learned else reset_every_step_schedule
    return schedule(start_size=spec.batch_size, refresh_frequency=spec.refresh_frequency, **common)


def _bayes_config(cell: SIRun) -> BayesConfig:
    models = hypotheses(cell.teacher, cell.noise, cell.told)
    return BayesConfig(cell.n_candidates, cell.fine_tuning.candidate_sampling, models)


def _robust_config(cell: SIRun, common: dict[str, Any]) -> RobustPESIConfig:
    return RobustPESIConfig(start_size=domain_spec(cell.domain).batch_size, **common)


LEARNERS: dict[str, LearnerBuilder] = {
    "osi": lambda cell, model, common, seed: None,
    "pesi": lambda cell, model, common, seed: PESILearner(model, PESIConfig(loss="soft", **common), seed),
    "pesi_ce": lambda cell, model, common, seed: PESILearner(
        model, PESIConfig(loss="standard", **common), seed
    ),
    "co_pesi": lambda cell, model, common, seed: CoPESILearner(
        model, cell.noise, _coteaching_config(cell, common), seed
    ),
    # A.9: the forget number comes from Algorithm 5 on the preferences so far, not the true noise.
    "co_pesi_estimated": lambda cell, model, common, seed: EstimatedNoiseCoPESILearner(
        model, _coteaching_config(cell, common), seed
    ),
    "co_pesi_estimated_same_pair": lambda cell, model, common, seed: EstimatedNoiseCoPESILearner(
        model, _coteaching_config(cell, common), seed, conflict="same_pair"
    ),
    "pesi_smoothed": lambda cell, model, common, seed: LabelSmoothingPESILearner(
        model, _robust_config(cell, common), seed
    ),
    "pesi_unbiased": lambda cell, model, common, seed: UnbiasedPESILearner(
        model, _robust_config(cell, common), seed
    ),
    "pesi_small_loss": lambda cell, model, common, seed: SmallLossPESILearner(
        model, _robust_config(cell, common), seed
    ),
    "pesi_rime": lambda cell, model, common, seed: TrustFlipPESILearner(
        model, _robust_config(cell, common), seed
    ),
    "co_pesi_likelihood": lambda cell, model, common, seed: LikelihoodNoiseCoPESILearner(
        model, _coteaching_config(cell, common), seed
    ),
    "bayes": lambda cell, model, common, seed: BayesLearner(
        model.candidates, _bayes_config(cell), seed, si_model=model
    ),
    "bayes_si": lambda cell, model, common, seed: BayesLearner(
        model.candidates, dataclasses.replace(_bayes_config(cell), prior="si"), seed, si_model=model
    ),
}
"""Every method by name. osi: pretrained, no preferences; pesi: Eq. 2/3; pesi_ce: standard cross-entropy
(A.8); co_pesi: Algorithm 1 told the true noise level; co_pesi_estimated: Algorithm 1 with the noise level
estimated by Algorithm 5 from the preferences so far (A.9), a conflict read as 'no parameter satisfies
both'; co_pesi_estimated_same_pair: the same with a conflict read as opposite answers to the same pair.
Beyond the paper (`hipref.learners.robust`): pesi_smoothed: label smoothing of Eq. 2 (conservative);
pesi_unbiased: the unbiased loss with the estimated flip rate; pesi_small_loss: SI's own small-loss
filter; pesi_rime: RIME's trust-and-flip; co_pesi_likelihood: Algorithm 1 with the maximum marginal
likelihood flip rate; bayes: the exact posterior over phi from every answer (`hipref.learners.bayes`), its
model of the teacher chosen by marginal likelihood unless told; bayes_si: that posterior times SI's Pr(phi
| tau) on the slice estimated from, so OSI's knowledge is kept."""

METHODS: tuple[str, ...] = tuple(LEARNERS)
"""The methods' names, in LEARNERS' order."""

LEARNING_METHODS: frozenset[str] = frozenset(METHODS) - {"osi"}
"""Methods whose learner is told preferences (OSI keeps the pretrained SI)."""

COTEACHING_METHODS: frozenset[str] = frozenset(m for m in METHODS if m.startswith("co_pesi"))
"""Methods filtering with co-teaching classifiers (Algorithm 1), which `FineTuning.coteaching_schedule`
refreshes: every CO-PESI, named so here."""

BAYES_METHODS: frozenset[str] = frozenset({"bayes", "bayes_si"})
"""Methods of the Bayesian learner, which may be told of the teacher (`SIRun.told`) and draws its queries
uniformly or by a rule."""

PAIR_METHODS: frozenset[str] = frozenset(METHODS) - {"osi", "pesi", "pesi_ce", "bayes", "bayes_si"}
"""Methods defined on pairs only (N = 2): classifiers of pairs, or losses mixing y and -y."""


def make_learner(cell: SIRun, model: SIModel, seed: int) -> Learner | None:
    """The learner of `cell.method` on a copy of the pretrained model; None for OSI (no updates)."""
    spec = domain_spec(cell.domain)
    tuning = cell.fine_tuning
    common = dict(
        encourage_percentage=tuning.encourage_percentage,
        learning_rate=tuning.learning_rate,
        batch_size=spec.batch_size,
        n_candidates=cell.n_candidates,
        history=cell.data.history,
        candidate_sampling=tuning.candidate_sampling,
        pr_domain=tuning.pr_domain,
        fine_tuned=tuning.fine_tuned,
    )
    return LEARNERS[cell.method](cell, model, common, seed)

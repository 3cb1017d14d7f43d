"""The methods of an SI run by name, and the learner each builds (`make_learner`).

Every method fine-tunes (or, for OSI, keeps) the same pretrained SI model with the same PESI settings,
which `make_learner` reads from the run once; a method's builder adds only what it needs beyond them.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import TYPE_CHECKING

from hipref.experiments.domains import domain_spec
from hipref.learners.answer_models import hypotheses
from hipref.learners.bayes import BayesConfig, BayesLearner
from hipref.learners.coteaching import CoTeaching, reset_every_step_schedule
from hipref.learners.filters import FilterSetting, SmallLoss, TrustFlip
from hipref.learners.noise_estimation import DEFAULT_CONFLICT
from hipref.learners.noise_rate import Algorithm5, FlipRate, Likelihood, Told
from hipref.learners.pesi import PESI_FILTER, TRUSTING, PESIConfig, PESILearner
from hipref.learners.sysid import SIModel

if TYPE_CHECKING:
    from hipref.experiments.si_run import SIRun

Learner = PESILearner | BayesLearner
"""What a method's learner is: PESI (and the learners built on it) or the Bayesian learner."""

LearnerBuilder = Callable[["SIRun", SIModel, PESIConfig, int], "Learner | None"]
"""Builds a method's learner from the cell, the pretrained model, the PESI settings every method shares
(`pesi_config`) and the learner's seed; None for a method that learns nothing."""

MAX_UNBIASED_RATE = 0.4
"""The flip rate the unbiased loss and the small-loss filter use is capped at this, in [0, 0.5): the
unbiased loss divides by 1 - 2 e."""


def _coteaching(cell: SIRun) -> CoTeaching:
    refresh_frequency = domain_spec(cell.domain).refresh_frequency
    if cell.fine_tuning.coteaching_schedule == "learned":
        return CoTeaching(refresh_frequency=refresh_frequency)
    return reset_every_step_schedule(refresh_frequency=refresh_frequency)


def _pesi(
    loss: str = "soft", filter: FilterSetting = PESI_FILTER, flip_rate: FlipRate = TRUSTING
) -> LearnerBuilder:
    """The preference learner with `loss`, `filter` and `flip_rate` on the run's PESI settings."""

    def build(cell: SIRun, model: SIModel, config: PESIConfig, seed: int) -> Learner:
        return PESILearner(model, dataclasses.replace(config, loss=loss), seed, filter, flip_rate)

    return build


def _co_pesi(flip_rate: Callable[[SIRun], FlipRate]) -> LearnerBuilder:
    """CO-PESI: the preference learner with co-teaching (Algorithm 1) and the flip rate `flip_rate(cell)`."""

    def build(cell: SIRun, model: SIModel, config: PESIConfig, seed: int) -> Learner:
        return PESILearner(model, config, seed, _coteaching(cell), flip_rate(cell))

    return build


def _bayes_config(cell: SIRun) -> BayesConfig:
    models = hypotheses(cell.teacher, cell.noise, cell.told)
    return BayesConfig(cell.n_candidates, cell.fine_tuning.pesi.candidate_sampling, models)


LEARNERS: dict[str, LearnerBuilder] = {
    "osi": lambda cell, model, config, seed: None,
    "pesi": _pesi("soft"),
    "pesi_ce": _pesi("standard"),
    "co_pesi": _co_pesi(lambda cell: Told(cell.noise)),
    # A.9: the forget number comes from Algorithm 5 on the preferences so far, not the true noise.
    "co_pesi_estimated": _co_pesi(lambda cell: Algorithm5(DEFAULT_CONFLICT)),
    "co_pesi_estimated_same_pair": _co_pesi(lambda cell: Algorithm5("same_pair")),
    "pesi_smoothed": _pesi("smoothed"),
    "pesi_unbiased": _pesi("unbiased", flip_rate=Likelihood(MAX_UNBIASED_RATE)),
    "pesi_small_loss": _pesi(filter=SmallLoss(), flip_rate=Likelihood(MAX_UNBIASED_RATE)),
    "pesi_rime": _pesi(filter=TrustFlip()),
    "co_pesi_likelihood": _co_pesi(lambda cell: Likelihood()),
    "bayes": lambda cell, model, config, seed: BayesLearner(
        model.candidates, _bayes_config(cell), seed, si_model=model
    ),
    "bayes_si": lambda cell, model, config, seed: BayesLearner(
        model.candidates, dataclasses.replace(_bayes_config(cell), prior="si"), seed, si_model=model
    ),
}
"""Every method by name. osi: pretrained, no preferences; pesi: Eq. 2/3; pesi_ce: standard cross-entropy
(A.8); co_pesi: Algorithm 1 told the true noise level; co_pesi_estimated: Algorithm 1 with the noise level
estimated by Algorithm 5 from the preferences so far (A.9), a conflict read as 'no parameter satisfies
both'; co_pesi_estimated_same_pair: the same with a conflict read as opposite answers to the same pair.
Beyond the paper (`hipref.learners.losses`, `hipref.learners.filters`): pesi_smoothed: label smoothing of
Eq. 2 (conservative); pesi_unbiased: the unbiased loss with the estimated flip rate; pesi_small_loss: SI's
own small-loss filter; pesi_rime: RIME's trust-and-flip; co_pesi_likelihood: Algorithm 1 with the maximum
marginal likelihood flip rate; bayes: the exact posterior over phi from every answer
(`hipref.learners.bayes`), its model of the teacher chosen by marginal likelihood unless told; bayes_si:
that posterior times SI's Pr(phi | tau) on the slice estimated from, so OSI's knowledge is kept."""

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


def pesi_config(cell: SIRun) -> PESIConfig:
    """The PESI settings of the run's learner: the run's fine-tuning on the domain's batch size (also s,
    where filters and flip-rate estimates start) and the data's slice length h."""
    spec = domain_spec(cell.domain)
    return dataclasses.replace(
        cell.fine_tuning.pesi,
        batch_size=spec.batch_size,
        start_size=spec.batch_size,
        n_candidates=cell.n_candidates,
        history=cell.data.history,
    )


def make_learner(cell: SIRun, model: SIModel, seed: int) -> Learner | None:
    """The learner of `cell.method` on a copy of the pretrained model; None for OSI (no updates)."""
    return LEARNERS[cell.method](cell, model, pesi_config(cell), seed)

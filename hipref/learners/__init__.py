"""Learners: tabular COACH for the high level; SI pretraining, PESI, CO-PESI and noise estimation below it."""

from hipref.learners.coach import CoachConfig, TabularCoach
from hipref.learners.coteaching import CoPESIConfig, CoPESILearner
from hipref.learners.coteaching_pair import CoTeachingPair, coteach_select
from hipref.learners.noise_estimation import (
    PreferenceSet,
    conflict_counts,
    estimate_noise,
)
from hipref.learners.pesi import SI_LOSSES, PESIConfig, PESILearner, pesi_loss, pesi_loss_n, standard_ce_loss
from hipref.learners.sysid import (
    CUBE_MASS,
    DESK_HEIGHT,
    CandidateSet,
    Normaliser,
    PretrainConfig,
    SIModel,
    pretrain,
)

__all__ = [
    "CUBE_MASS",
    "DESK_HEIGHT",
    "SI_LOSSES",
    "CandidateSet",
    "CoPESIConfig",
    "CoPESILearner",
    "CoTeachingPair",
    "CoachConfig",
    "Normaliser",
    "PESIConfig",
    "PESILearner",
    "PreferenceSet",
    "PretrainConfig",
    "SIModel",
    "TabularCoach",
    "conflict_counts",
    "coteach_select",
    "estimate_noise",
    "pesi_loss",
    "pesi_loss_n",
    "pretrain",
    "standard_ce_loss",
]

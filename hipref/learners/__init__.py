"""Learners: tabular COACH for the high level; SI pretraining, the preference learner (PESI, its losses,
filters such as CO-PESI's co-teaching, and flip-rate sources) and noise estimation below it."""

from hipref.learners.coach import CoachConfig, TabularCoach
from hipref.learners.coteaching import CoTeaching
from hipref.learners.coteaching_pair import CoTeachingPair, coteach_select
from hipref.learners.filters import SmallLoss, TrustFlip, Unfiltered
from hipref.learners.losses import SI_LOSSES, pesi_loss, pesi_loss_n, standard_ce_loss
from hipref.learners.noise_estimation import (
    PreferenceSet,
    conflict_counts,
    estimate_noise,
)
from hipref.learners.noise_rate import Algorithm5, Likelihood, Told
from hipref.learners.pesi import PESIConfig, PESILearner
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
    "Algorithm5",
    "CandidateSet",
    "CoTeaching",
    "CoTeachingPair",
    "CoachConfig",
    "Likelihood",
    "Normaliser",
    "PESIConfig",
    "PESILearner",
    "PreferenceSet",
    "PretrainConfig",
    "SIModel",
    "SmallLoss",
    "TabularCoach",
    "Told",
    "TrustFlip",
    "Unfiltered",
    "conflict_counts",
    "coteach_select",
    "estimate_noise",
    "pesi_loss",
    "pesi_loss_n",
    "pretrain",
    "standard_ce_loss",
]

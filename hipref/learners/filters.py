"""Filters of flipped preferences: what of each minibatch SI's update sees (Algorithm 2's "update SI").

A preference learner (`hipref.learners.pesi.PESILearner`) hands each received preference's learning to
its filter, with the flip rate e of the moment (`hipref.learners.noise_rate`). A filter is given as a frozen
setting (`Unfiltered`, `SmallLoss`, `TrustFlip`, or co-teaching, `hipref.learners.coteaching.CoTeaching`)
whose `start` builds the running filter of one learner. Every running filter reports its precision and
recall against the teacher's recorded flips through `precision_recall` (None when it filters nothing),
counted by `filter_quality` on its `UpdateLog`.

While |D| <= s (`PESIConfig.start_size`) the filters update SI as PESI does, on an unfiltered batch, like
CO-PESI's s; the estimate of e, where one is used, only starts then too.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Annotated, NamedTuple, Protocol

import numpy as np
import torch

from hipref.learners.coteaching_pair import coteach_select
from hipref.learners.losses import preference_nll
from hipref.learners.sysid import SIModel
from hipref.validation import Range, check_fields, check_range


class SILearner(Protocol):
    """What a filter uses of its learner: the buffer D, minibatches from it and SI's update."""

    model: SIModel

    def __len__(self) -> int: ...

    @property
    def start_size(self) -> int: ...

    def sample_batch(self) -> np.ndarray: ...

    def batch_tensors(self, batch: np.ndarray) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]: ...

    def queried(self, batch: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]: ...

    def si_step(self, queried: torch.Tensor, labels: torch.Tensor, rate: float) -> float: ...

    def update_si(self, batch: np.ndarray, rate: float) -> float: ...

    def next_seed(self) -> int: ...


class SIUpdateRecord(NamedTuple):
    """One SI update's minibatch and what the filter withheld from it, as indices into the buffer D."""

    batch: np.ndarray
    """The buffer entries of the batch b the filter selected from."""
    forgotten: np.ndarray
    """The entries of b not used as told (not shown to SI, or shown flipped); empty before the filter
    starts."""


def filter_quality(
    si_updates: Sequence[SIUpdateRecord], flipped: Sequence[bool] | np.ndarray, size: int
) -> tuple[float, float]:
    """A filter's precision and recall against the teacher's flips, over the SI updates `si_updates` of a
    buffer D of `size` preferences.

    flipped[i] says whether the teacher flipped the i-th preference of D (a scripted teacher knows; the
    learner never uses it). The counting unit is one (SI update, buffer entry) occurrence: an entry that
    sits in the batches of k updates counts k times, and an entry forgotten by k of them counts k times as
    forgotten. With F the forgotten occurrences and B the batch occurrences,

        precision = |flipped occurrences in F| / |F|,
        recall    = |flipped occurrences in F| / |flipped occurrences in B|.

    Updates before the filter starts (CO-PESI's `update_before_start`) forget nothing and count in B, so
    recall measures how many of the flipped labels SI was offered the filter kept from it. Either is NaN
    when its denominator is 0 (nothing forgotten; no flipped entry in any batch).
    """
    flags = np.asarray(flipped)
    if flags.shape != (size,):
        raise ValueError(f"flipped must hold one flag per preference in D ({size}), got shape {flags.shape}")
    if flags.dtype != np.bool_:
        if not np.isin(flags, (0, 1)).all():
            raise ValueError(f"flipped must hold booleans, got values {np.unique(flags).tolist()!r}")
        flags = flags.astype(bool)
    forgotten = sum(len(r.forgotten) for r in si_updates)
    flipped_forgotten = sum(int(flags[r.forgotten].sum()) for r in si_updates)
    flipped_offered = sum(int(flags[r.batch].sum()) for r in si_updates)
    precision = flipped_forgotten / forgotten if forgotten else math.nan
    recall = flipped_forgotten / flipped_offered if flipped_offered else math.nan
    return precision, recall


class Filter(Protocol):
    """A running filter of one learner."""

    def learn(self, rate: float) -> None:
        """One received preference's learning: SI's update(s) on what the filter keeps, at flip rate e."""
        ...

    def precision_recall(self, flipped: Sequence[bool] | np.ndarray) -> tuple[float, float] | None:
        """Its precision and recall against the teacher's record `flipped` (`filter_quality`); None when
        it filters nothing."""
        ...


class FilterSetting(Protocol):
    """A filter as a learner's setting: frozen, and `start` builds the running filter of `learner`."""

    @property
    def pairs_only(self) -> bool:
        """Whether the filter reads pairs only (N = 2)."""
        ...

    def start(self, learner: SILearner) -> Filter: ...


@dataclass
class UpdateLog:
    """Every SI update's batch and forgotten entries, for the filter's precision and recall."""

    learner: SILearner
    si_updates: list[SIUpdateRecord] = field(default_factory=list)

    def record(self, batch: np.ndarray, forgotten: np.ndarray) -> None:
        self.si_updates.append(SIUpdateRecord(np.array(batch), np.array(forgotten)))

    def warm_up(self, batch: np.ndarray, rate: float) -> bool:
        """While |D| <= s: one unfiltered update on `batch`, recorded as forgetting nothing; whether it was
        made (the filter starts once D is larger)."""
        if len(self.learner) > self.learner.start_size:
            return False
        self.record(batch, batch[:0])
        self.learner.update_si(batch, rate)
        return True

    def precision_recall(self, flipped: Sequence[bool] | np.ndarray) -> tuple[float, float] | None:
        return filter_quality(self.si_updates, flipped, len(self.learner))


@dataclass(frozen=True)
class Unfiltered:
    """No filter: every SI update sees its whole minibatch (PESI, Algorithm 2; the robust losses)."""

    pairs_only = False

    def start(self, learner: SILearner) -> Filter:
        return _Unfiltered(learner)


class _Unfiltered:
    def __init__(self, learner: SILearner) -> None:
        self.learner = learner

    def learn(self, rate: float) -> None:
        # Alg. 2 'update SI by Eqn. 2', here on a minibatch from D so one answer is not all a step sees.
        self.learner.update_si(self.learner.sample_batch(), rate)

    def precision_recall(self, flipped: Sequence[bool] | np.ndarray) -> tuple[float, float] | None:
        return None


@dataclass(frozen=True)
class NoUpdate:
    """No SI update at all: the learner only asks and stores the answers in D (a buffer of the runs'
    queries and answers, for studies of the answers alone)."""

    pairs_only = False

    def start(self, learner: SILearner) -> Filter:
        return _NoUpdate()


class _NoUpdate:
    def learn(self, rate: float) -> None:
        pass

    def precision_recall(self, flipped: Sequence[bool] | np.ndarray) -> tuple[float, float] | None:
        return None


@dataclass(frozen=True)
class SmallLoss:
    """pesi_small_loss: one network's small-loss filter (the single-network baseline of co-teaching, Han et
    al. 2018; Jiang et al. 2018): each SI update forgets the n_forget = round(e B) preferences of its batch
    with the largest loss -log Pr(preferred) under SI itself (`preference_nll`). No peer: SI selects its
    own data, so what it already believes wrongly it keeps believing; co-teaching's second network exists
    to break that loop."""

    pairs_only = True

    def start(self, learner: SILearner) -> Filter:
        return _SmallLoss(learner)


class _SmallLoss(UpdateLog):
    def learn(self, rate: float) -> None:
        batch = self.learner.sample_batch()
        if self.warm_up(batch, rate):
            return
        forget = min(math.floor(rate * len(batch) + 0.5), len(batch) - 1)
        with torch.no_grad():
            queried, labels = self.learner.queried(batch)
            losses = preference_nll(queried, labels[:, 0])
        kept, _ = coteach_select(losses, losses, forget)
        self.record(batch, np.setdiff1d(batch, batch[kept]))
        self.learner.update_si(batch[kept], rate)


@dataclass(frozen=True)
class TrustFlip:
    """pesi_rime: RIME's sample selection (Cheng et al. 2024, 'RIME: Robust Preference-based RL with Noisy
    Preferences') on SI, the model the preferences train, as RIME's reward model.

    Per SI update, with l_i = -log Pr(preferred_i) under SI (`preference_nll`): trusted if
    l_i < tau_lower = -ln(rho) + beta_t std(l) (beta_t decaying linearly from beta_start to beta_end over
    filtered updates), flipped (used as -y) if l_i > tau_upper = -ln(flip_probability), and left out
    otherwise. SI is updated on the trusted and the flipped. The filter's record counts every preference
    not used as told (left out or flipped) as forgotten. RIME's warm start is the pretrained SI; the
    thresholds' values are ours."""

    trust_probability: Annotated[float, Range(1e-9, 1.0)] = 0.5
    """rho; a preference is trusted when its loss -log Pr(preferred) is below -ln(rho) + beta_t * std(batch
    losses): SI gives the label at least rho, before the uncertainty term."""
    trust_spread_start: Annotated[float, Range(0.0, math.inf)] = 3.0
    """beta_t at the first filtered update (RIME: beta_max = 3)."""
    trust_spread_end: float = 1.0
    """The floor of beta_t (RIME: beta_min = 1)."""
    trust_spread_decay: Annotated[float, Range(0.0, math.inf)] = 1.0 / 30.0
    """beta_t = max(beta_end, beta_start - decay * t), t counting filtered updates."""
    flip_probability: float = 0.05
    """A label is flipped (used as -y) when SI gives it less than this probability, i.e. its loss exceeds
    -ln(flip_probability)."""
    pairs_only = True

    def __post_init__(self) -> None:
        check_fields(self)
        check_range("trust_spread_end", self.trust_spread_end, 0.0, self.trust_spread_start)
        check_range("flip_probability", self.flip_probability, 1e-9, self.trust_probability)

    def start(self, learner: SILearner) -> Filter:
        return TrustFlipFilter(learner, self)


class TrustFlipFilter(UpdateLog):
    """The running trust-and-flip filter of one learner (`TrustFlip`)."""

    def __init__(self, learner: SILearner, setting: TrustFlip) -> None:
        super().__init__(learner)
        self.setting = setting
        self.filtered_updates = 0
        self.flips = 0

    def trust_threshold(self, losses: torch.Tensor) -> float:
        """tau_lower for a batch's losses at the current filtered update."""
        c = self.setting
        spread = max(c.trust_spread_end, c.trust_spread_start - c.trust_spread_decay * self.filtered_updates)
        deviation = float(losses.std()) if losses.numel() > 1 else 0.0
        return -math.log(c.trust_probability) + spread * deviation

    def learn(self, rate: float) -> None:
        batch = self.learner.sample_batch()
        if self.warm_up(batch, rate):
            return
        queried, labels = self.learner.queried(batch)
        losses = preference_nll(queried.detach(), labels[:, 0])
        trusted = losses < self.trust_threshold(losses)
        flipped = losses > -math.log(self.setting.flip_probability)
        used = trusted | flipped
        self.filtered_updates += 1
        self.flips += int(flipped.sum())
        self.record(batch, batch[~(trusted & ~flipped).numpy()])
        if not bool(used.any()):
            return
        told = torch.where(flipped.unsqueeze(1), -labels, labels)
        self.learner.si_step(queried[used], told[used], rate)

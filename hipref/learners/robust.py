"""PESI learners robust to noisy preferences, beside co-teaching: a robust loss, an unbiased loss, a
small-loss filter and trust-and-flip, all on Eq. 2 and the same ask/tell as PESILearner.

What Eq. 2 does to a robust loss. With Pr over the queried pair (`log_probs`, 'query') and the weights
Pr + p y detached, Eq. 2's gradient on the pair's logits is (-p y, p y): linear in y. Any loss that mixes
L(y) and L(-y) with fixed weights therefore only rescales the step:

- label smoothing / conservative DPO, (1 - eps) L(y) + eps L(-y), is Eq. 2 with p (1 - 2 eps);
- the unbiased loss of robust DPO, [(1 - e) L(y) - e L(-y)] / (1 - 2 e), is Eq. 2 with p / (1 - 2 e).

Both keep the sign of every update, so neither can undo a flipped label: the first takes smaller steps, the
second larger ones, and what they change is how far a run of flipped labels moves SI. The filters
(`SmallLossPESILearner`, `TrustFlipPESILearner`) decide per preference and can.

The flip rate e, where a learner needs one, is the maximum marginal likelihood estimate
(`hipref.learners.noise_rate.likelihood_noise`) on the buffer D so far, as A.9's CO-PESI uses Algorithm 5.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch

from hipref.learners.coteaching import (
    EstimatedNoiseCoPESILearner,
    SIUpdateRecord,
    filter_quality,
)
from hipref.learners.coteaching_pair import coteach_select
from hipref.learners.noise_rate import likelihood_noise
from hipref.learners.pesi import PESIConfig, PESILearner, log_probs, pesi_loss
from hipref.learners.sysid import SIModel
from hipref.validation import check_int, check_range


def conservative_pesi_loss(
    log_probs_pair: torch.Tensor, y: torch.Tensor, encourage_percentage: float, smoothing: float
) -> torch.Tensor:
    """Label smoothing of Eq. 2's target (conservative DPO, Mitchell 2023; Szegedy et al. 2016):

        L_eps(y) = (1 - eps) L(y) + eps L(-y),

    L being Eq. 2 (`pesi_loss`): the label is trusted with probability 1 - eps. Its gradient is Eq. 2's
    times (1 - 2 eps) (module docstring)."""
    check_range("smoothing", smoothing, 0.0, 0.5)
    return (1.0 - smoothing) * pesi_loss(log_probs_pair, y, encourage_percentage) + smoothing * pesi_loss(
        log_probs_pair, -y, encourage_percentage
    )


def unbiased_pesi_loss(
    log_probs_pair: torch.Tensor, y: torch.Tensor, encourage_percentage: float, rate: float
) -> torch.Tensor:
    """The unbiased loss under flips of rate e (Natarajan et al. 2013; robust DPO, Chowdhury et al. 2024):

        L~(y) = [(1 - e) L(y) - e L(-y)] / (1 - 2 e),

    L being Eq. 2. Its expectation over a label flipped with probability e is the clean loss:
    (1 - e) L~(y) + e L~(-y) = L(y). Needs e < 1/2."""
    check_range("rate", rate, 0.0, 0.5 - 1e-9)
    clean = pesi_loss(log_probs_pair, y, encourage_percentage)
    reversed_ = pesi_loss(log_probs_pair, -y, encourage_percentage)
    return ((1.0 - rate) * clean - rate * reversed_) / (1.0 - 2.0 * rate)


def preference_nll(log_probs_pair: torch.Tensor, y: torch.Tensor) -> torch.Tensor:
    """Per preference, -log Pr(preferred candidate) under SI's Pr over the pair (Bradley-Terry): large when
    the label contradicts what SI believes. The loss the filters rank by."""
    preferred = (y < 0).long().unsqueeze(1)  # y = 1 -> phi_0, y = -1 -> phi_1
    return -log_probs_pair.gather(1, preferred).squeeze(1)


def estimated_flip_rate(learner: PESILearner, cap: float = 0.5) -> float:
    """The maximum marginal likelihood flip rate of the learner's buffer D, at most `cap`."""
    phi = learner.candidates
    return min(cap, likelihood_noise(learner.buffer_preferences(), phi.low, phi.high))


@dataclass(frozen=True)
class RobustPESIConfig(PESIConfig):
    """PESI's settings plus those of the robust learners; each field names the learner that reads it."""

    smoothing: float = 0.1
    """LabelSmoothingPESILearner: eps, the weight of the reversed label, in [0, 0.5) (conservative DPO
    commonly uses 0.1)."""
    start_size: int = 16
    """Estimated-rate learners and filters: they estimate e and filter once |D| > start_size; before that
    they update as PESI does (like CO-PESI's s)."""
    max_rate: float = 0.4
    """UnbiasedPESILearner, SmallLossPESILearner: the estimated rate is capped at this, in [0, 0.5): the
    unbiased loss divides by 1 - 2 e."""
    trust_probability: float = 0.5
    """TrustFlipPESILearner: rho; a preference is trusted when its loss -log Pr(preferred) is below
    -ln(rho) + beta_t * std(batch losses): SI gives the label at least rho, before the uncertainty term."""
    trust_spread_start: float = 3.0
    """TrustFlipPESILearner: beta_t at the first filtered update (RIME: beta_max = 3)."""
    trust_spread_end: float = 1.0
    """TrustFlipPESILearner: the floor of beta_t (RIME: beta_min = 1)."""
    trust_spread_decay: float = 1.0 / 30.0
    """TrustFlipPESILearner: beta_t = max(beta_end, beta_start - decay * t), t counting filtered updates."""
    flip_probability: float = 0.05
    """TrustFlipPESILearner: a label is flipped (used as -y) when SI gives it less than this probability,
    i.e. its loss exceeds -ln(flip_probability)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.n_candidates != 2:
            raise ValueError(
                f"n_candidates must be 2 for the robust learners (Eq. 2), got {self.n_candidates}"
            )
        check_range("smoothing", self.smoothing, 0.0, 0.5 - 1e-9)
        check_int("start_size", self.start_size, 0)
        check_range("max_rate", self.max_rate, 0.0, 0.5 - 1e-9)
        check_range("trust_probability", self.trust_probability, 1e-9, 1.0)
        check_range("trust_spread_start", self.trust_spread_start, 0.0, math.inf)
        check_range("trust_spread_end", self.trust_spread_end, 0.0, self.trust_spread_start)
        check_range("trust_spread_decay", self.trust_spread_decay, 0.0, math.inf)
        check_range("flip_probability", self.flip_probability, 1e-9, self.trust_probability)


class _RobustLearner(PESILearner):
    """A PESILearner with a RobustPESIConfig, a record of its estimated rates and of its filter."""

    def __init__(self, model: SIModel, config: RobustPESIConfig | None = None, seed: int = 0) -> None:
        config = config if config is not None else RobustPESIConfig()
        if not isinstance(config, RobustPESIConfig):
            raise ValueError(f"config must be a RobustPESIConfig, got {type(config).__name__}")
        super().__init__(model, config, seed)
        self.config: RobustPESIConfig = config
        self.noise_history: list[float] = []
        self.si_updates: list[SIUpdateRecord] = []

    def _pair_tensors(self, batch: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        """SI's log Pr over each queried pair (B, 2) and the labels y (B,) of buffer entries `batch`."""
        features, indices, labels = self._batch_tensors(batch)
        return log_probs(self.model(features), indices, self.config.pr_domain), labels[:, 0]

    def _step(self, loss: torch.Tensor) -> float:
        self.optimiser.zero_grad()
        loss.backward()
        self.optimiser.step()
        return loss.item()

    def _warm_up(self, batch: np.ndarray) -> bool:
        """While |D| <= start_size: one unfiltered Eq. 2 update on `batch`, recorded as forgetting nothing;
        whether it was made (a filter starts once D is larger)."""
        if len(self) > self.config.start_size:
            return False
        self.si_updates.append(SIUpdateRecord(batch, batch[:0]))
        self._update_si(batch)
        return True

    def _estimate(self) -> float:
        rate = estimated_flip_rate(self, self.config.max_rate)
        self.noise_history.append(rate)
        return rate

    def filter_precision_recall(self, flipped: Sequence[bool] | np.ndarray) -> tuple[float, float]:
        """The filter's score against the teacher's record, counted as CO-PESI's (`filter_quality`;
        forgotten = not used as told)."""
        return filter_quality(self.si_updates, flipped, len(self))


class LabelSmoothingPESILearner(_RobustLearner):
    """pesi_smoothed: Eq. 2 with a smoothed label, (1 - eps) L(y) + eps L(-y) (`conservative_pesi_loss`;
    conservative DPO, Mitchell 2023). eps is fixed (`RobustPESIConfig.smoothing`), not estimated."""

    def _update_si(self, batch: np.ndarray) -> float:
        pair, y = self._pair_tensors(batch)
        return self._step(
            conservative_pesi_loss(pair, y, self.config.encourage_percentage, self.config.smoothing)
        )


class UnbiasedPESILearner(_RobustLearner):
    """pesi_unbiased: Eq. 2 replaced by its unbiased version under flips of rate e (`unbiased_pesi_loss`;
    Natarajan et al. 2013, robust DPO of Chowdhury et al. 2024), e estimated by maximum marginal
    likelihood on D before every update once |D| > s (0 before), capped at `max_rate`."""

    def _learn(self) -> None:
        rate = self._estimate() if len(self) > self.config.start_size else 0.0
        batch = self._sample_batch()
        pair, y = self._pair_tensors(batch)
        self._step(unbiased_pesi_loss(pair, y, self.config.encourage_percentage, rate))


class SmallLossPESILearner(_RobustLearner):
    """pesi_small_loss: one network's small-loss filter (the single-network baseline of co-teaching, Han et
    al. 2018; Jiang et al. 2018): each SI update forgets the n_forget = round(e B) preferences of its batch
    with the largest loss -log Pr(preferred) under SI itself (`preference_nll`), e estimated by maximum
    marginal likelihood on D. No peer: SI selects its own data, so what it already believes wrongly it keeps
    believing; co-teaching's second network exists to break that loop."""

    def _learn(self) -> None:
        batch = self._sample_batch()
        if self._warm_up(batch):
            return
        forget = min(math.floor(self._estimate() * len(batch) + 0.5), len(batch) - 1)
        with torch.no_grad():
            losses = preference_nll(*self._pair_tensors(batch))
        kept, _ = coteach_select(losses, losses, forget)
        self.si_updates.append(SIUpdateRecord(batch, np.setdiff1d(batch, batch[kept])))
        self._update_si(batch[kept])


class TrustFlipPESILearner(_RobustLearner):
    """pesi_rime: RIME's sample selection (Cheng et al. 2024, 'RIME: Robust Preference-based RL with Noisy
    Preferences') on SI, the model the preferences train, as RIME's reward model.

    Per SI update, with l_i = -log Pr(preferred_i) under SI (`preference_nll`):
    trusted if l_i < tau_lower = -ln(rho) + beta_t std(l) (beta_t decaying linearly from beta_start to
    beta_end over filtered updates), flipped (used as -y) if l_i > tau_upper = -ln(flip_probability), and
    left out otherwise. SI is updated by Eq. 2 on the trusted and the flipped. The filter's record counts
    every preference not used as told (left out or flipped) as forgotten. RIME's warm start is the
    pretrained SI; the thresholds' values are ours (`RobustPESIConfig`)."""

    def __init__(self, model: SIModel, config: RobustPESIConfig | None = None, seed: int = 0) -> None:
        super().__init__(model, config, seed)
        self.filtered_updates = 0
        self.flips = 0

    def trust_threshold(self, losses: torch.Tensor) -> float:
        """tau_lower for a batch's losses at the current filtered update."""
        c = self.config
        spread = max(c.trust_spread_end, c.trust_spread_start - c.trust_spread_decay * self.filtered_updates)
        deviation = float(losses.std()) if losses.numel() > 1 else 0.0
        return -math.log(c.trust_probability) + spread * deviation

    def _learn(self) -> None:
        batch = self._sample_batch()
        if self._warm_up(batch):
            return
        pair, y = self._pair_tensors(batch)
        losses = preference_nll(pair.detach(), y)
        trusted = losses < self.trust_threshold(losses)
        flipped = losses > -math.log(self.config.flip_probability)
        used = trusted | flipped
        self.filtered_updates += 1
        self.flips += int(flipped.sum())
        self.si_updates.append(SIUpdateRecord(batch, batch[~(trusted & ~flipped).numpy()]))
        if not bool(used.any()):
            return
        labels = torch.where(flipped, -y, y)
        self._step(pesi_loss(pair[used], labels[used], self.config.encourage_percentage))  # Eq. 2


class LikelihoodNoiseCoPESILearner(EstimatedNoiseCoPESILearner):
    """co_pesi_likelihood: CO-PESI (Algorithm 1) whose noise level, hence forget rate, is the maximum
    marginal likelihood flip rate of D (`likelihood_noise`) instead of Algorithm 5's estimate; re-estimated
    at the same moments as co_pesi_estimated's (A.9), before each co-teaching preference."""

    def estimated_noise_level(self) -> float:
        """The noise level of D: its maximum marginal likelihood flip rate (`estimated_flip_rate`)."""
        return estimated_flip_rate(self)

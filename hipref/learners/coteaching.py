"""CO-PESI: PESI whose SI updates see only the preferences two co-teaching classifiers trust (Algorithm 1).

Co-teaching (Han et al. 2018): two networks each rank a minibatch by their own loss and keep the
small-loss part; each is trained on the part its peer kept, so one network's memorised noise is not fed
back to itself. Networks learn the clean, consistent pattern before they memorise the noise, so a
small loss is evidence of a clean label.

The classifiers predict the preference from the candidate pair alone. That suffices because during one
run the environment, and so the true parameter, is fixed: a clean label is then a function of the pair
(y = 1 iff phi_0 is nearer the truth), and a label that disagrees with what the rest of the buffer
implies is a likely flip.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from hipref.learners.noise_estimation import PreferenceSet, estimate_noise
from hipref.learners.pesi import PESIConfig, PESILearner
from hipref.learners.sysid import SIModel
from hipref.validation import check_int, check_range


@dataclass(frozen=True)
class CoPESIConfig(PESIConfig):
    """Algorithm 1 on top of PESI's settings (Table 2 for desk height; cube mass uses 32 for
    batch_size, refresh_frequency and start_size)."""

    classifier_learning_rate: float = 1e-2
    """Adam step size of the co-teaching classifiers M_0, M_1 (Table 2)."""
    classifier_hidden_sizes: tuple[int, ...] = (64, 64)
    """Hidden layer widths of M_0 and M_1, ReLU activations (Table 2)."""
    start_size: int = 16
    """s: co-teaching and SI updates begin once |D| > s (Alg. 1 l.5). Not given in the paper; by default
    a full batch must be available."""
    refresh_frequency: int = 16
    """f_refresh: M_0 and M_1 are re-initialised every this many co-teaching steps (Alg. 1 l.6-7; Table 2:
    16 for height, 32 for mass), so they never run long enough to memorise the noise."""
    ramp_steps: int = 10
    """Co-teaching steps over which the forget rate rises linearly from 0 to its final value. The paper is
    silent; Han et al. ramp it over their first 10 epochs, because networks fit clean data first and
    early losses say little. Counted from the first co-teaching step and not restarted at a refresh (a
    restart would keep the forget rate low for most of each short refresh period). 0 forgets the full
    amount from the first step."""
    rounds: int = 1
    """t: co-teaching rounds (Alg. 1 l.9-14: sample, select, cross-update, update SI) per preference."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.n_candidates != 2:
            raise ValueError(
                f"n_candidates must be 2 for CO-PESI (pair classifiers), got {self.n_candidates}"
            )
        check_range("classifier_learning_rate", self.classifier_learning_rate, 1e-8, 1.0)
        if not self.classifier_hidden_sizes or not all(
            isinstance(h, int) and h >= 1 for h in self.classifier_hidden_sizes
        ):
            raise ValueError(
                f"classifier_hidden_sizes must be a non-empty tuple of positive integers, "
                f"got {self.classifier_hidden_sizes!r}"
            )
        check_int("start_size", self.start_size, 0)
        check_int("refresh_frequency", self.refresh_frequency, 1)
        check_int("ramp_steps", self.ramp_steps, 0)
        check_int("rounds", self.rounds, 1)


def coteach_select(
    loss0: np.ndarray | torch.Tensor, loss1: np.ndarray | torch.Tensor, forget_number: int
) -> tuple[np.ndarray, np.ndarray]:
    """Alg. 1 l.10-11: each classifier keeps the batch - forget_number samples of smallest loss.

    Returns (b0, b1), indices into the batch selected by M_0 and by M_1, ordered by increasing loss (a
    stable sort, so equal losses keep batch order).
    """
    loss0, loss1 = (np.asarray(torch.as_tensor(loss).detach().cpu()) for loss in (loss0, loss1))
    if loss0.shape != loss1.shape or loss0.ndim != 1:
        raise ValueError(f"loss0 and loss1 must be 1-d of equal length, got {loss0.shape} and {loss1.shape}")
    check_int("forget_number", forget_number, 0, len(loss0) - 1)
    keep = len(loss0) - forget_number
    return np.argsort(loss0, kind="stable")[:keep], np.argsort(loss1, kind="stable")[:keep]


def _classifier(hidden_sizes: tuple[int, ...]) -> nn.Sequential:
    """M: normalised (phi_0, phi_1) -> 2 logits, class 0 for y = 1 and class 1 for y = -1."""
    layers: list[nn.Module] = []
    width = 2
    for hidden in hidden_sizes:
        layers += [nn.Linear(width, hidden), nn.ReLU()]
        width = hidden
    layers.append(nn.Linear(width, 2))
    return nn.Sequential(*layers)


class CoTeachingPair:
    """The classifiers M_0, M_1 with their optimisers, and one co-teaching step (Alg. 1 l.10-13)."""

    def __init__(self, hidden_sizes: tuple[int, ...], learning_rate: float, seed: int) -> None:
        self.hidden_sizes = hidden_sizes
        self.learning_rate = learning_rate
        self.reinitialise(seed)

    def reinitialise(self, seed: int) -> None:
        """Alg. 1 l.7: fresh random weights (and fresh optimiser state) for both classifiers."""
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            self.models = (_classifier(self.hidden_sizes), _classifier(self.hidden_sizes))
        self.optimisers = tuple(torch.optim.Adam(m.parameters(), lr=self.learning_rate) for m in self.models)

    @torch.no_grad()
    def losses(self, pairs: torch.Tensor, targets: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Per-sample cross-entropy of M_0 and of M_1 on a batch."""
        m0, m1 = self.models
        return (
            nn.functional.cross_entropy(m0(pairs), targets, reduction="none"),
            nn.functional.cross_entropy(m1(pairs), targets, reduction="none"),
        )

    def train_on(self, which: int, pairs: torch.Tensor, targets: torch.Tensor) -> None:
        """One Adam step of classifier `which` on the given samples."""
        loss = nn.functional.cross_entropy(self.models[which](pairs), targets)
        self.optimisers[which].zero_grad()
        loss.backward()
        self.optimisers[which].step()

    def step(
        self, pairs: torch.Tensor, targets: torch.Tensor, forget_number: int
    ) -> tuple[np.ndarray, np.ndarray]:
        """Select by each classifier's loss, then train each on its peer's selection; returns (b0, b1)."""
        # Alg. 1 l.10-11: small-loss selection, forgetting forget_number samples each
        loss0, loss1 = self.losses(pairs, targets)
        b0, b1 = coteach_select(loss0, loss1, forget_number)
        # Alg. 1 l.12-13: cross update, M_0 learns from M_1's selection and M_1 from M_0's
        self.train_on(0, pairs[b1], targets[b1])
        self.train_on(1, pairs[b0], targets[b0])
        return b0, b1


class CoPESILearner(PESILearner):
    """Algorithm 1 through the same ask/tell/estimate as PESILearner; only the learning step differs.

    `noise_level` is the fraction of flipped preferences assumed: the true one, or an estimate (A.9) for
    co_pesi_estimated. Following A.7 the remember rate is 1 - noise_level, so the final forget rate is
    noise_level and n_forget = round(forget_rate * batch).
    """

    def __init__(
        self, model: SIModel, noise_level: float, config: CoPESIConfig | None = None, seed: int = 0
    ) -> None:
        config = config if config is not None else CoPESIConfig()
        if not isinstance(config, CoPESIConfig):
            raise ValueError(f"config must be a CoPESIConfig, got {type(config).__name__}")
        check_range("noise_level", noise_level, 0.0, 1.0)
        super().__init__(model, config, seed)
        self.config: CoPESIConfig = config
        self.noise_level = float(noise_level)
        self.coteaching_steps = 0
        self.pair = CoTeachingPair(
            config.classifier_hidden_sizes, config.classifier_learning_rate, self._next_seed()
        )
        # Buffer indices of the most recent b_0, kept for inspection.
        self.last_selection: np.ndarray | None = None

    @property
    def remember_rate(self) -> float:
        """Fraction of each batch kept once the ramp is over (A.7: 1 - noise level)."""
        return 1.0 - self.noise_level

    def _next_seed(self) -> int:
        return int(self._torch_seeds.spawn(1)[0].generate_state(1)[0])

    def forget_rate(self, step: int) -> float:
        """Han et al.'s schedule: a linear ramp from 0 to 1 - remember_rate over `ramp_steps` steps."""
        ramp = 1.0 if self.config.ramp_steps == 0 else min(1.0, step / self.config.ramp_steps)
        return (1.0 - self.remember_rate) * ramp

    def forget_number(self, step: int, batch_size: int) -> int:
        """n_forget for a batch, rounded half up, and always leaving at least one sample to learn from."""
        return min(math.floor(self.forget_rate(step) * batch_size + 0.5), batch_size - 1)

    def _learn(self) -> None:
        # Alg. 1 l.5: nothing is learnt until the buffer holds more than s preferences.
        if len(self) <= self.config.start_size:
            return
        # Alg. 1 l.6-7: refresh the classifiers every f_refresh steps (they start fresh at step 0).
        if self.coteaching_steps > 0 and self.coteaching_steps % self.config.refresh_frequency == 0:
            self.pair.reinitialise(self._next_seed())
        for _ in range(self.config.rounds):
            # Alg. 1 l.9: sample batch b from D
            batch = self._sample_batch()
            _, indices, labels = self._batch_tensors(batch)
            pairs = self.model.normalised_values[indices]
            targets = (labels[:, 0] < 0).long()  # y = 1 -> class 0, y = -1 -> class 1
            # Alg. 1 l.10-13: select b_0, b_1 and cross-update M_0, M_1
            n_forget = self.forget_number(self.coteaching_steps, len(batch))
            b0, _ = self.pair.step(pairs, targets, n_forget)
            # Alg. 1 l.14: update SI by Eq. 2 on b_0
            self.last_selection = batch[b0]
            self._update_si(batch[b0])
        self.coteaching_steps += 1


class EstimatedNoiseCoPESILearner(CoPESILearner):
    """co_pesi_estimated (A.9, Figs. 8-9): CO-PESI whose noise level comes from Algorithm 5, not the teacher.

    When: immediately before every co-teaching step (Alg. 1 l.6-14, i.e. once the buffer holds more than
    s = start_size preferences, once per received preference), Algorithm 5 is run on the whole buffer D
    collected so far and its output becomes `noise_level`, hence the forget rate (1 - remember rate, A.7)
    and n_forget = round(forget_rate * batch). How: each buffered preference (phi_0, phi_1, y) is one entry
    of a PreferenceSet; a run has one environment, so all of them describe the same true parameter, as
    Algorithm 5 assumes. The estimate is taken as written: with no conflicts at all it is 1.0, which
    CoPESILearner caps at keeping one sample per batch. `noise_history` keeps every estimate.
    """

    def __init__(self, model: SIModel, config: CoPESIConfig | None = None, seed: int = 0) -> None:
        # The starting level is never used: the first co-teaching step re-estimates it from D.
        super().__init__(model, 0.0, config, seed)
        self.noise_history: list[float] = []

    def buffer_preferences(self) -> PreferenceSet:
        """D as Algorithm 5's input: the two candidates of each query and its label y (Eq. 2)."""
        values = self.candidates.values
        indices = np.stack(self._indices)
        labels = np.stack(self._labels)[:, 0]
        return PreferenceSet(first=values[indices[:, 0]], second=values[indices[:, 1]], label=labels)

    def _learn(self) -> None:
        if len(self) > self.config.start_size:
            self.noise_level = estimate_noise(self.buffer_preferences())
            self.noise_history.append(self.noise_level)
        super()._learn()

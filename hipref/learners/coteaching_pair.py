"""The co-teaching classifiers M_0, M_1 of Algorithm 1 (Han et al. 2018) and their small-loss selection.

Co-teaching: two networks each rank a minibatch by their own loss and keep the small-loss part; each is
trained on the part its peer kept, so one network's memorised noise is not fed back to itself. Networks
learn the clean, consistent pattern before they memorise the noise, so a small loss is evidence of a
clean label.

The classifiers predict the preference from the candidate pair alone. That suffices because during one
run the environment, and so the true parameter, is fixed: a clean label is then a function of the pair
(y = 1 iff phi_0 is nearer the truth), and a label that disagrees with what the rest of the buffer
implies is a likely flip.
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

from hipref.numerics import adam
from hipref.validation import check_int


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


def classifier_inputs(normalised_pairs: torch.Tensor) -> torch.Tensor:
    """The classifiers' input: the pair (phi_0, phi_1) on [-1, 1] over the candidate range.

    Centred rather than on [0, 1]: a ReLU network at its default initialisation has its units' kinks
    around the origin, and a clean label flips along the lines phi_0 = phi_1 and phi_0 + phi_1 = 2 phi*;
    in our synthetic runs centring made the classifiers separate flipped from clean labels in fewer steps.
    """
    return 2.0 * normalised_pairs - 1.0


def _classifier(hidden_sizes: tuple[int, ...]) -> nn.Sequential:
    """M: (phi_0, phi_1) from `classifier_inputs` -> 2 logits, class 0 for y = 1 and class 1 for y = -1."""
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
        self.optimisers = tuple(adam(m.parameters(), self.learning_rate) for m in self.models)

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

"""PESI: fine-tuning the system-identification model with preferences over candidates (Alg. 2, Eq. 2-3).

The learner asks which of N candidates phi_0..phi_{N-1} is better for the current trajectory slice; the
answer reshapes SI's distribution Pr(phi | tau) by a soft cross-entropy: the preferred candidate's target
weight is raised by p (the encourage percentage), the others' lowered, from where the model already is.
"""

from __future__ import annotations

import copy
import operator
from dataclasses import dataclass

import numpy as np
import torch

from hipref.learners.sysid import SIModel
from hipref.teachers.preference import PreferenceQuery, preference_label_vector
from hipref.validation import check_choice, check_int, check_range

SI_LOSSES: tuple[str, ...] = ("soft", "standard")
"""'soft': Eq. 2 (two candidates) / Eq. 3 (N); 'standard': cross-entropy, the pesi_ce ablation of A.8."""


def pesi_loss(log_probs_pair: torch.Tensor, y: torch.Tensor, encourage_percentage: float) -> torch.Tensor:
    """Eq. 2: soft cross-entropy over a queried pair, averaged over the batch.

    L = -[log Pr(phi_0) (Pr(phi_0) + p y) + log Pr(phi_1) (Pr(phi_1) - p y)]

    log_probs_pair: (B, 2) log Pr of the two queried candidates under SI's distribution over all of Phi
    (log-probabilities rather than probabilities so a vanishing Pr keeps a usable gradient).
    y: (B,) in {-1, 1}, 1 meaning phi_0 preferred. The weights Pr + p y are constants (detached): the
    target is the model's own current belief with p moved from the dispreferred to the preferred candidate,
    so the preferred is encouraged and the other discouraged, by an amount set by p.

    Pr is SI's distribution over all of Phi, as written, so the two weights sum to Pr(phi_0) + Pr(phi_1) < 1
    and the loss also pulls mass from unqueried candidates onto the queried pair in proportion to their
    probabilities. With p = 0 that is all it does: the label is then ignored and the queried pair's order is
    kept; only p turns the label into a change of ranking.
    """
    if not torch.all((y == 1) | (y == -1)):
        raise ValueError(f"y must contain only -1 and 1, got {y.tolist()!r}")
    probs = log_probs_pair.detach().exp()
    weight_0 = probs[:, 0] + encourage_percentage * y
    weight_1 = probs[:, 1] - encourage_percentage * y
    return -(log_probs_pair[:, 0] * weight_0 + log_probs_pair[:, 1] * weight_1).mean()


def pesi_loss_n(log_probs_n: torch.Tensor, y_vec: torch.Tensor, encourage_percentage: float) -> torch.Tensor:
    """Eq. 3: the soft cross-entropy over N queried candidates, averaged over the batch.

    L = -sum_i log Pr(phi_i) (Pr(phi_i) + p y_i),   y_i in {-1/(N-1), 1}, one y_i = 1.

    Our reading of Eq. 3: as printed, the weight is '(sum_{i=1}^{N-1} Pr(phi_i) + p y(phi_i))', an inner sum
    that reuses the outer index. We read the weight as Pr(phi_i) + p y_i, the per-candidate weight of Eq. 2:
    with N = 2 and y_vec = (y, -y) it is then exactly Eq. 2, and since the y_i sum to zero the total weight
    sum_i Pr(phi_i) is kept, p being moved from the N - 1 dispreferred candidates to the preferred one, as in
    Eq. 2. (Summing all N probabilities into every weight would not reduce to Eq. 2.)

    log_probs_n: (B, N) log Pr of the queried candidates; y_vec: (B, N) label vectors.
    """
    weights = log_probs_n.detach().exp() + encourage_percentage * y_vec
    return -(log_probs_n * weights).sum(dim=1).mean()


def standard_ce_loss(log_probs_n: torch.Tensor, y_vec: torch.Tensor) -> torch.Tensor:
    """The pesi_ce ablation (A.8): cross-entropy with the preferred candidate as the positive class.

    The classes are the queried candidates only (their probabilities renormalised, as in the Bradley-Terry
    loss of Christiano et al. 2017 that A.8 contrasts with): L = -log Pr(preferred) / sum_queried Pr.
    Unlike Eq. 2 it pushes toward certainty in the preferred candidate however good the model already is.
    """
    log_probs_among_queried = log_probs_n - torch.logsumexp(log_probs_n, dim=1, keepdim=True)
    preferred = y_vec.argmax(dim=1, keepdim=True)
    return -log_probs_among_queried.gather(1, preferred).mean()


@dataclass(frozen=True)
class PESIConfig:
    """Algorithm 2: preference fine-tuning of SI."""

    loss: str = "soft"
    """'soft' (Eq. 2 / Eq. 3, the method 'pesi') or 'standard' (cross-entropy, the ablation 'pesi_ce')."""
    encourage_percentage: float = 0.25
    """p of Eq. 2, how far one preference moves the target toward the preferred candidate (A.7: 0.25)."""
    learning_rate: float = 1e-3
    """Adam step size for SI (Table 2: 1e-3; the text of A.7 also says fine-tuning used 0.01)."""
    batch_size: int = 16
    """Preferences per SI update, drawn from the buffer (Table 2: 16 for desk height, 32 for cube mass)."""
    n_candidates: int = 2
    """N, candidates per query: 2 is Eq. 2, more is Eq. 3 (A.2)."""
    query_uniform_mix: float = 0.05
    """Weight of a uniform distribution mixed into Pr(phi) when drawing query candidates, in (0, 1]. It keeps
    every candidate askable and lets N distinct candidates be drawn even from a collapsed distribution."""

    def __post_init__(self) -> None:
        check_choice("loss", self.loss, SI_LOSSES)
        check_range("encourage_percentage", self.encourage_percentage, 0.0, 1.0)
        check_range("learning_rate", self.learning_rate, 1e-8, 1.0)
        check_int("batch_size", self.batch_size, 1)
        check_int("n_candidates", self.n_candidates, 2)
        check_range("query_uniform_mix", self.query_uniform_mix, 1e-9, 1.0)


class PESILearner:
    """Algorithm 2 through ask/tell: ask for a preference on a trajectory slice, be told, update SI.

    The learner fine-tunes its own copy of `model`, so one pretrained model can seed several methods.
    Its candidate set Phi is the model's.
    """

    def __init__(self, model: SIModel, config: PESIConfig | None = None, seed: int = 0) -> None:
        self.config = config if config is not None else PESIConfig()
        try:
            seed = operator.index(seed)  # any integer type; a float seed is a mistake
        except TypeError:
            raise ValueError(f"seed must be an integer >= 0, got {seed!r}") from None
        check_int("seed", seed, 0)
        self.model = copy.deepcopy(model)
        self.candidates = model.candidates
        if self.config.n_candidates > self.candidates.size:
            raise ValueError(
                f"n_candidates must be at most |Phi| = {self.candidates.size}, got {self.config.n_candidates}"
            )
        # Separate streams for queries, minibatches and (in CO-PESI) classifier initialisation, so how
        # often one is used does not shift the others.
        query_seed, batch_seed, self._torch_seeds = np.random.SeedSequence(seed).spawn(3)
        self._query_rng = np.random.default_rng(query_seed)
        self._batch_rng = np.random.default_rng(batch_seed)
        self.optimiser = torch.optim.Adam(self.model.parameters(), lr=self.config.learning_rate)
        # The preference buffer D: one entry per answered query.
        self._features: list[np.ndarray] = []
        self._indices: list[np.ndarray] = []
        self._labels: list[np.ndarray] = []

    def __len__(self) -> int:
        """|D|, the number of preferences received."""
        return len(self._labels)

    def _check_features(self, features: np.ndarray) -> np.ndarray:
        features = np.asarray(features, dtype=np.float64)
        if features.shape != (self.model.input_dim,):
            raise ValueError(f"features must have shape ({self.model.input_dim},), got {features.shape}")
        return features

    @torch.no_grad()
    def distribution(self, features: np.ndarray) -> np.ndarray:
        """SI's current Pr(phi | features) over Phi."""
        x = torch.as_tensor(self._check_features(features), dtype=torch.float32)
        return self.model.distribution(x).double().numpy()

    def estimate(self, features: np.ndarray) -> float:
        """SI's current estimate E_Pr[phi] in parameter units, the value the controller is given."""
        return float(self.model.predict(self._check_features(features)))

    def ask(self, features: np.ndarray) -> PreferenceQuery:
        """Alg. 2 'phi_0, phi_1 sampled from Phi': draw N distinct candidates for `features` and ask.

        The candidates are drawn from SI's own Pr(phi | features) (mixed with a little uniform), so queries
        concentrate where the model is unsure between plausible values, where an answer changes the
        estimate most, rather than on values it already rules out.
        """
        features = self._check_features(features)
        probs = self.distribution(features)
        mix = self.config.query_uniform_mix
        probs = (1.0 - mix) * probs + mix / probs.size
        chosen = self._query_rng.choice(
            probs.size, size=self.config.n_candidates, replace=False, p=probs / probs.sum()
        )
        return PreferenceQuery(candidates=tuple(self.candidates.values[chosen]), features=features)

    def tell(self, query: PreferenceQuery, label: int | np.ndarray) -> None:
        """Alg. 2 'ask for preference y, update SI': store it in D, learn (refuses a malformed label)."""
        if len(query.candidates) != self.config.n_candidates:
            raise ValueError(
                f"query must have n_candidates={self.config.n_candidates} candidates, "
                f"got {len(query.candidates)}"
            )
        label_vector = preference_label_vector(label, self.config.n_candidates)
        indices = np.array([self.candidates.index_of(c) for c in query.candidates])
        self._features.append(self._check_features(query.features))
        self._indices.append(indices)
        self._labels.append(label_vector)
        self._learn()

    def _learn(self) -> None:
        # Alg. 2 'update SI by Eqn. 2', here on a minibatch from D so one answer is not all a step sees.
        self._update_si(self._sample_batch())

    def _sample_batch(self) -> np.ndarray:
        size = min(self.config.batch_size, len(self))
        return self._batch_rng.choice(len(self), size=size, replace=False)

    def _batch_tensors(self, batch: np.ndarray) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Features (B, input_dim), candidate indices (B, N) and label vectors (B, N) of buffer entries."""
        features = torch.as_tensor(np.stack([self._features[i] for i in batch]), dtype=torch.float32)
        indices = torch.as_tensor(np.stack([self._indices[i] for i in batch]), dtype=torch.long)
        labels = torch.as_tensor(np.stack([self._labels[i] for i in batch]), dtype=torch.float32)
        return features, indices, labels

    def _update_si(self, batch: np.ndarray) -> float:
        """One Adam step of SI on the buffer entries `batch` with the configured loss; returns the loss."""
        features, indices, labels = self._batch_tensors(batch)
        log_probs = torch.log_softmax(self.model(features), dim=-1).gather(1, indices)
        if self.config.loss == "standard":
            loss = standard_ce_loss(log_probs, labels)  # A.8 ablation
        elif self.config.n_candidates == 2:
            loss = pesi_loss(log_probs, labels[:, 0], self.config.encourage_percentage)  # Eq. 2
        else:
            loss = pesi_loss_n(log_probs, labels, self.config.encourage_percentage)  # Eq. 3
        self.optimiser.zero_grad()
        loss.backward()
        self.optimiser.step()
        return loss.item()

"""PESI: fine-tuning the system-identification model with preferences over candidates (Alg. 2, Eq. 2-3).

The learner draws N candidates phi_0..phi_{N-1}, has the low-level policy executed with them, takes a
trajectory slice tau of one clip and asks which candidate is best; the answer reshapes SI's distribution
Pr(phi | tau) over the queried candidates by a soft cross-entropy: the preferred candidate's target weight
is raised by p (the encourage percentage), the others' lowered, from where the model already is.
"""

from __future__ import annotations

import copy
import operator
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import torch

from hipref.learners.answer_models import AnswerModel
from hipref.learners.noise_estimation import PreferenceSet
from hipref.learners.queries import CHOSEN, choose_pair
from hipref.learners.sysid import SIModel
from hipref.teachers.preference import NoLabel, PreferenceQuery, preference_label_vector
from hipref.validation import check_choice, check_int, check_range

SI_LOSSES: tuple[str, ...] = ("soft", "standard")
"""'soft': Eq. 2 (two candidates) / Eq. 3 (N); 'standard': cross-entropy, the pesi_ce ablation of A.8."""


PR_DOMAINS: tuple[str, ...] = ("query", "all")
"""Over what Pr in Eq. 2/3 is a distribution: the queried candidates, or all of Phi (see `log_probs`)."""
CANDIDATE_SAMPLING: tuple[str, ...] = ("uniform", "belief", *CHOSEN)
"""How Algorithm 2 draws the queried candidates from Phi (see `PESILearner.ask`): uniformly, from SI's
belief, or by a query rule of `hipref.learners.queries` on that belief (pairs only)."""
FINE_TUNED: tuple[str, ...] = ("all", "last_layer", "output_bias")
"""Which of SI's parameters preferences fine-tune: every layer, the output layer, or its bias alone."""


def log_probs(logits: torch.Tensor, indices: torch.Tensor, pr_domain: str = "query") -> torch.Tensor:
    """log Pr(phi_i) of the queried candidates (B, N), from SI's logits (B, |Phi|) and the query (B, N).

    'query': SI's distribution renormalised over the queried candidates, as the Bradley-Terry preference
    model of Christiano et al. (2017) that A.8 sets Eq. 2 against: Pr(phi_i) is the probability that phi_i
    is the best of the N shown. The weights Pr(phi_i) + p y_i then sum to one and an update only moves mass
    between the queried candidates. 'all': SI's distribution over all of Phi, the literal Pr(phi in Phi) of
    section 4; the weights then sum to less than one, and every update also drains the unqueried candidates
    onto the queried ones, whatever the label.
    """
    check_choice("pr_domain", pr_domain, PR_DOMAINS)
    if pr_domain == "query":
        return torch.log_softmax(logits.gather(1, indices), dim=1)
    return torch.log_softmax(logits, dim=1).gather(1, indices)


def pesi_loss(log_probs_pair: torch.Tensor, y: torch.Tensor, encourage_percentage: float) -> torch.Tensor:
    """Eq. 2: soft cross-entropy over a queried pair, averaged over the batch.

    L = -[log Pr(phi_0) (Pr(phi_0) + p y) + log Pr(phi_1) (Pr(phi_1) - p y)]

    log_probs_pair: (B, 2) from `log_probs` (log-probabilities rather than probabilities so a
    vanishing Pr keeps a usable gradient). y: (B,) in {-1, 1}, 1 meaning phi_0 preferred. The weights
    Pr + p y are constants (detached): the target is the model's own current belief with p moved from the
    dispreferred to the preferred candidate. The gradient on the pair's logits is then exactly -p y and
    p y, so p sets the update size (section 4), and with p = 0 there is no update at all.
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
    with N = 2 and y_vec = (y, -y) it is then exactly Eq. 2, and since the y_i sum to zero the weights
    still sum to one, p being moved from the N - 1 dispreferred candidates to the preferred one, as in
    Eq. 2. (Summing all N probabilities into every weight would not reduce to Eq. 2.)

    log_probs_n: (B, N) from `log_probs`; y_vec: (B, N) label vectors.
    """
    weights = log_probs_n.detach().exp() + encourage_percentage * y_vec
    return -(log_probs_n * weights).sum(dim=1).mean()


def standard_ce_loss(log_probs_n: torch.Tensor, y_vec: torch.Tensor) -> torch.Tensor:
    """The pesi_ce ablation (A.8): cross-entropy with the preferred candidate as the positive class.

    log_probs_n: (B, N) from `log_probs`, so this is the Bradley-Terry loss of Christiano et al.
    (2017) that A.8 contrasts with: L = -log Pr(preferred). Unlike Eq. 2 it pushes toward certainty in the
    preferred candidate however sure the model already is.
    """
    preferred = y_vec.argmax(dim=1, keepdim=True)
    return -log_probs_n.gather(1, preferred).mean()


@dataclass(frozen=True)
class PESIConfig:
    """Algorithm 2: preference fine-tuning of SI."""

    loss: str = "soft"
    """'soft' (Eq. 2 / Eq. 3, the method 'pesi') or 'standard' (cross-entropy, the ablation 'pesi_ce')."""
    encourage_percentage: float = 0.25
    """p of Eq. 2, how far one preference moves the target toward the preferred candidate (A.7: 0.25)."""
    learning_rate: float = 1e-2
    """Step size of SI fine-tuning (A.7: 'the finetuning process is conducted for learning rate of 0.01';
    Table 2's 1e-3 is Algorithm 4's pretraining rate)."""
    batch_size: int = 16
    """Preferences per SI update, drawn from the buffer (Table 2: 16 for desk height, 32 for cube mass)."""
    n_candidates: int = 2
    """N, candidates per query: 2 is Eq. 2, more is Eq. 3 (A.2)."""
    history: int = 3
    """h, control periods per trajectory slice tau (Algorithm 2's input; Table 2: 3)."""
    candidate_sampling: str = "uniform"
    """'uniform': phi_0..phi_{N-1} drawn uniformly from Phi (Algorithm 2: 'sampled from Phi'); 'belief':
    drawn from SI's Pr(phi) at the previous query's slice, mixed with `query_uniform_mix` of uniform; or a
    query rule of `hipref.learners.queries` ('thompson', 'information_gain', 'volume_removal') scoring
    pairs on that Pr (uniform before the first query) with the flip model's likelihood, pairs only."""
    query_uniform_mix: float = 0.05
    """With 'belief' sampling, the weight of a uniform distribution mixed into Pr(phi), in (0, 1]: it keeps
    every candidate askable and lets N distinct candidates be drawn even from a collapsed distribution."""
    pr_domain: str = "query"
    """Pr of Eq. 2/3 over the queried candidates ('query') or over all of Phi ('all'); see `log_probs`."""
    fine_tuned: str = "all"
    """Which parameters of SI the preferences update: 'all' (Algorithm 2 'update SI'), 'last_layer' or
    'output_bias'."""

    def __post_init__(self) -> None:
        check_choice("loss", self.loss, SI_LOSSES)
        check_range("encourage_percentage", self.encourage_percentage, 0.0, 1.0)
        check_range("learning_rate", self.learning_rate, 1e-8, 1.0)
        check_int("batch_size", self.batch_size, 1)
        check_int("n_candidates", self.n_candidates, 2)
        check_int("history", self.history, 1)
        check_choice("candidate_sampling", self.candidate_sampling, CANDIDATE_SAMPLING)
        if self.candidate_sampling in CHOSEN and self.n_candidates != 2:
            raise ValueError(
                f"candidate_sampling {self.candidate_sampling!r} asks pairs: n_candidates must be 2, "
                f"got {self.n_candidates}"
            )
        check_range("query_uniform_mix", self.query_uniform_mix, 1e-9, 1.0)
        check_choice("pr_domain", self.pr_domain, PR_DOMAINS)
        check_choice("fine_tuned", self.fine_tuned, FINE_TUNED)


def fine_tuned_parameters(model: SIModel, fine_tuned: str) -> list[torch.nn.Parameter]:
    """The parameters of `model` that preferences update; the others are frozen (requires_grad off)."""
    check_choice("fine_tuned", fine_tuned, FINE_TUNED)
    output = model.net[-1]
    chosen = {
        "all": list(model.parameters()),
        "last_layer": list(output.parameters()),
        "output_bias": [parameter for name, parameter in output.named_parameters() if name == "bias"],
    }[fine_tuned]
    ids = {id(p) for p in chosen}
    for parameter in model.parameters():
        parameter.requires_grad_(id(parameter) in ids)
    return chosen


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
        # Plain gradient steps: the update is then proportional to p, the encourage percentage 'controlling
        # the update size' (section 4). Adam would rescale every step to about the learning rate, so that p
        # hardly mattered and even a zero gradient's rounding noise moved the model.
        self.optimiser = torch.optim.SGD(
            fine_tuned_parameters(self.model, self.config.fine_tuned), lr=self.config.learning_rate
        )
        # The preference buffer D: one entry per answered query.
        self._features: list[np.ndarray] = []
        self._indices: list[np.ndarray] = []
        self._labels: list[np.ndarray] = []
        self._last_slice: np.ndarray | None = None
        # Answers without a label (SKIP, EQUAL), which D does not hold.
        self.unlabelled = 0

    def __len__(self) -> int:
        """|D|, the number of preferences received."""
        return len(self._labels)

    def buffer_preferences(self) -> PreferenceSet:
        """D as a preference dataset (Algorithm 5's input): the first two candidates of each query and its
        label y (Eq. 2)."""
        values = self.candidates.values
        indices = np.stack(self._indices)
        labels = np.stack(self._labels)[:, 0]
        return PreferenceSet(first=values[indices[:, 0]], second=values[indices[:, 1]], label=labels)

    def filter_precision_recall(self, flipped: Sequence[bool] | np.ndarray) -> tuple[float, float] | None:
        """The precision and recall of the learner's filter of flipped preferences against the teacher's
        record `flipped`; None: PESI filters nothing (learners with a filter override it)."""
        return None

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

    def ask(self, observe: Callable[[float, np.random.Generator], np.ndarray]) -> PreferenceQuery:
        """Algorithm 2, l.2-3: execute pi^l with phi_0 .. phi_{N-1} sampled from Phi, sample a slice tau.

        The candidates are distinct, drawn uniformly from Phi or (`candidate_sampling='belief'`) from SI's
        Pr(phi | tau) at the previous query's slice (uniform before the first), mixed with a little
        uniform. tau is h consecutive periods at a
        uniformly random place of a uniformly chosen candidate's clip: `observe(phi, rng)` executes pi^l
        with phi (every candidate from the same start) and returns that slice, flattened, its place drawn
        with `rng`.

        Algorithm 2 executes pi^l with every candidate so that a person can compare the clips. The
        scripted teacher compares the candidate values with the truth and never sees a clip, and pi^l
        draws no random numbers, so only the clip tau is cut from is executed: the queries, answers and
        updates are those of executing all N.
        """
        n = self.config.n_candidates
        if self.config.candidate_sampling in CHOSEN:
            chosen = np.array(self._chosen_pair())
        else:
            chosen = self._query_rng.choice(
                self.candidates.size, size=n, replace=False, p=self._query_distribution()
            )
        candidates = tuple(float(c) for c in self.candidates.values[chosen])
        sliced = candidates[int(self._query_rng.integers(n))]
        tau = self._check_features(observe(sliced, self._query_rng))
        self._last_slice = tau
        return PreferenceQuery(candidates, features=tau)

    def _chosen_pair(self) -> tuple[int, int]:
        size = self.candidates.size
        belief = (
            np.full(size, 1.0 / size) if self._last_slice is None else self.distribution(self._last_slice)
        )
        values = self.candidates.values
        rule = self.config.candidate_sampling
        return choose_pair(rule, self.candidates, values, [(AnswerModel(), belief)], self._query_rng)

    def _query_distribution(self) -> np.ndarray:
        size = self.candidates.size
        if self.config.candidate_sampling == "uniform":
            return np.full(size, 1.0 / size)
        if self._last_slice is not None:
            probs = self.distribution(self._last_slice)
        else:
            probs = np.full(size, 1.0 / size)
        mix = self.config.query_uniform_mix
        probs = (1.0 - mix) * probs + mix / size
        return probs / probs.sum()

    def tell(self, query: PreferenceQuery, label: int | np.ndarray | NoLabel) -> None:
        """Alg. 2 'ask for preference y, update SI': store it in D, learn (refuses a malformed label).

        A SKIP or EQUAL answer (`hipref.teachers.models`) carries no label: nothing is stored and SI is not
        updated. Eq. 2 with y = 0 would be no update either: its target is then SI's own Pr, so the gradient
        vanishes. `unlabelled` counts such answers."""
        if len(query.candidates) != self.config.n_candidates:
            raise ValueError(
                f"query must have n_candidates={self.config.n_candidates} candidates, "
                f"got {len(query.candidates)}"
            )
        if isinstance(label, NoLabel):
            self.unlabelled += 1
            return
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
        """One gradient step of SI on the buffer entries `batch` with the configured loss; returns it."""
        features, indices, labels = self._batch_tensors(batch)
        queried = log_probs(self.model(features), indices, self.config.pr_domain)
        if self.config.loss == "standard":
            loss = standard_ce_loss(queried, labels)  # A.8 ablation
        elif self.config.n_candidates == 2:
            loss = pesi_loss(queried, labels[:, 0], self.config.encourage_percentage)  # Eq. 2
        else:
            loss = pesi_loss_n(queried, labels, self.config.encourage_percentage)  # Eq. 3
        self.optimiser.zero_grad()
        loss.backward()
        self.optimiser.step()
        return loss.item()

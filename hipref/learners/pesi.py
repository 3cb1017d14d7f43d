"""PESI: fine-tuning the system-identification model with preferences over candidates (Alg. 2, Eq. 2-3).

The learner draws N candidates phi_0..phi_{N-1}, has the low-level policy executed with them, takes a
trajectory slice tau of one clip and asks which candidate is best; the answer reshapes SI's distribution
Pr(phi | tau) over the queried candidates by a soft cross-entropy: the preferred candidate's target weight
is raised by p (the encourage percentage), the others' lowered, from where the model already is.

One learner, `PESILearner`, composed of four parts: the query rule (`PESIConfig.candidate_sampling`), the
loss (`PESIConfig.loss`, `hipref.learners.losses`), a filter of flipped preferences
(`hipref.learners.filters`; co-teaching, Algorithm 1, makes it CO-PESI) and the source of its flip rate
(`hipref.learners.noise_rate`: told, Algorithm 5, likelihood).
"""

from __future__ import annotations

import copy
import operator
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Annotated

import numpy as np
import torch

from hipref.learners.answer_models import AnswerModel
from hipref.learners.filters import FilterSetting, Unfiltered
from hipref.learners.losses import PAIR_LOSSES, PR_DOMAINS, SI_LOSSES, log_probs, si_loss
from hipref.learners.noise_estimation import PreferenceSet
from hipref.learners.noise_rate import FlipRate, Told
from hipref.learners.queries import CHOSEN, choose_pair
from hipref.learners.sysid import SIModel
from hipref.seeds import integer_seed
from hipref.teachers.preference import NoLabel, PreferenceQuery, preference_label_vector
from hipref.validation import Integer, OneOf, Range, check_choice, check_fields, check_int

CANDIDATE_SAMPLING: tuple[str, ...] = ("uniform", "belief", *CHOSEN)
"""How Algorithm 2 draws the queried candidates from Phi (see `PESILearner.ask`): uniformly, from SI's
belief, or by a query rule of `hipref.learners.queries` on that belief (pairs only)."""
PESI_FILTER = Unfiltered()
"""PESI's filter: none, every SI update sees its whole minibatch."""
TRUSTING = Told(0.0)
"""The flip rate of a learner that trusts every label."""
FINE_TUNED: tuple[str, ...] = ("all", "last_layer", "output_bias")
"""Which of SI's parameters preferences fine-tune: every layer, the output layer, or its bias alone."""


LEARNING_RATE = Range(1e-8, 1.0)
"""The step sizes of SI fine-tuning a config accepts (`PESIConfig.learning_rate` and the studies')."""


@dataclass(frozen=True)
class PESIConfig:
    """Algorithm 2: preference fine-tuning of SI."""

    loss: Annotated[str, OneOf(SI_LOSSES)] = "soft"
    """One of `hipref.learners.losses.SI_LOSSES`: 'soft' (Eq. 2 / Eq. 3, the method 'pesi'), 'standard'
    (cross-entropy, the ablation 'pesi_ce'), 'smoothed' or 'unbiased' (pairs only)."""
    smoothing: Annotated[float, Range(0.0, 0.5 - 1e-9)] = 0.1
    """eps of the 'smoothed' loss, the weight of the reversed label, in [0, 0.5) (conservative DPO commonly
    uses 0.1)."""
    encourage_percentage: Annotated[float, Range(0.0, 1.0)] = 0.25
    """p of Eq. 2, how far one preference moves the target toward the preferred candidate (A.7: 0.25)."""
    learning_rate: Annotated[float, LEARNING_RATE] = 1e-2
    """Step size of SI fine-tuning (A.7: 'the finetuning process is conducted for learning rate of 0.01';
    Table 2's 1e-3 is Algorithm 4's pretraining rate)."""
    batch_size: Annotated[int, Integer(1)] = 16
    """Preferences per SI update, drawn from the buffer (Table 2: 16 for desk height, 32 for cube mass)."""
    n_candidates: Annotated[int, Integer(2)] = 2
    """N, candidates per query: 2 is Eq. 2, more is Eq. 3 (A.2)."""
    history: Annotated[int, Integer(1)] = 3
    """h, control periods per trajectory slice tau (Algorithm 2's input; Table 2: 3)."""
    candidate_sampling: Annotated[str, OneOf(CANDIDATE_SAMPLING)] = "uniform"
    """'uniform': phi_0..phi_{N-1} drawn uniformly from Phi (Algorithm 2: 'sampled from Phi'); 'belief':
    drawn from SI's Pr(phi) at the previous query's slice, mixed with `query_uniform_mix` of uniform; or a
    query rule of `hipref.learners.queries` ('thompson', 'information_gain', 'volume_removal') scoring
    pairs on that Pr (uniform before the first query) with the flip model's likelihood, pairs only."""
    query_uniform_mix: Annotated[float, Range(1e-9, 1.0)] = 0.05
    """With 'belief' sampling, the weight of a uniform distribution mixed into Pr(phi), in (0, 1]: it keeps
    every candidate askable and lets N distinct candidates be drawn even from a collapsed distribution."""
    pr_domain: Annotated[str, OneOf(PR_DOMAINS)] = "query"
    """Pr of Eq. 2/3 over the queried candidates ('query') or over all of Phi ('all'); see `log_probs`."""
    fine_tuned: Annotated[str, OneOf(FINE_TUNED)] = "all"
    """Which parameters of SI the preferences update: 'all' (Algorithm 2 'update SI'), 'last_layer' or
    'output_bias'."""
    start_size: Annotated[int, Integer(0)] = 16
    """s: a filter, and an estimate of the flip rate, start once |D| > s (Alg. 1 l.5); before that SI is
    updated on unfiltered batches as PESI does. Not given in the paper; by default a full batch must be
    available."""

    def __post_init__(self) -> None:
        check_fields(self)
        if self.candidate_sampling in CHOSEN and self.n_candidates != 2:
            raise ValueError(
                f"candidate_sampling {self.candidate_sampling!r} asks pairs: n_candidates must be 2, "
                f"got {self.n_candidates}"
            )


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
    Its candidate set Phi is the model's. Each received preference is learned by the `filter`
    (`hipref.learners.filters.Unfiltered` by default: PESI) at the flip rate `flip_rate` gives once
    |D| > s (0 before; `TRUSTING` by default, a learner that trusts every label); the estimated rates are
    kept in `noise_history`.
    """

    def __init__(
        self,
        model: SIModel,
        config: PESIConfig | None = None,
        seed: int = 0,
        filter: FilterSetting = PESI_FILTER,
        flip_rate: FlipRate = TRUSTING,
    ) -> None:
        self.config = config if config is not None else PESIConfig()
        try:
            seed = operator.index(seed)  # any integer type; a float seed is a mistake
        except TypeError:
            raise ValueError(f"seed must be an integer >= 0, got {seed!r}") from None
        check_int("seed", seed, 0)
        if (filter.pairs_only or self.config.loss in PAIR_LOSSES) and self.config.n_candidates != 2:
            raise ValueError(
                f"n_candidates must be 2 for a filter of pairs or the {self.config.loss!r} loss, "
                f"got {self.config.n_candidates}"
            )
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
        self.flip_rate = flip_rate
        self.noise_history: list[float] = []
        self.filter = filter.start(self)

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

    @property
    def start_size(self) -> int:
        """s, the size of D after which the filter and the flip-rate estimate start."""
        return self.config.start_size

    def next_seed(self) -> int:
        """A fresh seed of the learner's own stream for torch initialisations (CO-PESI's classifiers)."""
        return integer_seed(self._torch_seeds.spawn(1)[0])

    def filter_precision_recall(self, flipped: Sequence[bool] | np.ndarray) -> tuple[float, float] | None:
        """The precision and recall of the learner's filter of flipped preferences against the teacher's
        record `flipped`; None when it filters nothing (PESI)."""
        return self.filter.precision_recall(flipped)

    def estimates(self, slices: np.ndarray) -> np.ndarray:
        """SI's E_Pr[phi] on each of `slices` (one per row), as the evaluation reads a learner."""
        return self.model.predict(slices)

    def running_estimate(self, evaluation: np.ndarray) -> float:
        """What the learner gives the controller during a teaching session: SI's mean estimate on the
        session's probing slices `evaluation` (SI's multi-slice estimate)."""
        return float(self.model.predict(evaluation).mean())

    def mode(self, features: np.ndarray) -> float:
        """SI's most probable candidate on one slice."""
        return float(self.model.predict_mode(features))

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
        # The flip rate e of this preference's learning: told, or estimated from D once |D| > s.
        rate = 0.0
        if len(self) > self.config.start_size:
            rate = self.flip_rate.rate(self.buffer_preferences, self.candidates.low, self.candidates.high)
            if self.flip_rate.estimated:
                self.noise_history.append(rate)
        self.filter.learn(rate)

    def sample_batch(self) -> np.ndarray:
        """A minibatch of D, at most `batch_size` distinct entries, as buffer indices."""
        size = min(self.config.batch_size, len(self))
        return self._batch_rng.choice(len(self), size=size, replace=False)

    def batch_tensors(self, batch: np.ndarray) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Features (B, input_dim), candidate indices (B, N) and label vectors (B, N) of buffer entries."""
        features = torch.as_tensor(np.stack([self._features[i] for i in batch]), dtype=torch.float32)
        indices = torch.as_tensor(np.stack([self._indices[i] for i in batch]), dtype=torch.long)
        labels = torch.as_tensor(np.stack([self._labels[i] for i in batch]), dtype=torch.float32)
        return features, indices, labels

    def queried(self, batch: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        """SI's log Pr over each entry's queried candidates (B, N) and its label vector (B, N)."""
        features, indices, labels = self.batch_tensors(batch)
        return log_probs(self.model(features), indices, self.config.pr_domain), labels

    def si_step(self, queried: torch.Tensor, labels: torch.Tensor, rate: float) -> float:
        """One gradient step of SI by the configured loss of `queried` and `labels`; returns the loss."""
        c = self.config
        loss = si_loss(c.loss, queried, labels, c.encourage_percentage, c.smoothing, rate)
        self.optimiser.zero_grad()
        loss.backward()
        self.optimiser.step()
        return loss.item()

    def update_si(self, batch: np.ndarray, rate: float) -> float:
        """One gradient step of SI on the buffer entries `batch` with the configured loss; returns it."""
        return self.si_step(*self.queried(batch), rate)

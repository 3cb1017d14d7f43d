"""The system-identification model SI: a trajectory slice -> a distribution over candidate parameters (A.4).

SI maps the last h (state, action) steps to Pr(phi) over a finite candidate set Phi (section 4, 'Preference
Enhanced System Identification'); it is pretrained by regression on domain-randomised data (Algorithm 4)
and later fine-tuned with preferences (pesi.py, coteaching.py).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Annotated

import numpy as np
import torch
from torch import nn

from hipref.learners.mlp import tanh_mlp
from hipref.numerics import adam
from hipref.validation import Integer, OneOf, Range, check_fields, check_int, check_range


@dataclass(frozen=True)
class CandidateSet:
    """Phi: evenly spaced candidate values low, low + resolution, ..., high of one unknown parameter."""

    low: Annotated[float, Range(-1e9, 1e9)]
    """Smallest candidate, in parameter units (the lower end of the randomisation range)."""
    high: Annotated[float, Range(-1e9, 1e9)]
    """Largest candidate, in parameter units; high - low must be a whole number of `resolution` steps."""
    resolution: float
    """Spacing between neighbouring candidates, in parameter units."""

    def __post_init__(self) -> None:
        check_fields(self)
        if self.high <= self.low:
            raise ValueError(f"high must be greater than low={self.low}, got {self.high}")
        check_range("resolution", self.resolution, 1e-12, self.high - self.low)
        steps = (self.high - self.low) / self.resolution
        if abs(steps - round(steps)) > 1e-6:
            raise ValueError(
                f"resolution must divide high - low = {self.high - self.low} into whole steps, "
                f"got {self.resolution}"
            )

    @property
    def size(self) -> int:
        """|Phi|, the number of candidates."""
        return round((self.high - self.low) / self.resolution) + 1

    @property
    def values(self) -> np.ndarray:
        """The candidates in increasing order (linspace, so both ends are exact), computed once per set and
        copied."""
        return _values(self.low, self.high, self.size).copy()

    def normalise(self, parameter: np.ndarray | float) -> np.ndarray | float:
        """Map parameter units to [0, 1] over the range, so losses weigh height and mass alike."""
        return (parameter - self.low) / (self.high - self.low)

    def denormalise(self, normalised: np.ndarray | float) -> np.ndarray | float:
        """Inverse of `normalise`."""
        return self.low + normalised * (self.high - self.low)

    def index_of(self, value: float) -> int:
        """Index of `value` in Phi; raise ValueError if it is not (up to rounding) one of the candidates."""
        index = round((float(value) - self.low) / self.resolution)
        if not (
            0 <= index < self.size and math.isclose(self.values[index], value, abs_tol=1e-6 * self.resolution)
        ):
            raise ValueError(f"value must be a candidate of {self}, got {value!r}")
        return index


@functools.lru_cache(maxsize=64, typed=True)
def _values(low: float, high: float, size: int) -> np.ndarray:
    values = np.linspace(low, high, size)
    values.flags.writeable = False
    return values


DESK_HEIGHT = CandidateSet(low=0.5, high=0.9, resolution=0.01)
"""Desk height in m: the randomisation range of Table 2 in 1 cm steps (41 candidates)."""
CUBE_MASS = CandidateSet(low=8.0, high=20.0, resolution=0.25)
"""Cube mass in kg: the randomisation range of Table 2 in 0.25 kg steps (49 candidates)."""


@dataclass(frozen=True, eq=False)
class Normaliser:
    """Per-feature standardisation (x - mean) / std, fitted on the pretraining data, kept with the model."""

    mean: np.ndarray
    """Per-feature mean of the pretraining inputs."""
    std: np.ndarray
    """Per-feature standard deviation, floored so a constant feature does not divide by zero."""

    @classmethod
    def fit(cls, features: np.ndarray, min_std: float = 1e-6) -> Normaliser:
        """Fit on an (n_samples, input_dim) array."""
        features = np.asarray(features, dtype=np.float64)
        return cls(mean=features.mean(axis=0), std=np.maximum(features.std(axis=0), min_std))

    def __call__(self, features: np.ndarray) -> np.ndarray:
        return (np.asarray(features) - self.mean) / self.std


class SIModel(nn.Module):
    """SI: features -> logits over Phi. MLP [256, 128, 64, 32] with tanh (Table 2).

    The input is a slice tau of h control periods, each period's features (`hipref.control.tool`) one
    after the other, unnormalised; the model standardises it with its own stored `Normaliser` (buffers, so
    it travels in the state dict), which `pretrain` fits.
    """

    candidate_values: torch.Tensor
    normalised_values: torch.Tensor
    feature_mean: torch.Tensor
    feature_std: torch.Tensor

    def __init__(
        self,
        input_dim: int,
        candidates: CandidateSet,
        hidden_sizes: tuple[int, ...] = (256, 128, 64, 32),
        seed: int = 0,
    ) -> None:
        super().__init__()
        check_int("input_dim", input_dim, 1)
        if not hidden_sizes or not all(isinstance(h, int) and h >= 1 for h in hidden_sizes):
            raise ValueError(
                f"hidden_sizes must be a non-empty tuple of positive integers, got {hidden_sizes!r}"
            )
        self.candidates = candidates
        self.input_dim = input_dim
        self.register_buffer("candidate_values", torch.as_tensor(candidates.values, dtype=torch.float32))
        self.register_buffer(
            "normalised_values", torch.as_tensor(candidates.normalise(candidates.values), dtype=torch.float32)
        )
        self.register_buffer("feature_mean", torch.zeros(input_dim))
        self.register_buffer("feature_std", torch.ones(input_dim))
        self.net = tanh_mlp(input_dim, tuple(hidden_sizes), candidates.size, seed)

    def set_normaliser(self, normaliser: Normaliser) -> None:
        """Store the input standardisation used from now on."""
        if normaliser.mean.shape != (self.input_dim,):
            raise ValueError(
                f"normaliser must have {self.input_dim} features, got shape {normaliser.mean.shape}"
            )
        self.feature_mean.copy_(torch.as_tensor(normaliser.mean, dtype=torch.float32))
        self.feature_std.copy_(torch.as_tensor(normaliser.std, dtype=torch.float32))

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        """Logits over Phi for a batch (or a single vector) of raw features."""
        return self.net((features - self.feature_mean) / self.feature_std)

    def distribution(self, features: torch.Tensor) -> torch.Tensor:
        """Pr(phi | features), the softmax over Phi."""
        return torch.softmax(self(features), dim=-1)

    def estimate(self, features: torch.Tensor, normalised: bool = False) -> torch.Tensor:
        """E_Pr[phi]: the parameter the controller uses (in [0, 1] if `normalised`).

        The expectation rather than the argmax: it is not quantised to the candidate grid, it moves smoothly
        as preferences reshape the distribution (an argmax jumps only when the mode changes), it is the
        quantity Algorithm 4 regresses, and under uncertainty it minimises the expected squared error.
        """
        values = self.normalised_values if normalised else self.candidate_values
        return (self.distribution(features) * values).sum(dim=-1)

    @torch.no_grad()
    def predict_mode(self, features: np.ndarray) -> np.ndarray:
        """The candidate of highest probability (argmax of Pr), in parameter units, as float64."""
        logits = self(torch.as_tensor(np.asarray(features), dtype=torch.float32))
        return self.candidates.values[logits.argmax(dim=-1).numpy()]

    @torch.no_grad()
    def predict(self, features: np.ndarray) -> np.ndarray:
        """`estimate` for numpy input, in parameter units, as a float64 array (0-d for one vector).

        An expectation over Phi lies inside its range, but summed in float32 a distribution collapsed on
        an end of the range can round past it (0.90000004 m): the estimate is clipped to the range."""
        estimate = self.estimate(torch.as_tensor(np.asarray(features), dtype=torch.float32)).numpy()
        return np.clip(estimate.astype(np.float64), self.candidates.low, self.candidates.high)


PRETRAIN_LOSSES: tuple[str, ...] = ("brier", "expectation", "brier_expectation", "nll")
"""What Algorithm 4's 'MSE loss' is taken over (see `pretrain`)."""


@dataclass(frozen=True)
class PretrainConfig:
    """Algorithm 4: supervised pretraining of SI on domain-randomised (features, parameter) pairs."""

    learning_rate: Annotated[float, Range(1e-8, 1.0)] = 1e-3
    """Adam step size (Table 2, 'System Identification Learning Rate')."""
    batch_size: Annotated[int, Integer(1)] = 128
    """l, samples per minibatch. Not given in the paper."""
    n_steps: Annotated[int, Integer(0)] = 3000
    """Gradient steps (the loop of Algorithm 4 has no stated end)."""
    loss: Annotated[str, OneOf(PRETRAIN_LOSSES)] = "brier"
    """'brier': squared error between Pr(phi) and the target distribution (default); 'expectation': squared
    error between E_Pr[phi] and phi only; 'brier_expectation': their sum; 'nll': the negative log-likelihood
    of the target distribution. See `pretrain`."""

    def __post_init__(self) -> None:
        check_fields(self)


def target_distribution(candidates: CandidateSet, parameters: np.ndarray) -> np.ndarray:
    """The distribution over Phi that SI is pretrained towards for true parameters `parameters` (n,).

    The mass sits on the two candidates around phi, split linearly ('two-hot'), so the target's
    expectation is phi itself even between candidates, and a candidate 1 cm off gets no mass.
    """
    position = np.clip(candidates.normalise(np.asarray(parameters, dtype=np.float64)), 0.0, 1.0)
    position = position * (candidates.size - 1)
    lower = np.minimum(np.floor(position).astype(np.int64), candidates.size - 2)
    upper_weight = position - lower
    target = np.zeros((len(position), candidates.size))
    rows = np.arange(len(position))
    target[rows, lower] = 1.0 - upper_weight
    target[rows, lower + 1] = upper_weight
    return target


def pretrain(
    model: SIModel, features: np.ndarray, parameters: np.ndarray, config: PretrainConfig, seed: int
) -> np.ndarray:
    """Algorithm 4 on `model` in place; returns the loss of every step.

    Section 4 calls pretraining 'a regression problem' fitted with 'the mean squared loss', and A.4 says the
    trained model maps a slice 'to a predicted distribution of the parameters'. Two literal readings:

    - 'brier' (default): the mean squared error between the predicted distribution Pr(phi) and the target
      distribution of `target_distribution` (summed over Phi: the Brier score). The distribution itself
      is trained, so its mass sits near the truth, which is what Eq. 2 later reshapes.
    - 'expectation': the squared error between E_Pr[phi] and phi on the [0, 1]-normalised scale. Only the
      mean is trained; the shape is free, and in our runs about 40 % of the mass ended on the range ends,
      which Eq. 2's pair updates then tilted further (notebook 08 keeps this reading as a row).
    - 'brier_expectation': the sum of both.
    - 'nll': not the paper's squared loss but the cross-entropy of the target distribution (the negative
      log-likelihood of the candidates around the truth), the proper score under which Pr(phi | tau) is
      trained to be a posterior; the Brier score penalises a confident miss at most 2, so it leaves tails
      thin (notebook 13 measures both readings' calibration).
    """
    features = np.asarray(features, dtype=np.float64)
    parameters = np.asarray(parameters, dtype=np.float64).reshape(-1)
    if features.ndim != 2 or features.shape[1] != model.input_dim or len(features) != len(parameters):
        raise ValueError(
            f"features must be (n, {model.input_dim}) with one parameter per row, got {features.shape} "
            f"and {parameters.shape[0]} parameters"
        )
    model.set_normaliser(Normaliser.fit(features))
    x_all = torch.as_tensor(features, dtype=torch.float32)
    target_all = torch.as_tensor(model.candidates.normalise(parameters), dtype=torch.float32)
    distribution_all = torch.as_tensor(target_distribution(model.candidates, parameters), dtype=torch.float32)
    optimiser = adam(model.parameters(), config.learning_rate)
    rng = np.random.default_rng(seed)
    batch_size = min(config.batch_size, len(features))
    losses = np.empty(config.n_steps)
    for step in range(config.n_steps):
        # Alg. 4 l.2: sample a batch {(tau_j, phi_j)} from D
        batch = torch.as_tensor(rng.choice(len(features), size=batch_size, replace=False))
        # Alg. 4 l.4: update SI with the mean squared loss
        probs = model.distribution(x_all[batch])
        loss = torch.zeros(())
        if config.loss in ("brier", "brier_expectation"):
            loss = loss + torch.mean(torch.sum((probs - distribution_all[batch]) ** 2, dim=-1))
        if config.loss == "nll":
            log_probs = torch.log_softmax(model(x_all[batch]), dim=-1)
            loss = loss - torch.mean(torch.sum(distribution_all[batch] * log_probs, dim=-1))
        if config.loss in ("expectation", "brier_expectation"):
            expectation = (probs * model.normalised_values).sum(dim=-1)
            loss = loss + torch.mean((expectation - target_all[batch]) ** 2)
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()
        losses[step] = loss.item()
    return losses

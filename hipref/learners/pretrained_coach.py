"""Pretrained COACH (paper section 5, R1, Fig. 2c): feedback applied to a flat policy over low-level actions.

The baseline has no grid and no goal-conditioned controller. Its policy pi_theta(a|s) is a small MLP from
the low-level state to one of a few displacements of the sponge (`hipref.envs.flat_wiping`). It is
pretrained by behaviour cloning (cross-entropy) on demonstrations collected with the same predefined force
controller following the grid expert, then updated by Eq. 1 with the teacher's feedback:

    grad J(theta) = E_{a ~ pi(.|s)} [ grad_theta log pi_theta(a|s) * f ].

The teacher judges a low-level action by whether it moves the sponge the way the expert's next goal would:
+1 for the displacement closest in angle to the direction from the sponge to U(cell, expert(cell)), -1 for
any other.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import numpy as np
import torch
from torch import nn

from hipref.numerics import adam
from hipref.teachers.feedback import FeedbackQuery, validate_feedback
from hipref.validation import Integer, Range, check_fields, check_int


@dataclass(frozen=True)
class PretrainedCoachConfig:
    """The flat policy, its behaviour-cloning pretraining and its feedback updates."""

    hidden: Annotated[int, Integer(4, 4096)] = 64
    """Units in each of the MLP's two hidden layers."""
    bc_epochs: Annotated[int, Integer(0, 10_000)] = 30
    """Passes over the demonstrations in behaviour cloning."""
    bc_learning_rate: Annotated[float, Range(0.0, 1.0)] = 3e-3
    """Adam step size of behaviour cloning."""
    learning_rate: Annotated[float, Range(0.0, 10.0)] = 1e-2
    """SGD step size of the Eq. 1 update, one step per feedback (the paper gives no value)."""

    def __post_init__(self) -> None:
        check_fields(self)


class FlatPolicy(nn.Module):
    """pi_theta(a|s): an MLP from the low-level state to logits over the actions (the displacements)."""

    def __init__(self, observation_size: int, n_actions: int, hidden: int) -> None:
        super().__init__()
        self.n_actions = n_actions
        self.net = nn.Sequential(
            nn.Linear(observation_size, hidden),
            nn.Tanh(),
            nn.Linear(hidden, hidden),
            nn.Tanh(),
            nn.Linear(hidden, n_actions),
        )

    def forward(self, s: torch.Tensor) -> torch.Tensor:
        return self.net(s)


def behaviour_cloning(
    observations: np.ndarray, actions: np.ndarray, n_actions: int, config: PretrainedCoachConfig, seed: int
) -> FlatPolicy:
    """Pretrain pi_theta over `n_actions` actions on the demonstrations (observations (n, size), actions
    (n,)) by maximum likelihood (cross-entropy), minibatches of 256."""
    generator = torch.Generator().manual_seed(seed)
    torch.manual_seed(seed)
    policy = FlatPolicy(observations.shape[1], n_actions, config.hidden)
    optimiser = adam(policy.parameters(), config.bc_learning_rate)
    s = torch.as_tensor(observations)
    a = torch.as_tensor(actions)
    for _ in range(config.bc_epochs):
        for batch in torch.randperm(len(s), generator=generator).split(256):
            loss = nn.functional.cross_entropy(policy(s[batch]), a[batch])
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
    return policy


class PretrainedCoach:
    """COACH on a pretrained flat policy, speaking ask/tell like `TabularCoach`."""

    def __init__(self, policy: FlatPolicy, config: PretrainedCoachConfig) -> None:
        self.policy = policy
        self.config = config
        self.parameters = list(policy.parameters())
        self.n_actions = policy.n_actions

    def probabilities(self, state: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            logits = self.policy(torch.as_tensor(state)[None])[0]
        return torch.softmax(logits.double(), 0).numpy()

    def act(self, state: np.ndarray, rng: np.random.Generator) -> int:
        """Sample a ~ pi(.|s), the exploration Eq. 1's expectation is over."""
        return int(rng.choice(self.n_actions, p=self.probabilities(state)))

    def ask(self, state: np.ndarray, action: int) -> FeedbackQuery:
        check_int("action", int(action), 0, self.n_actions - 1)
        return FeedbackQuery(state=tuple(float(v) for v in state), action=int(action))

    def tell(self, query: FeedbackQuery, feedback: int) -> None:
        """Eq. 1: one ascent step along grad log pi(a|s) * f."""
        f = validate_feedback(feedback)
        if f == 0:
            return
        s = torch.tensor(query.state, dtype=torch.float32)[None]
        log_pi = torch.log_softmax(self.policy(s)[0], 0)[query.action]
        gradient = torch.autograd.grad(log_pi, self.parameters)
        with torch.no_grad():
            for parameter, slope in zip(self.parameters, gradient, strict=True):
                parameter.add_(slope, alpha=self.config.learning_rate * f)

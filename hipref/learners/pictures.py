"""The myopic teacher's remembered picture as a hidden chain: what an answer says given the answers before it.

The myopic teacher (`hipref.teachers.models`) answers from a picture of the truth that it keeps between
answers: m_t = phi + R delta_t, the picture's error an AR(1) chain at its stationary spread s,

    delta_t = memory delta_{t-1} + s sqrt(1 - memory^2) z_t,    z_t ~ N(0, 1),

so its errors come in runs. `AnswerModel.probabilities` ('myopic') is the law of one answer alone; read as
independent, a run of answers from a picture that has drifted looks like evidence against every model with
graded errors, and a learner weighing models by their marginal likelihood moves to a flip rate near 1/2 (in
wiping the learner told nothing gave the myopic kind 6 % of its posterior after 200 answers, and its error
was 1.6 times told the model's). `PictureChain` keeps Pr(delta_t | phi, answers so far) on a grid of picture
errors for every cell of the posterior, the forward algorithm of a hidden Markov chain (Rabiner 1989), so
that each answer's likelihood is P(answer_t | phi, answers before t). With memory 0 it is the answer's
marginal law (up to the grid's resolution).

The chain's transition and starting law weigh the grid's points (bin centres); an answer's likelihood spreads
the picture uniformly over the point's bin: the answer is the candidate nearest the picture, with the share
of the bin in each candidate's interval, then the model's lapse and flip as for one answer alone. The grid
ends at SPAN spreads: an answer only a picture beyond it would give has probability 0, where the law of one
answer alone gives it at most the normal tail beyond SPAN spreads, 3e-5.
"""

from __future__ import annotations

import numpy as np

from hipref.learners.answer_models import AnswerModel
from hipref.learners.sysid import CandidateSet

BINS = 61
"""Points of the picture-error grid, 2 SPAN s / (BINS - 1) apart: one answer's probability read by a chain
without memory is then within 5e-4 of its marginal law (0.4 ms per answer and model, against 2-6 ms with
121 points, whose error is 7e-5)."""

SPAN = 4.0
"""The grid covers delta within this many stationary spreads s of zero (the chain's tails beyond: < 1e-4)."""


class PictureChain:
    """Pr(delta_t | phi, answers so far) per cell, for one myopic answer model with memory (module docstring).

    `step` gives an answer's likelihood per cell and the next state without keeping it; the posterior keeps
    the state once the answer is accepted (`hipref.learners.bayes.PreferencePosterior.update`)."""

    def __init__(self, model: AnswerModel, candidates: CandidateSet, cells: np.ndarray) -> None:
        if model.kind != "myopic" or model.memory <= 0:
            raise ValueError(f"a picture chain is for a myopic answer model with memory > 0, got {model!r}")
        self.model = model
        self.candidates = candidates
        self.cells = np.asarray(cells, dtype=np.float64)
        spread = model.spread
        self.errors = np.linspace(-SPAN * spread, SPAN * spread, BINS)
        """The picture errors delta, fractions of the range, the centres of equal bins."""
        self.width = self.errors[1] - self.errors[0]
        innovation = spread * np.sqrt(1.0 - model.memory**2)
        step = (self.errors[None, :] - model.memory * self.errors[:, None]) / innovation
        transition = np.exp(-0.5 * step**2)
        self.transition = transition / transition.sum(axis=1, keepdims=True)
        """Pr(delta_t = j | delta_{t-1} = i), rows summing to one."""
        stationary = np.exp(-0.5 * (self.errors / spread) ** 2)
        self.state = np.tile(stationary / stationary.sum(), (self.cells.size, 1))
        """Pr(delta_{t-1} | phi, the answers so far): (cells, BINS), rows summing to one."""

    def probabilities(self, candidates: np.ndarray) -> np.ndarray:
        """P(answer | phi, delta) for a query over `candidates`: (cells, BINS, N + 2), the columns of
        `AnswerModel.probabilities`."""
        values = np.sort(np.asarray(candidates, dtype=np.float64))
        order = np.argsort(np.asarray(candidates, dtype=np.float64))
        span = self.candidates.high - self.candidates.low
        # The picture offsets at which the nearest candidate changes, per cell: the sorted midpoints.
        bounds = ((values[1:] + values[:-1]) / 2.0)[None, :] - self.cells[:, None]
        lower = self.errors - self.width / 2.0
        below = np.clip((bounds[:, None, :] / span - lower[None, :, None]) / self.width, 0.0, 1.0)
        n = values.size
        shape = (*below.shape[:2], 1)
        mass = np.diff(np.concatenate([np.zeros(shape), below, np.ones(shape)], axis=-1), axis=-1)
        out = np.zeros((*below.shape[:2], n + 2))
        out[..., order] = mass
        return self.model.after_rule(out)

    def step(self, candidates: np.ndarray, column: int) -> tuple[np.ndarray, np.ndarray]:
        """For the answer `column` to a query over `candidates`: log P(answer | phi, answers before) per cell,
        and the state after it (the prediction alone where a cell cannot give the answer)."""
        predicted = self.state @ self.transition
        joint = predicted * self.probabilities(candidates)[..., column]
        total = joint.sum(axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            state = np.where(total[:, None] > 0, joint / total[:, None], predicted)
            return np.log(total), state

"""The evaluation of an SI run (section 5, 'Performance metrics'): at each checkpoint the learner is
frozen and evaluation episodes are run: SI's absolute error on a fresh probing slice (`param_error`, with
two other read-outs) and the success of the task executed with SI's estimate (`success_rate`).

Every method, noise level and N of one environment meets the same episodes (`evaluation_episodes`), built
once and cached, so comparisons between methods are paired.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from hipref.envs.task import Layout, Task, probe_slice
from hipref.experiments.si_clips import run_streams
from hipref.experiments.si_methods import Learner
from hipref.learners.sysid import SIModel
from hipref.sweep import cached_prefix


@dataclass(frozen=True)
class EvaluationSpec:
    """What a run's evaluation episodes depend on: not the method, the noise level, N or how many
    checkpoints the run has (checkpoint k is the same in a short run and a long one)."""

    domain: str
    ground_truth: float
    seed: int
    """The run's seed, whose `run_streams(seed, ground_truth).evaluation` seeds the evaluations."""
    eval_episodes: int
    slices: int
    history: int
    low_level: tuple[Any, ...] = ("admittance",)
    """The pi^l the probing rollouts execute (`LowLevel.key`)."""


class Episode(NamedTuple):
    """An evaluation episode: the probing slices SI estimates from, and the layout the task is then
    attempted in."""

    slices: np.ndarray
    """(slices, input_dim): the first drives the attempt; all of them the multi-slice estimate."""
    layout: Layout


def evaluation_episodes(task: Task, spec: EvaluationSpec, checkpoints: int) -> list[list[Episode]]:
    """Per checkpoint, its evaluation episodes, drawn from the checkpoint's own seed (child k of the run's
    evaluation stream). Every method, noise level and N of one environment meets the same episodes, so
    they are built once (cached, and shared with studies of fewer checkpoints) and the methods' runs
    differ only in what SI makes of them: comparisons between methods are paired."""

    def build(count: int) -> list[list[Episode]]:
        built = []
        for seq in run_streams(spec.seed, spec.ground_truth).evaluation.spawn(count):
            rng = np.random.default_rng(seq)
            episodes = []
            for _ in range(spec.eval_episodes):
                taus = [probe_slice(task, spec.ground_truth, spec.history, rng) for _ in range(spec.slices)]
                episodes.append(Episode(np.stack(taus), task.sample_layout(rng)))
            built.append(episodes)
        return built

    def complete(episodes: list[Episode]) -> bool:
        return len(episodes) == spec.eval_episodes and all(len(e.slices) == spec.slices for e in episodes)

    return cached_prefix(f"si_evaluation_{spec.domain}", spec, checkpoints, build, check=complete)


class Estimator(NamedTuple):
    """How a learner estimates phi from slices: E[phi] on each, and the most probable value on one."""

    expectations: Callable[[np.ndarray], np.ndarray]
    mode: Callable[[np.ndarray], float]


def estimator(learner: Learner | None, model: SIModel) -> Estimator:
    """The learner's read-outs (a PESI learner's fine-tuned SI, or the Bayesian learner's posterior), or,
    without a learner (OSI), the pretrained `model`'s."""
    if learner is None:
        return Estimator(model.predict, lambda tau: float(model.predict_mode(tau)))
    return Estimator(learner.estimates, learner.mode)


def at_truth(ground_truth: float) -> Estimator:
    """The true parameter itself as the estimate: what an exact estimate achieves on the same episodes (the
    task can fail even so)."""
    return Estimator(lambda slices: np.full(len(slices), ground_truth), lambda tau: ground_truth)


def evaluate(task: Task, model: Estimator, episodes: list[Episode], ground_truth: float) -> dict[str, float]:
    """A frozen learner on one checkpoint's episodes: its errors by three read-outs, and the task's success.

    param_error: |E_Pr[phi] - phi| on the first slice, the estimate the controller is given and the task
    attempted with (success_rate). param_error_argmax: the most probable candidate instead of the mean.
    param_error_multislice: the mean of E_Pr[phi] over all the episode's slices, less sensitive to one
    unlucky slice.
    """
    errors: dict[str, list[float]] = {
        "param_error": [],
        "param_error_argmax": [],
        "param_error_multislice": [],
    }
    successes = []
    for episode in episodes:
        expectations = model.expectations(episode.slices)
        phi_hat = float(expectations[0])
        errors["param_error"].append(abs(phi_hat - ground_truth))
        errors["param_error_argmax"].append(abs(model.mode(episode.slices[0]) - ground_truth))
        errors["param_error_multislice"].append(abs(float(expectations.mean()) - ground_truth))
        successes.append(task.rollout(ground_truth, phi_hat, episode.layout).success)
    return {**{k: float(np.mean(v)) for k, v in errors.items()}, "success_rate": float(np.mean(successes))}

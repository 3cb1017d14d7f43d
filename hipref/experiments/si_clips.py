"""What the learning episodes of every run in one environment share: the environment's random streams
(`run_streams`) and, when candidates are drawn uniformly, the clips its queries observe (`learning_clips`).

Which estimate drives the slices. In a learning episode the candidates are drawn uniformly from Phi (or,
as an option, from SI's belief) and tau is a slice of the clip pi^l executes with one of them, every
candidate's clip starting from the same layout (PESILearner.ask, `hipref.envs.task.clip`). Uniformly drawn
queries do not depend on what SI has learnt, so one environment's clips are executed once and replayed by
every method and noise level (`learning_clips`). Every slice SI is evaluated on, and every slice of
Algorithm 4's data, comes from a probing rollout that pi^l executes with an estimate drawn uniformly from
the range (`hipref.experiments.si_evaluation`): OSI is evaluated on the inputs it was trained for.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from hipref.envs.task import Clip, Task, observer
from hipref.learners.pesi import PESIConfig, PESILearner
from hipref.learners.sysid import SIModel
from hipref.seeds import integer_seed
from hipref.sweep import cached_prefix


class RunStreams(NamedTuple):
    """A run's independent random streams, children of its (seed, ground truth) SeedSequence."""

    teacher: np.random.SeedSequence
    learner: np.random.SeedSequence
    learning: np.random.SeedSequence
    evaluation: np.random.SeedSequence


def run_streams(seed: int, ground_truth: float) -> RunStreams:
    """The streams of the environment (seed, ground truth): two truths of a grid never share draws."""
    micro = round(ground_truth * 1_000_000)
    return RunStreams(*np.random.SeedSequence([seed, micro]).spawn(4))


@dataclass(frozen=True)
class LearningSpec:
    """What the clips of a run's learning episodes depend on when its candidates are drawn uniformly: not
    the method, the noise level, how SI is fine-tuned or how many episodes the run has (episode k's clip is
    the same in a short run and a long one)."""

    domain: str
    ground_truth: float
    seed: int
    """The run's seed; with the ground truth it seeds the learner's queries and the layouts."""
    n_candidates: int
    history: int
    low_level: tuple[Any, ...] = ("admittance",)
    """The pi^l the clips execute (`LowLevel.key`)."""


def learning_clips(task: Task, spec: LearningSpec, episodes: int, model: SIModel) -> list[Clip]:
    """Per learning episode, the clip its query observes, executed once per environment (cached).

    With candidates drawn uniformly from Phi (Algorithm 2), what a learner asks never depends on what SI has
    learnt or on the answers: the candidates, the layout and the slice's place come from the run's own
    streams. So every method, noise level and fine-tuning of one environment executes the same clips, and
    they are executed once, by a learner that only asks; runs replay them (`Clip.replay`) with their own
    learners, whose queries are checked against them. The rows are those of executing every run's clips.
    A study with fewer episodes replays the first clips of a longer one.
    """

    def build(count: int) -> list[Clip]:
        truth, h = spec.ground_truth, spec.history
        _, learner_seq, learn_seq, _ = run_streams(spec.seed, truth)
        config = PESIConfig(n_candidates=spec.n_candidates, history=spec.history)
        asker = PESILearner(model, config, integer_seed(learner_seq))
        learn_rng = np.random.default_rng(learn_seq)
        clips: list[Clip] = []
        for _ in range(count):
            layout = task.sample_layout(learn_rng)
            asker.ask(observer(task, truth, layout, h, clips))
        return clips

    return cached_prefix(
        f"si_learning_{spec.domain}", spec, episodes, build, check=lambda item: isinstance(item, Clip)
    )

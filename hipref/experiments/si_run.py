"""One SI run (`run_si`, a sweep cell) in one environment with a fixed, unknown parameter phi: Algorithm 2.

    for i <- 0, 1, 2, ... do
        Execute policy pi^l_phi with phi_0, phi_1 sampled from Phi
        Sample trajectory slice tau
        Ask for human preference y
        Update system identification model SI by Eqn. 2
    end for

Each learning episode samples N candidates, executes the low-level policy pi^l with each in the world,
samples a trajectory slice tau of h control periods, gets the scripted teacher's (possibly flipped)
preference and tells the learner, which updates SI (Eq. 2, Eq. 3 or the standard cross-entropy of A.8;
Algorithm 1 for CO-PESI). OSI (`si_pretraining`) learns nothing. The methods' learners are built in
`hipref.experiments.si_methods`; the clips the queries observe are shared by every run of an environment
(`hipref.experiments.si_clips`); at episode 0 and every 33 learning episodes the learner is frozen and
evaluated (`hipref.experiments.si_evaluation`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Annotated

import numpy as np
import pandas as pd

from hipref.envs.task import Task, observer
from hipref.experiments.domains import domain_spec
from hipref.experiments.low_level import make_task
from hipref.experiments.si_clips import LearningSpec, learning_clips, run_streams
from hipref.experiments.si_evaluation import (
    EvaluationSpec,
    at_truth,
    estimator,
    evaluate,
    evaluation_episodes,
)
from hipref.experiments.si_methods import BAYES_METHODS, METHODS, PAIR_METHODS, Learner, make_learner
from hipref.experiments.si_pretraining import PretrainData, pretrained_model
from hipref.learners.answer_models import TOLD
from hipref.learners.pesi import PESIConfig
from hipref.learners.queries import CHOSEN
from hipref.learners.sysid import SIModel
from hipref.numerics import one_thread
from hipref.results import tidy_rows
from hipref.seeds import integer_seed
from hipref.sweep import cached_prefix
from hipref.teachers.models import TeacherModel
from hipref.teachers.preference import ScriptedPreferenceTeacher
from hipref.validation import Integer, OneOf, Range, check_fields, check_int, check_range

COTEACHING_SCHEDULES: tuple[str, ...] = ("learned", "reset_every_step")
"""How CO-PESI's classifiers are refreshed (`hipref.learners.coteaching.CoTeaching`): 'learned', the
refresh counted in preferences with several classifier rounds per preference (default); 'reset_every_step',
the refresh counted in single co-teaching steps with one round each, under which the classifiers are reset
before they can learn the (pair -> label) rule."""


RUN_SET: tuple[str, ...] = ("loss", "batch_size", "start_size", "n_candidates", "history")
"""The PESI settings a run sets itself: the loss (the method's), the batch size and s (the domain's), N
(`SIRun.n_candidates`) and h (the data's)."""


@dataclass(frozen=True)
class FineTuning:
    """How preferences fine-tune SI (Algorithm 2, Eq. 2/3; Algorithm 1 for CO-PESI): the paper's reading by
    default, the alternatives a sensitivity study compares (notebook 08)."""

    pesi: PESIConfig = PESIConfig()  # noqa: RUF009 - frozen, so a shared default is safe
    """The learner's settings (`hipref.learners.pesi.PESIConfig`: p, the learning rate, the query rule, the
    domain of Pr, the parameters fine-tuned); those of RUN_SET keep their defaults, the run sets them."""
    coteaching_schedule: Annotated[str, OneOf(COTEACHING_SCHEDULES)] = "learned"
    """CO-PESI's classifier schedule, one of COTEACHING_SCHEDULES."""

    def __post_init__(self) -> None:
        check_fields(self)
        if not isinstance(self.pesi, PESIConfig):
            raise ValueError(f"pesi must be a PESIConfig, got {self.pesi!r}")
        for name in RUN_SET:
            if getattr(self.pesi, name) != getattr(PESIConfig, name):
                raise ValueError(f"pesi.{name} is set by the run, got {getattr(self.pesi, name)!r}")


def check_evaluations(episodes: int, eval_every: int) -> None:
    """Raise ValueError unless evaluations every `eval_every` learning episodes end on the last one: the
    episodes after the last evaluation would be learnt by no learner that is evaluated."""
    check_int("eval_every", eval_every, 1, episodes)
    if episodes % eval_every:
        raise ValueError(
            f"episodes must be a multiple of eval_every={eval_every} (the last evaluation is after the last "
            f"episode), got {episodes}"
        )


@dataclass(frozen=True)
class SIRun:
    """One run (one sweep cell): a method fine-tuning SI in one environment with a fixed true parameter."""

    domain: str
    """'wiping' (desk height) or 'pushing' (cube mass)."""
    method: Annotated[str, OneOf(METHODS)]
    """One of METHODS."""
    ground_truth: float
    """The environment's true parameter, inside the domain's range."""
    noise: Annotated[float, Range(0.0, 1.0)] = 0.0
    """Fraction of flipped preferences, in [0, 1]."""
    seed: Annotated[int, Integer(0)] = 0
    """Seed of the teacher, the learner and the evaluation, together with the ground truth: the same seed
    and truth give every method the same teacher draws and the same evaluation episodes."""
    n_candidates: int = 2
    """N, candidates per query (Eq. 3, A.2); CO-PESI needs 2."""
    episodes: Annotated[int, Integer(1)] = 66
    """Learning episodes (preferences asked), at least 1: two evaluation periods of 33 by default, the quick
    profile's (the full profile: 330 in notebooks 02-04, 198 in 06 and 07, 99 in 08, 10 and 11)."""
    eval_every: int = 33
    """Learning episodes between evaluations (section 5: 33), dividing `episodes` (without `checkpoints`)."""
    eval_episodes: Annotated[int, Integer(1)] = 10
    """Evaluation episodes per evaluation (section 5: 10)."""
    eval_slices: Annotated[int, Integer(1)] = 3
    """Probing slices per evaluation episode; the first drives the task attempt, all of them the
    multi-slice estimate."""
    fine_tuning: FineTuning = FineTuning()
    """How preferences update SI."""
    data: PretrainData = PretrainData()
    """Algorithm 4's data and pretraining, shared by every run with the same value."""
    teacher: TeacherModel = TeacherModel()  # noqa: RUF009 - frozen, so a shared default is safe
    """The scripted teacher's model (`hipref.teachers.models`); the paper's uniform flip of rate `noise`
    by default. Its rows carry a `teacher` column unless it is the default."""
    told: Annotated[str, OneOf(TOLD)] = "nothing"
    """'bayes' only: what the learner is told of the teacher (`hipref.learners.answer_models.TOLD`): its
    'model', its 'kind', or 'nothing' (every model weighed by its marginal likelihood)."""
    checkpoints: tuple[int, ...] = ()
    """Learning episodes after which the learner is evaluated, increasing, from 0 to `episodes`; empty:
    every `eval_every` (section 5)."""

    def __post_init__(self) -> None:
        check_fields(self)
        spec = domain_spec(self.domain)
        check_range("ground_truth", self.ground_truth, spec.candidates.low, spec.candidates.high)
        check_int("n_candidates", self.n_candidates, 2, spec.candidates.size)
        if self.method in PAIR_METHODS and self.n_candidates != 2:
            raise ValueError(
                f"n_candidates must be 2 for {self.method} (pairs only), got {self.n_candidates}"
            )
        if not isinstance(self.teacher, TeacherModel):
            raise ValueError(f"teacher must be a TeacherModel, got {self.teacher!r}")
        if self.teacher.kind == "oracle" and self.noise != 0:
            raise ValueError(f"noise must be 0 with the 'oracle' teacher, got {self.noise!r}")
        if self.teacher.kind == "distance" and self.n_candidates != 2:
            raise ValueError(f"n_candidates must be 2 for the 'distance' teacher, got {self.n_candidates}")
        if not self.checkpoints:
            check_evaluations(self.episodes, self.eval_every)
        if self.told != "nothing" and self.method not in BAYES_METHODS:
            raise ValueError(f"told is for the 'bayes' method, got method {self.method!r}")
        if self.method in BAYES_METHODS and self.fine_tuning.pesi.candidate_sampling == "belief":
            raise ValueError(
                "candidate_sampling 'belief' is PESI's; the 'bayes' method takes 'uniform' or a rule"
            )
        for checkpoint in self.checkpoints:
            check_int("checkpoints", checkpoint, 0, self.episodes)
        if list(self.checkpoints) != sorted(set(self.checkpoints)):
            raise ValueError(f"checkpoints must be increasing and distinct, got {self.checkpoints!r}")

    @property
    def evaluated_at(self) -> tuple[int, ...]:
        """The learning episodes after which the learner is evaluated."""
        return self.checkpoints or tuple(range(0, self.episodes + 1, self.eval_every))


Observe = Callable[[float, np.random.Generator], np.ndarray]
"""What a learner's query executes: pi^l with a candidate phi, returning a slice tau cut with the rng."""


def algorithm_2(
    learner: Learner, teacher: ScriptedPreferenceTeacher, observe: Callable[[int], Observe], episodes: range
) -> None:
    """Algorithm 2 (module docstring) over the learning episodes `episodes`:

        for i in episodes do
            Execute policy pi^l_phi with phi_0, phi_1 sampled from Phi   } learner.ask(observe(i))
            Sample trajectory slice tau                                  }
            Ask for human preference y                                   teacher.answer
            Update system identification model SI by Eqn. 2              learner.tell
        end for

    `observe(i)` executes pi^l in episode i's world (a stored clip replayed, or a fresh layout).
    """
    for i in episodes:
        query = learner.ask(observe(i))
        learner.tell(query, teacher.answer(query))


def _teacher(cell: SIRun, teacher_seq: np.random.SeedSequence) -> ScriptedPreferenceTeacher:
    phi = domain_spec(cell.domain).candidates
    return ScriptedPreferenceTeacher(
        cell.ground_truth,
        cell.noise,
        np.random.default_rng(teacher_seq),
        cell.teacher,
        scale=phi.high - phi.low,
        bounds=(phi.low, phi.high),
    )


def _observer(
    cell: SIRun, task: Task, model: SIModel, learn_seq: np.random.SeedSequence
) -> Callable[[int], Observe]:
    """Episode i's execution of pi^l: with uniform candidates, the clips every run of the environment
    shares (`learning_clips`: the Bayesian learner draws uniform queries as PESI does, so the same clips),
    replayed; otherwise (or without clips) a fresh layout from the run's own stream, executed."""
    h = cell.data.history
    clips = None
    if cell.fine_tuning.pesi.candidate_sampling == "uniform":
        learning = LearningSpec(
            cell.domain, cell.ground_truth, cell.seed, cell.n_candidates, h, cell.data.low_level.key
        )
        clips = learning_clips(task, learning, cell.episodes, model)
    if clips is not None:
        return lambda i: clips[i].replayer(h)
    learn_rng = np.random.default_rng(learn_seq)
    return lambda i: observer(task, cell.ground_truth, task.sample_layout(learn_rng), h)


Evaluation = list[tuple[int, str, float]]
"""One evaluation's rows: (learning episodes so far, metric, value)."""


def _evaluation_spec(cell: SIRun) -> EvaluationSpec:
    return EvaluationSpec(
        cell.domain,
        cell.ground_truth,
        cell.seed,
        cell.eval_episodes,
        cell.eval_slices,
        cell.data.history,
        cell.data.low_level.key,
    )


def _learn_and_evaluate(cell: SIRun) -> list[Evaluation]:
    """Algorithm 2 between the evaluations of `cell`, and each evaluation's rows."""
    model = pretrained_model(cell.domain, cell.data)
    with one_thread():
        teacher_seq, learner_seq, learn_seq, _ = run_streams(cell.seed, cell.ground_truth)
        truth = cell.ground_truth
        task = make_task(cell.domain, cell.data.low_level)
        teacher = _teacher(cell, teacher_seq)
        learner = make_learner(cell, model, integer_seed(learner_seq))
        evaluated_at = cell.evaluated_at
        checkpoints = evaluation_episodes(task, _evaluation_spec(cell), len(evaluated_at))
        observe = None if learner is None else _observer(cell, task, model, learn_seq)
        evaluations: list[Evaluation] = []
        learned = 0
        for episode, episodes in zip(evaluated_at, checkpoints, strict=True):
            if learner is not None and observe is not None:
                algorithm_2(learner, teacher, observe, range(learned, episode))
                learned = episode
            metrics = evaluate(task, estimator(learner, model), episodes, truth)
            quality = None if learner is None else learner.filter_precision_recall(teacher.wrong_labels)
            if quality is not None:
                metrics |= {"filter_precision": quality[0], "filter_recall": quality[1]}
            evaluations.append([(episode, k, v) for k, v in metrics.items() if np.isfinite(v)])
    return evaluations


def run_at_truth(cell: SIRun) -> pd.DataFrame:
    """The task executed with the true parameter on `cell`'s evaluation episodes, at each of its
    evaluations (a sweep cell function; rows of method 'true_parameter', noise NaN: no teacher is asked):
    the success an exact estimate gets on the very episodes every learner of the environment meets. Only
    the cell's environment and evaluations are read."""
    with one_thread():
        task = make_task(cell.domain, cell.data.low_level)
        checkpoints = evaluation_episodes(task, _evaluation_spec(cell), len(cell.evaluated_at))
        exact = at_truth(cell.ground_truth)
        rows = [
            (episode, metric, value)
            for episode, episodes in zip(cell.evaluated_at, checkpoints, strict=True)
            for metric, value in evaluate(task, exact, episodes, cell.ground_truth).items()
        ]
    return tidy_rows(
        rows,
        domain=cell.domain,
        method="true_parameter",
        noise=np.nan,
        seed=cell.seed,
        ground_truth=round(cell.ground_truth, 6),
        n_candidates=cell.n_candidates,
    )


def run_si(cell: SIRun) -> pd.DataFrame:
    """One run of `cell` (a sweep cell function): tidy rows of every metric per evaluation.

    Between evaluations the learner learns by `algorithm_2`; at each, it is frozen and evaluated
    (`hipref.experiments.si_evaluation`). Learners with a filter (`filter_precision_recall` not None) also
    report its precision and recall against the flips the scripted teacher recorded (never shown to the
    learner), counted over the learning so far.

    A run's first k evaluations do not depend on how many episodes follow them (its clips and evaluation
    episodes are prefixes of a longer run's, its learner and teacher draw from their own streams), so runs
    evaluated every `eval_every` episodes are cached by `cached_prefix`: a study with fewer episodes reads
    the first evaluations of a longer run of the same environment, method and setting instead of
    learning again.
    """
    count = len(cell.evaluated_at)
    if cell.checkpoints:
        evaluations = _learn_and_evaluate(cell)
    else:
        evaluations = cached_prefix(
            "si_run",
            replace(cell, episodes=cell.eval_every),
            count,
            lambda n: _learn_and_evaluate(replace(cell, episodes=(n - 1) * cell.eval_every)),
            check=lambda item: isinstance(item, list),
        )
    rows = [row for evaluation in evaluations for row in evaluation]
    low_level = cell.data.low_level.key
    return tidy_rows(
        rows,
        domain=cell.domain,
        method=cell.method,
        noise=cell.noise,
        seed=cell.seed,
        ground_truth=round(cell.ground_truth, 6),
        n_candidates=cell.n_candidates,
        **({} if cell.teacher == TeacherModel() else {"teacher": cell.teacher.name}),
        **({} if low_level == ("admittance",) else {"low_level": cell.data.low_level.kind}),
        **(
            {"query_rule": cell.fine_tuning.pesi.candidate_sampling}
            if cell.fine_tuning.pesi.candidate_sampling in CHOSEN
            else {}
        ),
        **({"told": cell.told} if cell.told != "nothing" else {}),
    )

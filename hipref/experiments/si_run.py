"""One SI run (`run_si`, a sweep cell) in one environment with a fixed, unknown parameter phi.

- Algorithm 2: each learning episode samples N candidates, executes the low-level policy pi^l with each
  in the world, samples a trajectory slice tau of h control periods, gets the scripted teacher's
  (possibly flipped) preference and tells the learner, which updates SI (Eq. 2, Eq. 3 or the standard
  cross-entropy of A.8; Algorithm 1 for CO-PESI). OSI (`si_pretraining`) learns nothing.
- Evaluation (section 5, 'Performance metrics'): at episode 0 and every 33 learning episodes the learner is
  frozen and 10 evaluation episodes are run: SI's absolute error on a fresh slice (`param_error`, with two
  other read-outs) and the success of the task executed with SI's estimate (`success_rate`).

Which estimate drives the slices. In a learning episode the candidates are drawn uniformly from Phi (or,
as an option, from SI's belief) and tau is a slice of the clip pi^l executes with one of them, every
candidate's clip starting from the same layout (PESILearner.ask, `hipref.envs.task.clip`). Uniformly drawn
queries do not depend on what SI has learnt, so one environment's clips are executed once and replayed by
every method and noise level (`learning_clips`). Every slice SI is evaluated on, and every slice of
Algorithm 4's data, comes from a probing rollout that pi^l executes with an estimate drawn uniformly from
the range: OSI is evaluated on the inputs it was trained for.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import pandas as pd

from hipref.envs.task import Clip, Layout, Task, observer, probe_slice
from hipref.experiments.domains import domain_spec
from hipref.experiments.low_level import make_task
from hipref.experiments.si_pretraining import PretrainData, pretrained_model
from hipref.learners.answer_models import TOLD, hypotheses
from hipref.learners.bayes import BayesConfig, BayesLearner
from hipref.learners.coteaching import (
    CoPESIConfig,
    CoPESILearner,
    EstimatedNoiseCoPESILearner,
    reset_every_step_schedule,
)
from hipref.learners.pesi import CANDIDATE_SAMPLING, FINE_TUNED, PR_DOMAINS, PESIConfig, PESILearner
from hipref.learners.queries import CHOSEN
from hipref.learners.robust import (
    LabelSmoothingPESILearner,
    LikelihoodNoiseCoPESILearner,
    RobustPESIConfig,
    SmallLossPESILearner,
    TrustFlipPESILearner,
    UnbiasedPESILearner,
)
from hipref.learners.sysid import SIModel
from hipref.numerics import one_thread
from hipref.results import tidy_rows
from hipref.seeds import integer_seed
from hipref.sweep import cached_prefix
from hipref.teachers.models import TeacherModel
from hipref.teachers.preference import ScriptedPreferenceTeacher
from hipref.validation import check_choice, check_int, check_range

COTEACHING_SCHEDULES: tuple[str, ...] = ("learned", "reset_every_step")
"""How CO-PESI's classifiers are refreshed (`hipref.learners.coteaching.CoPESIConfig`): 'learned', the
refresh counted in preferences with several classifier rounds per preference (default); 'reset_every_step',
the refresh counted in single co-teaching steps with one round each, under which the classifiers are reset
before they can learn the (pair -> label) rule."""


@dataclass(frozen=True)
class FineTuning:
    """How preferences fine-tune SI (Algorithm 2, Eq. 2/3; Algorithm 1 for CO-PESI): the paper's reading by
    default, the alternatives a sensitivity study compares (notebook 08)."""

    learning_rate: float = 1e-2
    """Plain gradient step size of SI fine-tuning (A.7: 0.01)."""
    encourage_percentage: float = 0.25
    """p of Eq. 2 (A.7: 0.25)."""
    candidate_sampling: str = "uniform"
    """'uniform' (Algorithm 2: 'sampled from Phi'), 'belief' (from SI's current distribution) or a query
    rule of `hipref.learners.queries` ('thompson', 'information_gain', 'volume_removal'); the Bayesian
    learner takes 'uniform' or a rule."""
    pr_domain: str = "query"
    """Pr of Eq. 2 over the queried candidates ('query') or all of Phi ('all')."""
    fine_tuned: str = "all"
    """Which parameters of SI are updated: 'all', 'last_layer' or 'output_bias'."""
    coteaching_schedule: str = "learned"
    """CO-PESI's classifier schedule, one of COTEACHING_SCHEDULES."""

    def __post_init__(self) -> None:
        check_range("learning_rate", self.learning_rate, 1e-8, 1.0)
        check_range("encourage_percentage", self.encourage_percentage, 0.0, 1.0)
        check_choice("candidate_sampling", self.candidate_sampling, CANDIDATE_SAMPLING)
        check_choice("pr_domain", self.pr_domain, PR_DOMAINS)
        check_choice("fine_tuned", self.fine_tuned, FINE_TUNED)
        check_choice("coteaching_schedule", self.coteaching_schedule, COTEACHING_SCHEDULES)


@dataclass(frozen=True)
class SIRun:
    """One run (one sweep cell): a method fine-tuning SI in one environment with a fixed true parameter."""

    domain: str
    """'wiping' (desk height) or 'pushing' (cube mass)."""
    method: str
    """One of METHODS."""
    ground_truth: float
    """The environment's true parameter, inside the domain's range."""
    noise: float = 0.0
    """Fraction of flipped preferences, in [0, 1]."""
    seed: int = 0
    """Seed of the teacher, the learner and the evaluation, together with the ground truth: the same seed
    and truth give every method the same teacher draws and the same evaluation episodes."""
    n_candidates: int = 2
    """N, candidates per query (Eq. 3, A.2); CO-PESI needs 2."""
    episodes: int = 99
    """Learning episodes (preferences asked), at least 1."""
    eval_every: int = 33
    """Learning episodes between evaluations (section 5: 33)."""
    eval_episodes: int = 10
    """Evaluation episodes per evaluation (section 5: 10)."""
    eval_slices: int = 3
    """Probing slices per evaluation episode; the first drives the task attempt, all of them the
    multi-slice estimate."""
    fine_tuning: FineTuning = FineTuning()
    """How preferences update SI."""
    data: PretrainData = PretrainData()
    """Algorithm 4's data and pretraining, shared by every run with the same value."""
    teacher: TeacherModel = TeacherModel()  # noqa: RUF009 - frozen, so a shared default is safe
    """The scripted teacher's model (`hipref.teachers.models`); the paper's uniform flip of rate `noise`
    by default. Its rows carry a `teacher` column unless it is the default."""
    told: str = "nothing"
    """'bayes' only: what the learner is told of the teacher (`hipref.learners.answer_models.TOLD`): its
    'model', its 'kind', or 'nothing' (every model weighed by its marginal likelihood)."""
    checkpoints: tuple[int, ...] = ()
    """Learning episodes after which the learner is evaluated, increasing, from 0 to `episodes`; empty:
    every `eval_every` (section 5)."""

    def __post_init__(self) -> None:
        spec = domain_spec(self.domain)
        check_choice("method", self.method, METHODS)
        check_range("ground_truth", self.ground_truth, spec.candidates.low, spec.candidates.high)
        check_range("noise", self.noise, 0.0, 1.0)
        check_int("seed", self.seed, 0)
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
        check_int("episodes", self.episodes, 1)
        if not self.checkpoints:
            check_int("eval_every", self.eval_every, 1, self.episodes)
        check_int("eval_episodes", self.eval_episodes, 1)
        check_int("eval_slices", self.eval_slices, 1)
        check_choice("told", self.told, TOLD)
        if self.told != "nothing" and self.method not in ("bayes", "bayes_si"):
            raise ValueError(f"told is for the 'bayes' method, got method {self.method!r}")
        if self.method.startswith("bayes") and self.fine_tuning.candidate_sampling == "belief":
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


Learner = PESILearner | BayesLearner
"""What a method's learner is: PESI (and the learners built on it) or the Bayesian learner."""

LearnerBuilder = Callable[["SIRun", SIModel, dict[str, Any], int], "Learner | None"]
"""Builds a method's learner from the cell, the pretrained model, the PESI settings every method shares
(`common`) and the learner's seed; None for a method that learns nothing."""


def _coteaching_config(cell: SIRun, common: dict[str, Any]) -> CoPESIConfig:
    spec = domain_spec(cell.domain)
    learned = cell.fine_tuning.coteaching_schedule == "learned"
    schedule = CoPESIConfig if learned else reset_every_step_schedule
    return schedule(start_size=spec.batch_size, refresh_frequency=spec.refresh_frequency, **common)


def _bayes_config(cell: SIRun) -> BayesConfig:
    models = hypotheses(cell.teacher, cell.noise, cell.told)
    return BayesConfig(cell.n_candidates, cell.fine_tuning.candidate_sampling, models)


def _robust_config(cell: SIRun, common: dict[str, Any]) -> RobustPESIConfig:
    return RobustPESIConfig(start_size=domain_spec(cell.domain).batch_size, **common)


LEARNERS: dict[str, LearnerBuilder] = {
    "osi": lambda cell, model, common, seed: None,
    "pesi": lambda cell, model, common, seed: PESILearner(model, PESIConfig(loss="soft", **common), seed),
    "pesi_ce": lambda cell, model, common, seed: PESILearner(
        model, PESIConfig(loss="standard", **common), seed
    ),
    "co_pesi": lambda cell, model, common, seed: CoPESILearner(
        model, cell.noise, _coteaching_config(cell, common), seed
    ),
    # A.9: the forget number comes from Algorithm 5 on the preferences so far, not the true noise.
    "co_pesi_estimated": lambda cell, model, common, seed: EstimatedNoiseCoPESILearner(
        model, _coteaching_config(cell, common), seed
    ),
    "pesi_smoothed": lambda cell, model, common, seed: LabelSmoothingPESILearner(
        model, _robust_config(cell, common), seed
    ),
    "pesi_unbiased": lambda cell, model, common, seed: UnbiasedPESILearner(
        model, _robust_config(cell, common), seed
    ),
    "pesi_small_loss": lambda cell, model, common, seed: SmallLossPESILearner(
        model, _robust_config(cell, common), seed
    ),
    "pesi_rime": lambda cell, model, common, seed: TrustFlipPESILearner(
        model, _robust_config(cell, common), seed
    ),
    "co_pesi_likelihood": lambda cell, model, common, seed: LikelihoodNoiseCoPESILearner(
        model, _coteaching_config(cell, common), seed
    ),
    "bayes": lambda cell, model, common, seed: BayesLearner(
        model.candidates, _bayes_config(cell), seed, si_model=model
    ),
    "bayes_si": lambda cell, model, common, seed: BayesLearner(
        model.candidates, dataclasses.replace(_bayes_config(cell), prior="si"), seed, si_model=model
    ),
}
"""Every method by name. osi: pretrained, no preferences; pesi: Eq. 2/3; pesi_ce: standard cross-entropy
(A.8); co_pesi: Algorithm 1 told the true noise level; co_pesi_estimated: Algorithm 1 with the noise level
estimated by Algorithm 5 from the preferences so far (A.9). Beyond the paper (`hipref.learners.robust`):
pesi_smoothed: label smoothing of Eq. 2 (conservative); pesi_unbiased: the unbiased loss with the estimated
flip rate; pesi_small_loss: SI's own small-loss filter; pesi_rime: RIME's trust-and-flip; co_pesi_likelihood:
Algorithm 1 with the maximum marginal likelihood flip rate; bayes: the exact posterior over phi from every
answer (`hipref.learners.bayes`), its model of the teacher chosen by marginal likelihood unless told;
bayes_si: that posterior times SI's Pr(phi | tau) on the slice estimated from, so OSI's knowledge is kept."""

METHODS: tuple[str, ...] = tuple(LEARNERS)
"""The methods' names, in LEARNERS' order."""

PAIR_METHODS: frozenset[str] = frozenset(METHODS) - {"osi", "pesi", "pesi_ce", "bayes", "bayes_si"}
"""Methods defined on pairs only (N = 2): classifiers of pairs, or losses mixing y and -y."""


def make_learner(cell: SIRun, model: SIModel, seed: int) -> Learner | None:
    """The learner of `cell.method` on a copy of the pretrained model; None for OSI (no updates)."""
    spec = domain_spec(cell.domain)
    tuning = cell.fine_tuning
    common = dict(
        encourage_percentage=tuning.encourage_percentage,
        learning_rate=tuning.learning_rate,
        batch_size=spec.batch_size,
        n_candidates=cell.n_candidates,
        history=cell.data.history,
        candidate_sampling=tuning.candidate_sampling,
        pr_domain=tuning.pr_domain,
        fine_tuned=tuning.fine_tuned,
    )
    return LEARNERS[cell.method](cell, model, common, seed)


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


class Estimator(NamedTuple):
    """How a learner estimates phi from slices: E[phi] on each, and the most probable value on one."""

    expectations: Callable[[np.ndarray], np.ndarray]
    mode: Callable[[np.ndarray], float]


def estimator(learner: Learner | SIModel) -> Estimator:
    """SI's read-outs (OSI, and every PESI learner's fine-tuned SI), or the Bayesian learner's."""
    if isinstance(learner, BayesLearner):
        return Estimator(learner.estimates, learner.mode)
    model = learner if isinstance(learner, SIModel) else learner.model
    return Estimator(model.predict, lambda tau: float(model.predict_mode(tau)))


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


def run_si(cell: SIRun) -> pd.DataFrame:
    """One run of `cell` (a sweep cell function): tidy rows of every metric per evaluation.

    CO-PESI runs also report the precision and recall of their filter against the flips the scripted
    teacher recorded (never shown to the learner), counted over the learning so far.
    """
    model = pretrained_model(cell.domain, cell.data)
    with one_thread():
        teacher_seq, learner_seq, learn_seq, _ = run_streams(cell.seed, cell.ground_truth)
        truth = cell.ground_truth
        task = make_task(cell.domain, cell.data.low_level)
        phi = domain_spec(cell.domain).candidates
        teacher = ScriptedPreferenceTeacher(
            truth,
            cell.noise,
            np.random.default_rng(teacher_seq),
            cell.teacher,
            scale=phi.high - phi.low,
            bounds=(phi.low, phi.high),
        )
        learner = make_learner(cell, model, integer_seed(learner_seq))
        learn_rng = np.random.default_rng(learn_seq)
        h = cell.data.history
        evaluated_at = cell.evaluated_at
        n_checkpoints = len(evaluated_at)
        low_level = cell.data.low_level.key
        spec = EvaluationSpec(
            cell.domain, truth, cell.seed, cell.eval_episodes, cell.eval_slices, h, low_level
        )
        checkpoints = evaluation_episodes(task, spec, n_checkpoints)
        clips = None
        if learner is not None and cell.fine_tuning.candidate_sampling == "uniform":
            # The Bayesian learner draws uniform queries as PESI does: the same clips, replayed.
            learning = LearningSpec(cell.domain, truth, cell.seed, cell.n_candidates, h, low_level)
            clips = learning_clips(task, learning, cell.episodes, model)
        rows: list[tuple[int, str, float]] = []
        for episode in range(cell.episodes + 1):
            if episode in evaluated_at:
                current = estimator(model if learner is None else learner)
                metrics = evaluate(task, current, checkpoints[evaluated_at.index(episode)], truth)
                if learner is not None and hasattr(learner, "filter_precision_recall"):
                    precision, recall = learner.filter_precision_recall(teacher.wrong_labels)
                    metrics |= {"filter_precision": precision, "filter_recall": recall}
                rows += [(episode, name, value) for name, value in metrics.items() if np.isfinite(value)]
            if episode == cell.episodes or learner is None:
                continue
            # Algorithm 2: execute pi^l with the candidates from one layout, sample a slice tau, ask for a
            # preference y, update SI (Eq. 2/3).
            if clips is not None:
                query = learner.ask(clips[episode].replayer(h))
            else:
                layout = task.sample_layout(learn_rng)
                query = learner.ask(observer(task, truth, layout, h))
            learner.tell(query, teacher.answer(query))
    return tidy_rows(
        rows,
        domain=cell.domain,
        method=cell.method,
        noise=cell.noise,
        seed=cell.seed,
        ground_truth=round(truth, 6),
        n_candidates=cell.n_candidates,
        **({} if cell.teacher == TeacherModel() else {"teacher": cell.teacher.name}),
        **({} if low_level == ("admittance",) else {"low_level": cell.data.low_level.kind}),
        **(
            {"query_rule": cell.fine_tuning.candidate_sampling}
            if cell.fine_tuning.candidate_sampling in CHOSEN
            else {}
        ),
        **({"told": cell.told} if cell.told != "nothing" else {}),
    )

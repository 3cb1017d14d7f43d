"""From answers to success (notebook 12, beyond the paper): how much of what its answers say a learner uses.

Two parts, on one fixed grid of environments (truth, seed) per domain, every learner of an environment
answered by the same teacher stream:

- **The answers** (no physics, `run_answers`): the Bayesian learner (`hipref.learners.bayes`) asks a
  scripted teacher and is told; its error |estimate - phi*| after every number of answers, per teacher model
  and flip rate, query rule, and answer model told or chosen by marginal likelihood. Against it the Shannon
  floor: to single out one of K candidates from answers each wrong with probability e takes at least
  log2(K) / (1 - h(e)) answers, h the binary entropy (`hipref.experiments.answers_tables`).
- **The task** (MuJoCo, `hipref.experiments.si_run.run_si`): PESI and CO-PESI with uniform pairs (Algorithm
  2), the Bayesian learner with uniform and chosen queries, evaluated after 0, 5, 10, 20, 33, ... answers on
  the same evaluation episodes: the error of the estimate the controller gets and the success of the task
  executed with it; beside them the success with the true parameter on those episodes (method
  'true_parameter', `run_at_truth`): what an exact estimate gets, the task's own failures. PESI's update
  does not use a posterior to choose from, and a chosen query executes a fresh clip per answer (uniform
  pairs replay the environment's clips): chosen queries for PESI were measured once (no difference detected
  in its final error) and are left out.

The Bayesian learner of the task part is not told the teacher's model; under uniform queries it asks
exactly PESI's queries (the same seed and draws), so the two differ only in what they make of the answers.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Annotated, Any

import numpy as np
import pandas as pd

from hipref.experiments.domains import DOMAINS, domain_spec, truth_grids
from hipref.experiments.protocol import SIStudy
from hipref.experiments.si_clips import run_streams
from hipref.experiments.si_methods import BAYES_METHODS, COTEACHING_METHODS, METHODS
from hipref.experiments.si_run import FineTuning, SIRun, run_at_truth, run_si
from hipref.learners.answer_models import TOLD, AnswerModel, hypotheses, told
from hipref.learners.bayes import BayesConfig, BayesLearner
from hipref.learners.pesi import PESIConfig
from hipref.learners.queries import QUERY_RULES
from hipref.numerics import one_thread
from hipref.results import tidy_rows
from hipref.seeds import integer_seed
from hipref.sweep import run_sweep
from hipref.teachers.models import TEACHER_KINDS, TeacherModel
from hipref.teachers.preference import ScriptedPreferenceTeacher
from hipref.validation import Integer, NonEmptyTuple, OneOf, Range, check_fields, check_int, check_range

TASK_METHODS: tuple[str, ...] = ("pesi", "co_pesi", "bayes", "bayes_si")
"""The learners of the task part: the paper's two and the Bayesian one, from a uniform prior or from SI's
Pr(phi | tau) on each evaluation slice."""
assert set(TASK_METHODS) <= set(METHODS)

STEP_BOUNDS: dict[float, int] = {0.0: 10, 0.2: 30}
"""The claims' most answers to one step with chosen queries, per flip rate of the paper's teacher (the
learner told its kind, not its flip rate)."""

MODEL_CHOICE_BOUND = 1.25
"""The claims' most answers (or final error) of the learner told nothing against the one told the model."""

SUCCESS_AFTER = 20
"""The answers after which the claims read the task's success with the Bayesian learner's estimate."""

SUCCESS_BARS: dict[str, float] = {"wiping": 0.9, "pushing": 0.8}
"""The claims' least success rate of the task after SUCCESS_AFTER chosen answers, per domain."""

SUCCESS_SHORTFALL = 0.10
"""The claims' most the task's success with the Bayesian learner's estimate may fall below its success with
the true parameter on the same episodes (notebook 10's margin for a learned low level against its expert)."""

FLIP_RATE = Range(0.0, 0.5 - 1e-9)
"""A flip rate of the paper's teacher: at 0.5 its answers would tell nothing."""

OTHER_TEACHERS: tuple[str, ...] = tuple(k for k in TEACHER_KINDS if k not in ("oracle", "mistake"))
"""The teacher models of `AnswersConfig.teachers`: all but the oracle and the paper's teacher."""


def answer_counts(episodes: int) -> tuple[int, ...]:
    """The numbers of answers after which the answers part records the error: every one up to 40, then
    every 5 up to 100, then every 10, and the last."""
    counts = {*range(1, 41), *range(45, 101, 5), *range(110, episodes + 1, 10), episodes}
    return tuple(sorted(c for c in counts if c <= episodes))


@dataclass(frozen=True)
class AnswersCell:
    """One Bayesian learner answered by one scripted teacher in one environment, without physics."""

    domain: str
    """'wiping' or 'pushing'."""
    ground_truth: float
    """The environment's true parameter."""
    seed: Annotated[int, Integer(0)]
    """The environment's seed: with the truth, the teacher's and the learner's streams (`run_streams`)."""
    teacher: Annotated[str, OneOf(TEACHER_KINDS)]
    """The teacher model's kind (`hipref.teachers.models.TEACHER_KINDS`)."""
    noise: Annotated[float, FLIP_RATE]
    """Its uniform flip rate."""
    query_rule: Annotated[str, OneOf(QUERY_RULES)]
    """One of QUERY_RULES."""
    told: Annotated[str, OneOf(TOLD)]
    """What the learner is told of the teacher: its 'model', its 'kind' or 'nothing' (`TOLD`)."""
    episodes: Annotated[int, Integer(1)]
    """Answers asked."""

    def __post_init__(self) -> None:
        check_fields(self)
        spec = domain_spec(self.domain)
        check_range("ground_truth", self.ground_truth, spec.candidates.low, spec.candidates.high)


def run_answers(
    cell: AnswersCell,
    models: tuple[AnswerModel, ...] | None = None,
    reader: tuple[AnswerModel, ...] | None = None,
) -> pd.DataFrame:
    """The learner's error after each of `answer_counts` (a sweep cell; under a chosen query rule also the
    error of the same posterior's median, 'median_error'), and at the end the posterior's filter of wrong
    answers against the teacher's record and the probability it gives the true kind. `models` replaces the
    answer models the learner weighs (`hypotheses` of what it is told, by default). With `reader`, a second
    learner weighing the answer models `reader` hears the same queries and answers without asking, and
    every row is its (what that posterior makes of answers to queries another belief chose), though the
    rows keep the cell's `told`."""
    phi = domain_spec(cell.domain).candidates
    teacher_seq, learner_seq, _, _ = run_streams(cell.seed, cell.ground_truth)
    model = TeacherModel(cell.teacher)
    teacher = ScriptedPreferenceTeacher(
        cell.ground_truth, cell.noise, np.random.default_rng(teacher_seq), model, scale=phi.high - phi.low
    )
    if models is None:
        models = hypotheses(model, cell.noise, cell.told)
    asker = BayesLearner(
        phi, BayesConfig(query_rule=cell.query_rule, answer_models=models), integer_seed(learner_seq)
    )
    learner = asker
    if reader is not None:
        learner = BayesLearner(
            phi, BayesConfig(query_rule=cell.query_rule, answer_models=reader), integer_seed(learner_seq)
        )
    counts = set(answer_counts(cell.episodes))
    rows: list[tuple[int, str, float]] = []
    with one_thread():
        for answered in range(1, cell.episodes + 1):
            query = asker.ask()
            answer = teacher.answer(query)
            asker.tell(query, answer)
            if learner is not asker:
                learner.tell(query, answer)
            if answered in counts:
                rows.append((answered, "param_error", abs(learner.estimate() - cell.ground_truth)))
                if cell.query_rule != "uniform":  # the same posterior read by its median: the reading's cost
                    median = learner.estimate(reading="median")
                    rows.append((answered, "median_error", abs(median - cell.ground_truth)))
    precision, recall = learner.filter_precision_recall(teacher.wrong_labels)
    kind = told(model, 0.0).kind
    final = {
        "filter_precision": precision,
        "filter_recall": recall,
        "true_model_probability": learner.posterior.model_posterior().get(kind, 0.0),
    }
    rows += [(cell.episodes, name, value) for name, value in final.items() if np.isfinite(value)]
    return tidy_rows(
        rows,
        domain=cell.domain,
        method="bayes",
        noise=cell.noise,
        seed=cell.seed,
        ground_truth=round(cell.ground_truth, 6),
        teacher=cell.teacher,
        query_rule=cell.query_rule,
        told=cell.told,
        part="answers",
    )


@dataclass(frozen=True)
class AnswersConfig(SIStudy):
    """Parameters of notebook 12 (the quick profile's sizes by default)."""

    domains: NonEmptyTuple[Annotated[str, OneOf(DOMAINS)]] = ("wiping", "pushing")
    """Domains to run: 'wiping' (desk height) and 'pushing' (cube mass)."""
    heights: tuple[float, ...] = (0.62, 0.78)
    """True desk heights in m of the wiping environments, each in [0.5, 0.9]."""
    masses: tuple[float, ...] = (11.5, 16.5)
    """True cube masses in kg of the pushing environments, each in [8, 20]."""
    episodes: Annotated[int, Integer(1)] = 66
    """Answers per run, at least 1."""
    eval_every: Annotated[int, Integer(1)] = 1
    """Not used: the task part evaluates after `checkpoints` (1 passes the base's check for any episodes)."""
    checkpoints: tuple[int, ...] = (0, 5, 10, 20, 33, 66)
    """Answers after which the task part evaluates (increasing, from 0 to at most `episodes`); its runs end
    at the last one."""
    eval_episodes: Annotated[int, Integer(1)] = 3
    """Evaluation episodes per checkpoint of the task part (section 5: 10)."""
    noise_levels: NonEmptyTuple[Annotated[float, FLIP_RATE]] = (0.0, 0.2)
    """Flip rates of the paper's teacher ('mistake') in the answers part, each in [0, 0.5)."""
    blind_noise_levels: tuple[Annotated[float, FLIP_RATE], ...] = (0.0, 0.2)
    """Of `noise_levels`, those at which the answers part also runs, under chosen rules, the learner told
    only the teacher's kind and the one told nothing (the claims read 0 and 20 %); at the others it is told
    the model."""
    teachers: tuple[Annotated[str, OneOf(OTHER_TEACHERS)], ...] = ("distance",)
    """The other teacher models of the answers part (notebook 11's, each at its default; no flips)."""
    answer_rules: NonEmptyTuple[Annotated[str, OneOf(QUERY_RULES)]] = ("uniform", "information_gain")
    """Query rules of the answers part under the paper's teacher (the other teachers: information_gain)."""
    task_noise_levels: NonEmptyTuple[Annotated[float, FLIP_RATE]] = (0.2,)
    """Flip rates of the paper's teacher in the task part, each in [0, 0.5); CO-PESI runs where above 0."""
    methods: NonEmptyTuple[Annotated[str, OneOf(TASK_METHODS)]] = TASK_METHODS
    """Learners of the task part, of TASK_METHODS."""
    task_rules: NonEmptyTuple[Annotated[str, OneOf(QUERY_RULES)]] = ("uniform", "information_gain")
    """Query rules of the Bayesian learners in the task part, of QUERY_RULES (PESI and CO-PESI ask uniform
    pairs, Algorithm 2's)."""
    task_seeds: int = 1
    """Seeds per true parameter of the task part (its environments are the first of the answers part's):
    the physics costs a hundred times what the answers alone do."""
    held_out_heights: NonEmptyTuple[float] = (0.68,)
    """True desk heights in m of the held-out wiping environments, each in [0.5, 0.9] and none of `heights`:
    the answers part's headline claims replicated on truths the study does not tune on (full profile: 30)."""
    held_out_masses: NonEmptyTuple[float] = (14.75,)
    """True cube masses in kg of the held-out pushing environments, each in [8, 20] and none of `masses`
    (full profile: 30)."""
    held_out_seeds: NonEmptyTuple[int] = (300,)
    """Seeds of the held-out environments, none below `seeds` (the grid's are 0 .. seeds - 1)."""
    held_out_episodes: Annotated[int, Integer(1)] = 40
    """Answers per held-out run, at least 1: the replicated claims read at most 30 (`STEP_BOUNDS`)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        extra = set(self.blind_noise_levels) - set(self.noise_levels)
        if extra:
            raise ValueError(f"blind_noise_levels must be among noise_levels, got {sorted(extra)!r} besides")
        if not self.checkpoints or self.checkpoints[0] != 0 or self.checkpoints[-1] > self.episodes:
            raise ValueError(
                f"checkpoints must run from 0 to at most episodes={self.episodes}, got {self.checkpoints!r}"
            )
        SIRun("wiping", "pesi", 0.7, episodes=self.episodes, checkpoints=self.checkpoints)
        check_int("task_seeds", self.task_seeds, 1, self.seeds)
        grids = truth_grids(self)
        for domain, values in self.held_out_grids().items():
            name = f"held_out_{DOMAINS[domain].truths}"
            phi = DOMAINS[domain].candidates
            for value in values:
                check_range(name, value, phi.low, phi.high)
                if value in grids[domain]:
                    raise ValueError(f"{name} must hold truths outside the grid, got {value} (in the grid)")
        for seed in self.held_out_seeds:
            check_int("held_out_seeds", seed, self.seeds)

    def held_out_grids(self) -> dict[str, tuple[float, ...]]:
        """Each domain's held-out true parameters (`held_out_heights`, `held_out_masses`)."""
        return {domain: getattr(self, f"held_out_{spec.truths}") for domain, spec in DOMAINS.items()}

    def held_out_environments(self, domain: str) -> list[tuple[float, int]]:
        """The held-out (ground truth, seed) of `domain`: its held-out truths x `held_out_seeds`."""
        return [(truth, seed) for truth in self.held_out_grids()[domain] for seed in self.held_out_seeds]

    def held_out_cells(self) -> list[AnswersCell]:
        """The held-out replication: the paper's teacher at each of `blind_noise_levels` under information
        gain, told its model, its kind or nothing, on the held-out truths x seeds."""
        return [
            AnswersCell(
                domain, truth, seed, "mistake", noise, "information_gain", told, self.held_out_episodes
            )
            for domain in self.domains
            for noise in self.blind_noise_levels
            for told in TOLD
            for truth, seed in self.held_out_environments(domain)
        ]

    def task_environments(self, domain: str) -> list[tuple[float, int]]:
        """The task part's (ground truth, seed): the grid crossed with the first `task_seeds` seeds."""
        return [(truth, seed) for truth, seed in self.environments(domain) if seed < self.task_seeds]

    def answers_cells(self) -> list[AnswersCell]:
        """The answers part: per environment, the paper's teacher at every flip rate: under uniform pairs
        told its model (as PESI is told the flip rate), under a chosen rule told its model, and at
        `blind_noise_levels` also its kind or nothing; every other teacher under information gain, told its
        model or nothing."""
        settings = [
            ("mistake", e, rule, told)
            for e in self.noise_levels
            for rule in self.answer_rules
            for told in (TOLD if rule != "uniform" and e in self.blind_noise_levels else ("model",))
        ]
        settings += [
            (t, 0.0, "information_gain", told) for t in self.teachers for told in ("model", "nothing")
        ]
        return [
            AnswersCell(domain, truth, seed, teacher, noise, rule, told, self.episodes)
            for domain in self.domains
            for teacher, noise, rule, told in settings
            for truth, seed in self.environments(domain)
        ]

    def task_cells(self) -> list[SIRun]:
        """The task part: every learner at every flip rate (CO-PESI above 0), the Bayesian ones under every
        rule, PESI and CO-PESI under uniform pairs; each run ends at the last checkpoint."""
        return [
            self._task_run(domain, method, truth, seed, rule, noise, self.checkpoints)
            for domain in self.domains
            for noise in self.task_noise_levels
            for method in self.methods
            if not (method in COTEACHING_METHODS and noise == 0)
            for rule in self.task_rules
            if rule == "uniform" or method in BAYES_METHODS
            for truth, seed in self.task_environments(domain)
        ]

    def held_out_task_cells(self) -> list[SIRun | AtTruth]:
        """The success claims replicated on the held-out truths x seeds: the Bayesian learner told nothing
        of the teacher, asking by information gain at each of `task_noise_levels`, evaluated before any
        answer and after SUCCESS_AFTER, and the true parameter on the same evaluation episodes."""
        checkpoints = (0, SUCCESS_AFTER)
        runs: list[SIRun | AtTruth] = [
            self._task_run(domain, "bayes", truth, seed, "information_gain", noise, checkpoints)
            for domain in self.domains
            for noise in self.task_noise_levels
            for truth, seed in self.held_out_environments(domain)
        ]
        return runs + [
            self._at_truth(domain, truth, seed, checkpoints)
            for domain in self.domains
            for truth, seed in self.held_out_environments(domain)
        ]

    def truth_cells(self) -> list[AtTruth]:
        """The task part's reference: each environment's evaluation episodes with the true parameter."""
        return [
            self._at_truth(domain, truth, seed, self.checkpoints)
            for domain in self.domains
            for truth, seed in self.task_environments(domain)
        ]

    def _task_run(
        self,
        domain: str,
        method: str,
        truth: float,
        seed: int,
        rule: str,
        noise: float,
        checkpoints: tuple[int, ...],
    ) -> SIRun:
        """One run of the task part, asking by `rule`, evaluated at `checkpoints` and ending at the last."""
        tuning = FineTuning(PESIConfig(learning_rate=self.learning_rate, candidate_sampling=rule))
        run = self.run_cell(
            domain, method, truth, seed, fine_tuning=tuning, noise=noise, checkpoints=checkpoints
        )
        return replace(run, episodes=checkpoints[-1])

    def _at_truth(self, domain: str, truth: float, seed: int, checkpoints: tuple[int, ...]) -> AtTruth:
        """The true parameter on the evaluation episodes of an environment's task runs at `checkpoints`."""
        run = self.run_cell(domain, "osi", truth, seed, checkpoints=checkpoints)
        return AtTruth(replace(run, episodes=checkpoints[-1]))


@dataclass(frozen=True)
class AtTruth:
    """The task executed with the true parameter on the evaluation episodes of `run`'s environment
    (`run_at_truth`): what an exact estimate gets there."""

    run: SIRun


def run_cell(cell: SIRun | AnswersCell | AtTruth) -> pd.DataFrame:
    """One cell of either part, or the task part's reference (a sweep cell function)."""
    if isinstance(cell, AnswersCell):
        return run_answers(cell)
    return run_at_truth(cell.run) if isinstance(cell, AtTruth) else run_si(cell)


def run(config: AnswersConfig, **sweep: Any) -> pd.DataFrame:
    """Both parts' tidy rows, with the columns `part` ('task' or 'answers') and `grid` ('study', or 'held_out'
    for the held-out replication's answers) on every row, and teacher, query_rule and told on every row but
    the true parameter's (no teacher is asked: its noise, teacher, query_rule and told are empty). One sweep,
    the task part's runs first: they take the longest."""
    config.pretrain(config.domains, **sweep)
    task, answers, held_out = config.task_cells(), config.answers_cells(), config.held_out_cells()
    cells = [*task, *config.truth_cells(), *config.held_out_task_cells(), *answers, *held_out]
    rows = run_sweep(run_cell, cells, desc="answers to success", **sweep)
    held_out_seeds = set(config.held_out_seeds)
    rows["grid"] = np.where(rows["seed"].isin(held_out_seeds), "held_out", "study")
    rows["part"] = rows["part"].fillna("task")
    asked = rows["method"] != "true_parameter"
    for column, default in {"teacher": "mistake", "query_rule": "uniform", "told": "nothing"}.items():
        rows.loc[asked, column] = rows.loc[asked, column].fillna(default)
    return rows

"""The shared engine of every system-identification study: OSI, PESI, PESI-CE and CO-PESI in the real worlds.

One run (`run_si`) follows the paper's protocol for one environment with a fixed, unknown parameter phi:

- Algorithm 4 (A.4): SI is pretrained once per domain on trajectories collected under domain randomisation
  (`collect_dataset`, `pretrained_model`, both cached). That pretrained model, never updated, is `osi`.
- Algorithm 2: each learning episode samples N candidates, executes the low-level policy pi^l with each
  in the world, samples a trajectory slice tau of h control periods, gets the scripted teacher's
  (possibly flipped) preference and tells the learner, which updates SI (Eq. 2, Eq. 3 or the standard
  cross-entropy of A.8; Algorithm 1 for CO-PESI).
- Evaluation (section 5, 'Performance metrics'): at episode 0 and every 33 learning episodes the learner is
  frozen and 10 evaluation episodes are run: SI's absolute error on a fresh slice (`param_error`) and the
  success of the task executed with SI's estimate (`success_rate`).

Which estimate drives the slices. In a learning episode the candidates are drawn uniformly from Phi (or,
as an option, from SI's belief) and tau is a slice of the clip pi^l executes with one of them, every
candidate's clip starting from the same layout (PESILearner.ask, World.clip). Uniformly drawn queries do
not depend on what SI has learnt, so one environment's clips are executed once and replayed by every
method and noise level (`learning_clips`). Every slice SI is evaluated on, and every slice of Algorithm 4's
data, comes from a probing rollout that pi^l executes with an estimate drawn uniformly from the range: OSI
is evaluated on the inputs it was trained for.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
import pandas as pd
import torch

from hipref.learners.coteaching import (
    CoPESIConfig,
    CoPESILearner,
    EstimatedNoiseCoPESILearner,
    legacy_schedule,
)
from hipref.learners.pesi import CANDIDATE_SAMPLING, FINE_TUNED, PR_DOMAINS, PESIConfig, PESILearner
from hipref.learners.sysid import (
    CUBE_MASS,
    DESK_HEIGHT,
    PRETRAIN_LOSSES,
    CandidateSet,
    PretrainConfig,
    SIModel,
    pretrain,
)
from hipref.results import TIDY_COLUMNS
from hipref.sweep import Expect, cached_artefact
from hipref.teachers.preference import ScriptedPreferenceTeacher
from hipref.validation import check_choice, check_int, check_range

METHODS: tuple[str, ...] = ("osi", "pesi", "pesi_ce", "co_pesi", "co_pesi_estimated")
"""osi: pretrained, no preferences; pesi: Eq. 2/3; pesi_ce: standard cross-entropy (A.8); co_pesi:
Algorithm 1 told the true noise level; co_pesi_estimated: Algorithm 1 with the noise level estimated by
Algorithm 5 from the preferences so far (A.9)."""


@dataclass(frozen=True)
class DomainSpec:
    """What a domain contributes to system identification (Table 2)."""

    name: str
    """'wiping' or 'pushing'."""
    parameter: str
    """The unknown parameter phi, for axis labels."""
    unit: str
    """Its unit."""
    candidates: CandidateSet
    """Phi, the candidate set over the randomisation range."""
    batch_size: int
    """Preferences per SI update (Table 2: 16 for height, 32 for mass)."""
    refresh_frequency: int
    """f_refresh of the co-teaching classifiers (Table 2: 16 for height, 32 for mass)."""


DOMAINS: dict[str, DomainSpec] = {
    "wiping": DomainSpec("wiping", "desk height", "m", DESK_HEIGHT, batch_size=16, refresh_frequency=16),
    "pushing": DomainSpec("pushing", "cube mass", "kg", CUBE_MASS, batch_size=32, refresh_frequency=32),
}


def domain_spec(domain: str) -> DomainSpec:
    """The spec of `domain`; ValueError naming the allowed domains otherwise."""
    check_choice("domain", domain, tuple(DOMAINS))
    return DOMAINS[domain]


@dataclass(frozen=True)
class PretrainData:
    """Algorithm 4's dataset D and the pretraining of SI (A.4, A.7)."""

    n_trajectories: int = 100
    """Domain-randomised trajectories in D (A.7: 100)."""
    trajectory_steps: int = 100
    """Control periods per trajectory (A.7: 100 states and actions)."""
    history: int = 3
    """h, control periods per SI input slice (Table 2: 3)."""
    pretrain_steps: int = 3000
    """Adam steps of Algorithm 4 (its loop has no stated end)."""
    learning_rate: float = 1e-3
    """Adam step size of Algorithm 4 (Table 2: 1e-3)."""
    loss: str = "brier"
    """What Algorithm 4's mean squared loss is taken over: 'brier' (SI's distribution against the target
    distribution), 'expectation' (its mean only) or 'brier_expectation' (`hipref.learners.sysid.pretrain`)."""
    seed: int = 0
    """Seed of the collection and of the pretraining: one pretrained model per domain, shared by all runs."""

    def __post_init__(self) -> None:
        check_choice("loss", self.loss, PRETRAIN_LOSSES)
        check_int("n_trajectories", self.n_trajectories, 2)
        check_int("trajectory_steps", self.trajectory_steps, self.history if self.history >= 1 else 1)
        check_int("history", self.history, 1)
        check_int("pretrain_steps", self.pretrain_steps, 0)
        check_range("learning_rate", self.learning_rate, 1e-8, 1.0)
        check_int("seed", self.seed, 0)

    @property
    def collection(self) -> tuple[int, int, int, int]:
        """What the dataset D depends on (not how SI is then trained on it), so pretraining variants share
        one collection."""
        return (self.n_trajectories, self.trajectory_steps, self.history, self.seed)


class World:
    """A domain's physical task behind one interface: probe (a rollout with a given estimate) and attempt."""

    def __init__(self, domain: str) -> None:
        self.spec = domain_spec(domain)
        if domain == "wiping":
            from hipref.envs.wiping import WipingTask

            self.task = WipingTask()
        else:
            from hipref.envs.pushing import PushingTask

            self.task = PushingTask()

    def sample_layout(self, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
        """A random episode layout: the stroke's start and goal on the desk, or the cube's start and goal."""
        if self.spec.name == "wiping":
            cfg = self.task.config
            start, goal = rng.uniform(
                [cfg.area_x[0], cfg.area_y[0]], [cfg.area_x[1], cfg.area_y[1]], size=(2, 2)
            )
            return start, goal
        return self.task.sample_layout(rng)

    def rollout(
        self, true_parameter: float, estimate: float, layout: tuple[np.ndarray, np.ndarray]
    ) -> tuple[np.ndarray, bool]:
        """Execute pi^l once with `estimate` in a world whose parameter is `true_parameter`.

        Returns the per-period features (periods, 21) and whether the task succeeded.
        """
        start, goal = layout
        if self.spec.name == "wiping":
            self.task.reset(true_parameter, (float(start[0]), float(start[1])))
            stroke = self.task.stroke(goal, estimate)
            return stroke.features, bool(stroke.success)
        self.task.reset(true_parameter, start, goal)
        push = self.task.push(estimate)
        return push.features, bool(push.success)

    def random_estimate(self, rng: np.random.Generator) -> float:
        """A uniformly random estimate: what probing rollouts (and Algorithm 4's data) run with."""
        return float(rng.uniform(self.spec.candidates.low, self.spec.candidates.high))

    def clip_slice(
        self,
        true_parameter: float,
        estimate: float,
        layout: tuple[np.ndarray, np.ndarray],
        history: int,
        rng: np.random.Generator,
    ) -> np.ndarray:
        """tau: h consecutive periods at a place drawn uniformly with `rng` of the clip pi^l executes with
        `estimate` from `layout`, flattened (the SI input).

        Where the layout alone sets the clip's length (wiping: the stroke's distance at the tool speed),
        only the periods up to tau's end are simulated; physics draws no random numbers, so they are the
        whole clip's, bit for bit. A push ends when the cube comes to rest, so it is executed whole.
        """
        return self.clip(true_parameter, estimate, layout, history, rng).tau

    def clip(
        self,
        true_parameter: float,
        estimate: float,
        layout: tuple[np.ndarray, np.ndarray],
        history: int,
        rng: np.random.Generator,
    ) -> Clip:
        """`clip_slice` with the clip's length and the slice's place, so that the draw can be replayed."""
        start, goal = layout
        if self.spec.name == "wiping":
            self.task.reset(true_parameter, (float(start[0]), float(start[1])))
            periods = self.task.stroke_periods(goal)
            first = _slice_start(periods, history, rng)
            features = self.task.stroke(goal, estimate, periods=first + history).features
        else:
            features, _ = self.rollout(true_parameter, estimate, layout)
            periods = len(features)
            first = _slice_start(periods, history, rng)
        return Clip(estimate, periods, first, features[first : first + history].reshape(-1))

    def probe_slice(self, true_parameter: float, history: int, rng: np.random.Generator) -> np.ndarray:
        """tau of a probing rollout: pi^l executed with a uniformly random estimate from a random layout."""
        return self.clip_slice(
            true_parameter, self.random_estimate(rng), self.sample_layout(rng), history, rng
        )


class Clip(NamedTuple):
    """What a learning episode observes of the clip pi^l executes with one candidate: its slice tau."""

    estimate: float
    """The candidate pi^l was given."""
    periods: int
    """The clip's length in control periods, over which the slice's place was drawn."""
    first: int
    """The slice's first period."""
    tau: np.ndarray
    """The slice, flattened (the SI input)."""

    def replay(self, estimate: float, history: int, rng: np.random.Generator) -> np.ndarray:
        """tau again, drawing the slice's place from `rng` as the execution did, without the physics."""
        first = _slice_start(self.periods, history, rng)
        if estimate != self.estimate or first != self.first:
            raise RuntimeError(
                f"a replayed clip was asked for estimate {estimate} at period {first}, but was executed "
                f"with {self.estimate} at {self.first}: the queries depend on what the learner has learnt"
            )
        return self.tau


def _slice_start(periods: int, history: int, rng: np.random.Generator) -> int:
    """Where a slice of h periods starts, uniformly over a clip of `periods` periods."""
    if periods < history:
        raise ValueError(f"a clip of {periods} periods is shorter than the slice length h = {history}")
    return int(rng.integers(0, periods - history + 1))


def collect_dataset(domain: str, data: PretrainData) -> tuple[np.ndarray, np.ndarray]:
    """Algorithm 4's D: every h-period slice of `n_trajectories` domain-randomised trajectories.

    Each trajectory has its parameter drawn uniformly from the range (A.7) and is made of rollouts of pi^l,
    each with its own uniformly random estimate, chained until `trajectory_steps` periods are collected:
    the estimate is what pi^l acts on, so a spread of estimates shows SI how each parameter looks through
    both good and bad control. Returns (features (n, h * features per period), parameters (n,)).
    """
    world = World(domain)
    rng = np.random.default_rng(np.random.SeedSequence([data.seed, 4]))
    features, parameters = [], []
    for _ in range(data.n_trajectories):
        phi = float(rng.uniform(world.spec.candidates.low, world.spec.candidates.high))
        periods: list[np.ndarray] = []
        while sum(len(p) for p in periods) < data.trajectory_steps:
            periods.append(world.rollout(phi, world.random_estimate(rng), world.sample_layout(rng))[0])
        trajectory = np.concatenate(periods)[: data.trajectory_steps]
        windows = np.lib.stride_tricks.sliding_window_view(trajectory, data.history, axis=0)
        # sliding_window_view puts the window last: (n, 21, h) -> (n, h, 21), flattened in time order.
        features.append(windows.transpose(0, 2, 1).reshape(len(windows), -1))
        parameters.append(np.full(len(windows), phi))
    return np.concatenate(features), np.concatenate(parameters)


def pretrained_model(domain: str, data: PretrainData) -> SIModel:
    """The OSI model: SI pretrained by Algorithm 4 on `collect_dataset`, built once per config (cached)."""
    spec = domain_spec(domain)

    def build() -> SIModel:
        features, parameters = cached_artefact(
            f"si_dataset_{domain}",
            data.collection,
            lambda: collect_dataset(domain, data),
            expect=Expect(tuple, lambda d: d[0].ndim == 2 and d[0].shape[1] % data.history == 0
                          and d[1].shape == (len(d[0]),)),
        )
        with _one_thread():
            model = SIModel(features.shape[1], spec.candidates, seed=data.seed)
            pretrain(
                model,
                features,
                parameters,
                PretrainConfig(data.learning_rate, n_steps=data.pretrain_steps, loss=data.loss),
                data.seed,
            )
        return model

    return cached_artefact(f"si_osi_{domain}", (domain, dataclasses.asdict(data)), build, expect=SIModel)


class _one_thread:
    """Torch on one thread inside a run, restored after (a run may execute in the user's kernel)."""

    def __enter__(self) -> None:
        self.before = torch.get_num_threads()
        torch.set_num_threads(1)

    def __exit__(self, *exc: object) -> None:
        torch.set_num_threads(self.before)


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
    """'uniform' (Algorithm 2: 'sampled from Phi') or 'belief' (from SI's current distribution)."""
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

    def __post_init__(self) -> None:
        spec = domain_spec(self.domain)
        check_choice("method", self.method, METHODS)
        check_range("ground_truth", self.ground_truth, spec.candidates.low, spec.candidates.high)
        check_range("noise", self.noise, 0.0, 1.0)
        check_int("seed", self.seed, 0)
        check_int("n_candidates", self.n_candidates, 2, spec.candidates.size)
        if self.method.startswith("co_pesi") and self.n_candidates != 2:
            raise ValueError(
                f"n_candidates must be 2 for co_pesi (pair classifiers), got {self.n_candidates}"
            )
        check_int("episodes", self.episodes, 1)
        check_int("eval_every", self.eval_every, 1, self.episodes)
        check_int("eval_episodes", self.eval_episodes, 1)
        check_int("eval_slices", self.eval_slices, 1)


def make_learner(cell: SIRun, model: SIModel, seed: int) -> PESILearner | None:
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
    if cell.method == "osi":
        return None
    if cell.method in ("pesi", "pesi_ce"):
        loss = "soft" if cell.method == "pesi" else "standard"
        return PESILearner(model, PESIConfig(loss=loss, **common), seed)
    schedule = CoPESIConfig if tuning.coteaching_schedule == "learned" else legacy_schedule
    config = schedule(start_size=spec.batch_size, refresh_frequency=spec.refresh_frequency, **common)
    if cell.method == "co_pesi_estimated":
        # A.9: the forget number comes from Algorithm 5 on the preferences so far, not the true noise.
        return EstimatedNoiseCoPESILearner(model, config, seed)
    return CoPESILearner(model, cell.noise, config, seed)


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
    """What a run's evaluation episodes depend on: not the method, the noise level or N."""

    domain: str
    ground_truth: float
    seed: int
    """The run's seed, whose `run_streams(seed, ground_truth).evaluation` seeds the evaluations."""
    checkpoints: int
    eval_episodes: int
    slices: int
    history: int


class Episode(NamedTuple):
    """An evaluation episode: the probing slices SI estimates from, and the layout the task is then
    attempted in."""

    slices: np.ndarray
    """(slices, input_dim): the first drives the attempt; all of them the multi-slice estimate."""
    layout: tuple[np.ndarray, np.ndarray]


def evaluation_episodes(world: World, spec: EvaluationSpec) -> list[list[Episode]]:
    """Per checkpoint, its evaluation episodes, drawn from the checkpoint's own seed. Every method, noise
    level and N of one environment meets the same episodes, so they are built once (cached) and the
    methods' runs differ only in what SI makes of them: comparisons between methods are paired."""

    def build() -> list[list[Episode]]:
        checkpoints = []
        for seq in run_streams(spec.seed, spec.ground_truth).evaluation.spawn(spec.checkpoints):
            rng = np.random.default_rng(seq)
            episodes = []
            for _ in range(spec.eval_episodes):
                taus = [world.probe_slice(spec.ground_truth, spec.history, rng) for _ in range(spec.slices)]
                episodes.append(Episode(np.stack(taus), world.sample_layout(rng)))
            checkpoints.append(episodes)
        return checkpoints

    def complete(checkpoints: list[list[Episode]]) -> bool:
        return len(checkpoints) == spec.checkpoints and all(
            len(episodes) == spec.eval_episodes and all(len(e.slices) == spec.slices for e in episodes)
            for episodes in checkpoints
        )

    return cached_artefact(f"si_evaluation_{spec.domain}", spec, build, expect=Expect(list, complete))


@dataclass(frozen=True)
class LearningSpec:
    """What the clips of a run's learning episodes depend on when its candidates are drawn uniformly: not
    the method, the noise level or how SI is fine-tuned."""

    domain: str
    ground_truth: float
    seed: int
    """The run's seed; with the ground truth it seeds the learner's queries and the layouts."""
    episodes: int
    n_candidates: int
    history: int


def learning_clips(world: World, spec: LearningSpec, model: SIModel) -> list[Clip]:
    """Per learning episode, the clip its query observes, executed once per environment (cached).

    With candidates drawn uniformly from Phi (Algorithm 2), what a learner asks never depends on what SI has
    learnt or on the answers: the candidates, the layout and the slice's place come from the run's own
    streams. So every method, noise level and fine-tuning of one environment executes the same clips, and
    they are executed once, by a learner that only asks; runs replay them (`Clip.replay`) with their own
    learners, whose queries are checked against them. The rows are those of executing every run's clips.
    """

    def build() -> list[Clip]:
        truth, h = spec.ground_truth, spec.history
        _, learner_seq, learn_seq, _ = run_streams(spec.seed, truth)
        config = PESIConfig(n_candidates=spec.n_candidates, history=spec.history)
        asker = PESILearner(model, config, learner_seed(learner_seq))
        learn_rng = np.random.default_rng(learn_seq)
        clips: list[Clip] = []

        for _ in range(spec.episodes):
            layout = world.sample_layout(learn_rng)
            asker.ask(lambda phi, rng, layout=layout: _record(clips, world.clip(truth, phi, layout, h, rng)))
        return clips

    def complete(clips: list[Clip]) -> bool:
        return len(clips) == spec.episodes and all(isinstance(c, Clip) for c in clips)

    return cached_artefact(f"si_learning_{spec.domain}", spec, build, expect=Expect(list, complete))


def _record(clips: list[Clip], clip: Clip) -> np.ndarray:
    clips.append(clip)
    return clip.tau


def learner_seed(learner_seq: np.random.SeedSequence) -> int:
    """The learner's integer seed from its stream of `run_streams`."""
    return int(learner_seq.generate_state(1)[0])


def evaluate(
    world: World, model: SIModel, episodes: list[Episode], ground_truth: float
) -> dict[str, float]:
    """SI frozen on one checkpoint's episodes: its errors by three read-outs, and the task's success.

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
        expectations = model.predict(episode.slices)
        phi_hat = float(expectations[0])
        errors["param_error"].append(abs(phi_hat - ground_truth))
        errors["param_error_argmax"].append(abs(float(model.predict_mode(episode.slices[0])) - ground_truth))
        errors["param_error_multislice"].append(abs(float(expectations.mean()) - ground_truth))
        successes.append(world.rollout(ground_truth, phi_hat, episode.layout)[1])
    return {**{k: float(np.mean(v)) for k, v in errors.items()}, "success_rate": float(np.mean(successes))}


def run_si(cell: SIRun) -> pd.DataFrame:
    """One run of `cell` (a sweep cell function): tidy rows of every metric per evaluation.

    CO-PESI runs also report the precision and recall of their filter against the flips the scripted
    teacher recorded (never shown to the learner), counted over the learning so far.
    """
    model = pretrained_model(cell.domain, cell.data)
    with _one_thread():
        teacher_seq, learner_seq, learn_seq, _ = run_streams(cell.seed, cell.ground_truth)
        truth = cell.ground_truth
        world = World(cell.domain)
        teacher = ScriptedPreferenceTeacher(truth, cell.noise, np.random.default_rng(teacher_seq))
        learner = make_learner(cell, model, learner_seed(learner_seq))
        learn_rng = np.random.default_rng(learn_seq)
        h = cell.data.history
        n_checkpoints = cell.episodes // cell.eval_every + 1
        spec = EvaluationSpec(
            cell.domain, truth, cell.seed, n_checkpoints, cell.eval_episodes, cell.eval_slices, h
        )
        checkpoints = evaluation_episodes(world, spec)
        clips = None
        if learner is not None and cell.fine_tuning.candidate_sampling == "uniform":
            learning = LearningSpec(cell.domain, truth, cell.seed, cell.episodes, cell.n_candidates, h)
            clips = learning_clips(world, learning, model)
        rows: list[tuple[int, str, float]] = []
        for episode in range(cell.episodes + 1):
            if episode % cell.eval_every == 0:
                current = model if learner is None else learner.model
                metrics = evaluate(world, current, checkpoints[episode // cell.eval_every], truth)
                if isinstance(learner, CoPESILearner):
                    precision, recall = learner.filter_precision_recall(teacher.flipped)
                    metrics |= {"filter_precision": precision, "filter_recall": recall}
                rows += [(episode, name, value) for name, value in metrics.items() if np.isfinite(value)]
            if episode == cell.episodes or learner is None:
                continue
            # Algorithm 2: execute pi^l with the candidates from one layout, sample a slice tau, ask for a
            # preference y, update SI (Eq. 2/3).
            if clips is not None:
                query = learner.ask(lambda phi, rng, clip=clips[episode]: clip.replay(phi, h, rng))
            else:
                layout = world.sample_layout(learn_rng)
                query = learner.ask(
                    lambda phi, rng, layout=layout: world.clip_slice(truth, phi, layout, h, rng)
                )
            learner.tell(query, teacher.answer(query))
    return tidy_rows(
        rows,
        domain=cell.domain,
        method=cell.method,
        noise=cell.noise,
        seed=cell.seed,
        ground_truth=round(truth, 6),
        n_candidates=cell.n_candidates,
    )


def tidy_rows(rows: list[tuple[int, str, float]], **keys: Any) -> pd.DataFrame:
    """(episode, metric, value) rows with constant `keys` as the results contract's tidy frame."""
    frame = pd.DataFrame(rows, columns=["episode", "metric", "value"]).assign(**keys)
    extra = [k for k in keys if k not in TIDY_COLUMNS]
    return frame[[*TIDY_COLUMNS, *extra]]


@dataclass(frozen=True)
class Protocol:
    """What the SI studies share: a fixed grid of true parameters crossed with seeds, the paper's
    evaluation protocol and Algorithm 4's size.

    Every method of a study meets the same environments (truth, seed) and the same evaluation episodes,
    so methods are compared as paired differences (`hipref.verdicts`)."""

    heights: tuple[float, ...] = (0.6, 0.8)
    """True desk heights in m of the wiping environments, each in [0.5, 0.9] (full profile: 5, evenly)."""
    masses: tuple[float, ...] = (11.0, 17.0)
    """True cube masses in kg of the pushing environments, each in [8, 20] (full profile: 5, evenly)."""
    seeds: int = 1
    """Seeds per true parameter; truths x seeds is the repetitions of the paper (A.7: 15)."""
    episodes: int = 66
    """Learning episodes per run, at least 1."""
    eval_every: int = 33
    """Learning episodes between evaluations (section 5: 33)."""
    eval_episodes: int = 10
    """Evaluation episodes per evaluation (section 5: 10)."""
    eval_slices: int = 3
    """Probing slices per evaluation episode (for the multi-slice estimate)."""
    n_trajectories: int = 100
    """Algorithm 4 trajectories (A.7: 100)."""
    pretrain_steps: int = 3000
    """Adam steps of Algorithm 4."""
    pretrain_loss: str = "brier"
    """Algorithm 4's loss: 'brier', 'expectation' or 'brier_expectation' (see `pretrain` of
    `hipref.learners.sysid`)."""
    learning_rate: float = 1e-2
    """Gradient step size of SI fine-tuning (A.7: 0.01)."""

    def __post_init__(self) -> None:
        for name, values, domain in (("heights", self.heights, "wiping"), ("masses", self.masses, "pushing")):
            candidates = domain_spec(domain).candidates
            if not values:
                raise ValueError(
                    f"{name} must hold at least one value in [{candidates.low}, {candidates.high}], got ()"
                )
            for value in values:
                check_range(name, value, candidates.low, candidates.high)
        check_int("seeds", self.seeds, 1)
        check_int("episodes", self.episodes, 1)
        check_int("eval_every", self.eval_every, 1, self.episodes)
        check_int("eval_episodes", self.eval_episodes, 1)
        check_int("eval_slices", self.eval_slices, 1)
        FineTuning(learning_rate=self.learning_rate)
        self.data  # noqa: B018 - validates n_trajectories, pretrain_steps and pretrain_loss

    @property
    def data(self) -> PretrainData:
        return PretrainData(self.n_trajectories, pretrain_steps=self.pretrain_steps, loss=self.pretrain_loss)

    def truths(self, domain: str) -> tuple[float, ...]:
        """The grid of true parameters of `domain`."""
        return self.heights if domain_spec(domain).name == "wiping" else self.masses

    def environments(self, domain: str) -> list[tuple[float, int]]:
        """Every (ground truth, seed) of `domain`: the grid crossed with the seeds."""
        return [(truth, seed) for truth in self.truths(domain) for seed in range(self.seeds)]

    def run_cell(
        self,
        domain: str,
        method: str,
        truth: float,
        seed: int,
        fine_tuning: FineTuning | None = None,
        **setting: Any,
    ) -> SIRun:
        """One run of this protocol; `setting` holds what the study varies (noise, N). OSI learns nothing,
        so its run ignores the fine-tuning and the noise: one OSI run per environment serves every study."""
        tuning = fine_tuning if fine_tuning is not None else FineTuning(learning_rate=self.learning_rate)
        if method == "osi":
            tuning, setting = FineTuning(), {k: v for k, v in setting.items() if k != "noise"}
        elif not method.startswith("co_pesi"):
            # The classifier schedule means nothing without classifiers: such runs share one cache entry.
            tuning = dataclasses.replace(tuning, coteaching_schedule=FineTuning.coteaching_schedule)
        return SIRun(
            domain,
            method,
            truth,
            seed=seed,
            episodes=self.episodes,
            eval_every=self.eval_every,
            eval_episodes=self.eval_episodes,
            eval_slices=self.eval_slices,
            fine_tuning=tuning,
            data=self.data,
            **setting,
        )

    def pretrain(self, domains: Iterable[str]) -> None:
        """Algorithm 4 once, in this process: parallel workers then load the model, not race to build it."""
        for domain in domains:
            pretrained_model(domain, self.data)

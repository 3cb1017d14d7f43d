"""Teachers and robustness (notebook 11, beyond the paper): which learner is best under which teacher.

The matrix teacher model x learner (`hipref.teachers.models`; the robust learners' losses and filters,
`hipref.learners.losses`, `hipref.learners.filters`), in both domains.
Every learner of one environment (truth, seed) meets the same teacher draws, the same learning clips and
the same evaluation episodes as plain PESI (`hipref.experiments.si_run`), so each is compared with PESI as
a paired difference at the last evaluation (`hipref.verdicts`). The paper's flip teacher ('mistake') flips
at `noise`; the other teachers' errors come from their own model, whose defaults make about as many wrong
answers on uniformly drawn pairs (`TeacherModel`). Beside the runs, `run_teacher_noise` measures, for every
teacher and environment, the true share of wrong answers among the labelled ones and the maximum marginal
likelihood estimate of the flip rate on the same preferences (what the estimated-rate learners see).

The config's defaults are the quick profile (three teachers, four learners, one environment per domain: a
smoke test whose intervals are single points); the full profile crosses every teacher with every learner.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any

import numpy as np
import pandas as pd

from hipref.experiments.domains import DOMAINS, domain_spec
from hipref.experiments.protocol import SIStudy
from hipref.experiments.si_clips import LearningSpec, learning_clips, run_streams
from hipref.experiments.si_methods import METHODS as SI_METHODS
from hipref.experiments.si_pretraining import PretrainData, pretrained_model
from hipref.experiments.si_run import SIRun, run_si
from hipref.learners.filters import NoUpdate
from hipref.learners.noise_rate import likelihood_noise
from hipref.learners.pesi import PESIConfig, PESILearner
from hipref.numerics import one_thread
from hipref.results import METRICS, tidy_rows
from hipref.seeds import integer_seed
from hipref.sweep import run_sweep
from hipref.teachers.models import TEACHER_KINDS, TeacherModel
from hipref.teachers.preference import ScriptedPreferenceTeacher
from hipref.validation import Integer, NonEmptyTuple, OneOf, Range, check_fields
from hipref.verdicts import Difference, better_on_both, bootstrap_mean, paired_difference, within

BASELINE = "pesi"
"""Every learner is compared with plain PESI (Eq. 2) under the same teacher."""

LEARNERS: tuple[str, ...] = (
    "pesi",
    "pesi_smoothed",
    "pesi_unbiased",
    "pesi_small_loss",
    "pesi_rime",
    "co_pesi_likelihood",
)
"""The learners of the matrix: PESI, then the robust ones (their losses and filters in `hipref.learners`)."""

TEACHERS: tuple[str, ...] = ("mistake", "stochastic", "skip", "equal", "myopic", "distance")
"""The teachers of the matrix: the paper's flip and the other models, each with its default parameters."""

QUICK_TEACHERS: tuple[str, ...] = ("mistake", "stochastic", "distance")
"""The quick profile's teachers: wrong answers of three kinds (uniform flips, Bradley-Terry's on nearly equal
pairs, confusion of pairs hard to tell apart), about as many of each."""

QUICK_LEARNERS: tuple[str, ...] = ("pesi", "pesi_unbiased", "pesi_small_loss", "co_pesi_likelihood")
"""The quick profile's learners: PESI, a robust loss, a one-network filter and co-teaching."""

ROW_METRICS: tuple[str, ...] = (*METRICS, "unlabelled_share")
"""The metrics of the study's rows: the results contract's, and the teachers' share of unlabelled answers."""

NOISE_TOLERANCE = 0.05
"""How near a teacher's true share of wrong answers the estimated flip rate must be to recover it: the
claims' tolerance on the bias (estimate - true), a quarter of the paper's middle noise level."""


@dataclass(frozen=True)
class RobustnessConfig(SIStudy):
    """Parameters of notebook 11 (the quick profile's sizes by default)."""

    domains: NonEmptyTuple[Annotated[str, OneOf(DOMAINS)]] = ("wiping", "pushing")
    """Domains to run: 'wiping' (desk height) and 'pushing' (cube mass)."""
    teachers: NonEmptyTuple[Annotated[str, OneOf(TEACHER_KINDS)]] = QUICK_TEACHERS
    """Teacher models (`hipref.teachers.models.TEACHER_KINDS`); full profile: all of TEACHERS."""
    methods: NonEmptyTuple[Annotated[str, OneOf(SI_METHODS)]] = QUICK_LEARNERS
    """Learners (`hipref.experiments.si_methods.METHODS`); must include the baseline 'pesi'. Full profile:
    all of LEARNERS."""
    noise: Annotated[float, Range(0.0, 1.0)] = 0.2
    """The flip rate of the 'mistake' teacher (the paper's middle level); the other teachers flip nothing
    on top of their own errors."""
    heights: tuple[float, ...] = (0.6,)
    """True desk heights in m of the wiping environments, each in [0.5, 0.9] (notebook 04's, so its
    learning clips and evaluation episodes are reused)."""
    masses: tuple[float, ...] = (11.0,)
    """True cube masses in kg of the pushing environments, each in [8, 20]."""
    eval_every: Annotated[int, Integer(1)] = 66
    """Learning episodes between evaluations (section 5: 33). By default equal to `episodes`: one evaluation
    before learning and one at the end, the only one the verdicts use."""
    eval_episodes: Annotated[int, Integer(1)] = 5
    """Evaluation episodes per evaluation (section 5: 10)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        if BASELINE not in self.methods:
            raise ValueError(f"methods must include the baseline {BASELINE!r}, got {self.methods!r}")

    def teacher_noise(self, teacher: str) -> float:
        """The uniform flip rate of a teacher's runs: `noise` for the paper's teacher, else 0."""
        return self.noise if teacher == "mistake" else 0.0


def cells(config: RobustnessConfig) -> list[SIRun]:
    """The sweep: domain x teacher x learner x environment (truth, seed)."""
    return [
        config.run_cell(
            domain,
            method,
            truth,
            seed,
            noise=config.teacher_noise(teacher),
            teacher=TeacherModel(teacher),
        )
        for domain in config.domains
        for teacher in config.teachers
        for method in config.methods
        for truth, seed in config.environments(domain)
    ]


@dataclass(frozen=True)
class TeacherNoiseCell:
    """One teacher answering one environment's learning queries, without any learner updating."""

    domain: str
    """'wiping' or 'pushing'."""
    teacher: Annotated[str, OneOf(TEACHER_KINDS)]
    """The teacher model's kind."""
    noise: float
    """Its uniform flip rate."""
    ground_truth: float
    """The environment's true parameter."""
    seed: int
    """The environment's seed (with the truth, the same teacher and query streams as its SI runs)."""
    episodes: Annotated[int, Integer(1)]
    """Queries answered."""
    data: PretrainData
    """Algorithm 4's data: the model whose clips the queries replay."""

    def __post_init__(self) -> None:
        check_fields(self)


def run_teacher_noise(cell: TeacherNoiseCell) -> pd.DataFrame:
    """The true and the estimated noise of one teacher on one environment's queries (a sweep cell).

    The queries are those every learner of the environment asks (uniform candidates: they do not depend on
    the learner), answered by the teacher with the runs' own stream, so the answers are the runs' answers.
    Metrics at episode = episodes: true_noise (wrong share of the labelled answers), estimated_noise (the
    maximum marginal likelihood flip rate of the labelled ones, `likelihood_noise`), unlabelled_share (the
    share of answers without a label, SKIP or EQUAL)."""
    spec = domain_spec(cell.domain)
    model = pretrained_model(cell.domain, cell.data)
    with one_thread():
        teacher_seq, learner_seq, _, _ = run_streams(cell.seed, cell.ground_truth)
        phi = spec.candidates
        teacher = ScriptedPreferenceTeacher(
            cell.ground_truth,
            cell.noise,
            np.random.default_rng(teacher_seq),
            TeacherModel(cell.teacher),
            scale=phi.high - phi.low,
            bounds=(phi.low, phi.high),
        )
        h = cell.data.history
        clips = learning_clips(
            spec.make_task(),
            LearningSpec(cell.domain, cell.ground_truth, cell.seed, 2, h),
            cell.episodes,
            model,
        )
        # A PESI learner that asks and stores but never updates SI: its buffer is the runs' buffer.
        learner = PESILearner(model, PESIConfig(history=h), integer_seed(learner_seq), NoUpdate())
        for recorded in clips:
            query = learner.ask(recorded.replayer(h))
            learner.tell(query, teacher.answer(query))
    labelled = len(learner)
    metrics = {
        "true_noise": float(np.mean(teacher.wrong_labels)) if labelled else np.nan,
        "estimated_noise": (
            likelihood_noise(learner.buffer_preferences(), phi.low, phi.high) if labelled else np.nan
        ),
        "unlabelled_share": 1.0 - labelled / cell.episodes,
    }
    rows = [(cell.episodes, name, value) for name, value in metrics.items() if np.isfinite(value)]
    return tidy_rows(
        rows,
        domain=cell.domain,
        method="teacher",
        noise=cell.noise,
        seed=cell.seed,
        ground_truth=round(cell.ground_truth, 6),
        teacher=cell.teacher,
    )


def noise_cells(config: RobustnessConfig) -> list[TeacherNoiseCell]:
    """One teacher-noise cell per domain, teacher and environment."""
    return [
        TeacherNoiseCell(
            domain, teacher, config.teacher_noise(teacher), truth, seed, config.episodes, config.data
        )
        for domain in config.domains
        for teacher in config.teachers
        for truth, seed in config.environments(domain)
    ]


def run_cell(cell: SIRun | TeacherNoiseCell) -> pd.DataFrame:
    """One cell of the study's sweep: an SI run (`run_si`) or a teacher's noise (`run_teacher_noise`)."""
    if isinstance(cell, TeacherNoiseCell):
        return run_teacher_noise(cell)
    return run_si(cell)


def run(config: RobustnessConfig, **sweep: Any) -> pd.DataFrame:
    """Tidy rows of every run (`run_si`, with filter precision and recall where a learner filters) and of
    every teacher's noise (`run_teacher_noise`, method 'teacher'); a `teacher` column names the model."""
    config.pretrain(config.domains, **sweep)
    # One sweep, the noise cells last: each replays the clips that its environment's runs execute first, and
    # takes a tenth of a second in a worker already started (seconds of imports in a fresh process).
    rows = run_sweep(
        run_cell, [*cells(config), *noise_cells(config)], desc="teachers x learners, teacher noise", **sweep
    )
    # The paper's teacher leaves its runs' rows as every other study's (no teacher column): name it here.
    rows["teacher"] = rows["teacher"].fillna("mistake")
    return rows


def final_difference(
    rows: pd.DataFrame, domain: str, teacher: str, method: str, metric: str, *, resamples: int = 5000
) -> Difference:
    """`method` minus PESI on `metric` at the last evaluation under `teacher` in `domain`, paired over the
    environments (`hipref.verdicts.paired_difference`, which reads float32 rounding as zero)."""
    at = rows[(rows["domain"] == domain) & (rows["teacher"] == teacher)]
    if at.empty:
        raise ValueError(f"no rows for domain={domain!r} and teacher={teacher!r}")
    return paired_difference(at, metric=metric, method=method, baseline=BASELINE, resamples=resamples)


def difference_table(rows: pd.DataFrame, *, resamples: int = 5000) -> pd.DataFrame:
    """Every learner but PESI minus PESI, per domain and teacher, on param_error and success_rate at the
    last evaluation: columns domain, teacher, method, metric, mean, low, high, n."""
    runs = rows[rows["method"] != "teacher"]
    out = []
    for (domain, teacher), group in runs.groupby(["domain", "teacher"], sort=False):
        for method in [m for m in group["method"].unique() if m != BASELINE]:
            for metric in ("param_error", "success_rate"):
                d = final_difference(group, domain, teacher, method, metric, resamples=resamples)
                out.append(
                    dict(
                        domain=domain,
                        teacher=teacher,
                        method=method,
                        metric=metric,
                        mean=d.mean,
                        low=d.low,
                        high=d.high,
                        n=d.n,
                    )
                )
    return pd.DataFrame(out, columns=["domain", "teacher", "method", "metric", "mean", "low", "high", "n"])


def best_learner(table: pd.DataFrame, domain: str, teacher: str) -> tuple[str, str, str]:
    """The learner with the lowest mean final error difference to PESI under `teacher` in `domain`, and the
    claim 'it improves on PESI' tested on both metrics: `better` (the 95% interval wholly on the better
    side) for the error and for the success rate (`hipref.verdicts.better_on_both`). Returns (learner,
    verdict, the measured differences as text)."""
    at = table[(table["domain"] == domain) & (table["teacher"] == teacher)]
    errors = at[at["metric"] == "param_error"].set_index("method")
    if errors.empty:
        raise ValueError(f"no differences for domain={domain!r} and teacher={teacher!r}")
    method = str(errors["mean"].idxmin())
    success = at[(at["metric"] == "success_rate") & (at["method"] == method)].iloc[0]
    error = errors.loc[method]
    error_d = Difference(error["mean"], error["low"], error["high"], int(error["n"]))
    success_d = Difference(success["mean"], success["low"], success["high"], int(success["n"]))
    held = better_on_both(error_d, success_d)
    text = (
        f"{method} - pesi ({error_d.n} environments): error {error_d.mean:+.3g} "
        f"[{error_d.low:+.3g}, {error_d.high:+.3g}], success {success_d.mean:+.2f} "
        f"[{success_d.low:+.2f}, {success_d.high:+.2f}]"
    )
    return method, held, text


def noise_table(rows: pd.DataFrame, *, resamples: int = 5000) -> pd.DataFrame:
    """Per domain and teacher, the means over the environments of the teacher's true_noise,
    estimated_noise and unlabelled_share (`run_teacher_noise` rows, method 'teacher'), and the bias
    estimated - true paired per environment with its 95% bootstrap interval (`bootstrap_mean`), over the
    environments where the teacher labelled at least one answer. `recovered`: the verdict of `within` the
    bias and +-NOISE_TOLERANCE. A domain and teacher without a labelled answer has no row.
    Columns: domain, teacher, true_noise, estimated_noise, unlabelled_share, bias, bias_low, bias_high, n,
    recovered."""
    teacher_rows = rows[rows["method"] == "teacher"]
    columns = ["domain", "teacher", "true_noise", "estimated_noise", "unlabelled_share"]
    columns += ["bias", "bias_low", "bias_high", "n", "recovered"]
    out = []
    for (domain, teacher), group in teacher_rows.groupby(["domain", "teacher"], sort=False):
        wide = group.pivot_table(index=["ground_truth", "seed"], columns="metric", values="value")
        if not {"true_noise", "estimated_noise"} <= set(wide.columns):
            continue
        labelled = wide.dropna(subset=["true_noise", "estimated_noise"])
        if labelled.empty:
            continue
        bias = bootstrap_mean(labelled["estimated_noise"] - labelled["true_noise"], resamples=resamples)
        out.append(
            dict(
                domain=domain,
                teacher=teacher,
                true_noise=labelled["true_noise"].mean(),
                estimated_noise=labelled["estimated_noise"].mean(),
                unlabelled_share=wide["unlabelled_share"].mean() if "unlabelled_share" in wide else np.nan,
                bias=bias.mean,
                bias_low=bias.low,
                bias_high=bias.high,
                n=bias.n,
                recovered=within(bias, -NOISE_TOLERANCE, NOISE_TOLERANCE),
            )
        )
    return pd.DataFrame(out, columns=columns)


def filter_quality(rows: pd.DataFrame) -> pd.DataFrame:
    """Per domain, teacher and filtering learner, the filter's precision and recall at the last evaluation
    (over all learning), means over the environments, beside `chance`: the teacher's mean true share of
    wrong answers in the domain, the precision of a filter that forgets at random. Columns: domain,
    teacher, method, filter_precision, filter_recall, chance."""
    runs = rows[rows["method"] != "teacher"]
    last = runs[runs["episode"] == runs.groupby(["domain", "teacher", "method"])["episode"].transform("max")]
    quality = last[last["metric"].isin(["filter_precision", "filter_recall"])]
    columns = ["domain", "teacher", "method", "filter_precision", "filter_recall", "chance"]
    if quality.empty:
        return pd.DataFrame(columns=columns)
    table = quality.pivot_table(
        index=["domain", "teacher", "method"], columns="metric", values="value", sort=False
    ).reset_index()
    for metric in ("filter_precision", "filter_recall"):
        if metric not in table:
            table[metric] = np.nan
    truth = rows[(rows["method"] == "teacher") & (rows["metric"] == "true_noise")]
    chance = truth.groupby(["domain", "teacher"])["value"].mean().rename("chance")
    table = table.join(chance, on=["domain", "teacher"])
    return table[columns]

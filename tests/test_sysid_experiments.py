"""The SI engine: Algorithm 4 pretraining learns, runs are reproducible, bad configs fail before compute."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hipref import sweep
from hipref.envs.task import Clip
from hipref.envs.wiping import WipingTask
from hipref.experiments import si_methods, si_pretraining, si_run
from hipref.experiments.n_candidates import NCandidatesConfig
from hipref.experiments.protocol import SIStudy
from hipref.experiments.r2_noise import R2Config
from hipref.experiments.si_evaluation import Episode, EvaluationSpec, evaluation_episodes
from hipref.experiments.si_evaluation import evaluate as si_evaluate
from hipref.experiments.si_pretraining import (
    PretrainCell,
    PretrainData,
    collect_dataset,
    pretrain_models,
    pretrained_model,
)
from hipref.experiments.si_run import FineTuning, SIRun, run_si
from hipref.learners.pesi import PESIConfig

TINY = PretrainData(n_trajectories=24, trajectory_steps=40, pretrain_steps=400)


@pytest.fixture(autouse=True)
def _private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("HIPREF_CACHE_DIR", str(tmp_path))


def test_osi_pretraining_beats_predicting_the_midpoint_on_held_out_environments():
    model = pretrained_model("wiping", TINY)
    features, heights = collect_dataset("wiping", PretrainData(n_trajectories=8, trajectory_steps=40, seed=1))
    osi_error = np.abs(model.predict(features) - heights).mean()
    midpoint_error = np.abs(0.7 - heights).mean()
    assert osi_error < midpoint_error


def test_a_run_gives_identical_rows_twice(tmp_path, monkeypatch):
    cell = SIRun(
        "wiping", "pesi", 0.64, noise=0.2, seed=3, episodes=4, eval_every=2, eval_episodes=2, data=TINY
    )
    first = run_si(cell)
    monkeypatch.setenv("HIPREF_CACHE_DIR", str(tmp_path / "second"))
    sweep.forget_artefacts()  # learnt again, not read from memory or disk
    second = run_si(cell)
    pd.testing.assert_frame_equal(first, second)
    readouts = {"param_error", "param_error_argmax", "param_error_multislice"}
    assert set(first.metric) == {*readouts, "success_rate"}
    assert sorted(first.episode.unique()) == [0, 2, 4]


@pytest.mark.parametrize(("method", "truth"), [("pesi", 0.64), ("co_pesi", 0.74), ("bayes", 0.58)])
def test_a_shorter_run_reads_the_first_evaluations_of_a_longer_one(method, truth, tmp_path, monkeypatch):
    # CO-PESI's classifiers start after s = 16 preferences, so its short run already co-teaches.
    long = SIRun(
        "wiping", method, truth, noise=0.3, seed=2, episodes=40, eval_every=20, eval_episodes=1, data=TINY
    )
    short = dataclasses.replace(long, episodes=20)
    direct = run_si(short)  # learnt by itself
    monkeypatch.setenv("HIPREF_CACHE_DIR", str(tmp_path / "second"))
    sweep.forget_artefacts()
    longer = run_si(long)
    learnt = []
    monkeypatch.setattr(si_run, "_learn_and_evaluate", lambda cell: learnt.append(cell))
    served = run_si(short)
    assert learnt == []  # read from the longer run, not learnt again
    pd.testing.assert_frame_equal(served, direct)
    pd.testing.assert_frame_equal(longer[longer.episode <= 20].reset_index(drop=True), direct)
    assert sorted(longer.episode.unique()) == [0, 20, 40]


@pytest.mark.slow
def test_co_pesi_reports_its_filter_against_the_recorded_flips_and_it_beats_chance(monkeypatch):
    # A filter forgetting at random has as precision the flipped share of what it is offered: about the
    # teacher's realised flip rate. CO-PESI's small-loss selection by two classifiers must do clearly better.
    # Cube mass at 20 % noise over 99 preferences (R3's scale): over seeds 0-7 the precision is 0.38-0.72
    # (seed 2: 0.64) against realised flip rates of 0.16-0.28, at least 0.18 above chance at every seed.
    teachers = []
    make_teacher = si_run._teacher

    def kept_teacher(*args):
        teachers.append(make_teacher(*args))
        return teachers[-1]

    monkeypatch.setattr(si_run, "_teacher", kept_teacher)
    cell = SIRun(
        "pushing", "co_pesi", 14.0, noise=0.2, seed=2, episodes=99, eval_every=33, eval_episodes=1, data=TINY
    )
    rows = run_si(cell)
    quality = rows[rows.metric.isin(["filter_precision", "filter_recall"])]
    # Reported at every evaluation once the filter has forgotten something (undefined, so absent, at 0).
    assert sorted(quality.episode.unique()) == [33, 66, 99]
    final = quality[quality.episode == 99].set_index("metric").value
    (teacher,) = teachers
    realised = float(np.mean(teacher.wrong_labels))
    assert len(teacher.wrong_labels) == 99 and 0.1 < realised < 0.3
    assert final["filter_precision"] > max(cell.noise, realised) + 0.15
    assert 0.0 < final["filter_recall"] <= 1.0
    assert "filter_precision" not in set(
        run_si(
            SIRun("pushing", "pesi", 14.0, noise=0.3, episodes=2, eval_every=2, eval_episodes=1, data=TINY)
        ).metric
    )


@pytest.mark.slow
@pytest.mark.parametrize(
    ("domain", "truth", "method", "noise"),
    [("wiping", 0.74, "co_pesi", 0.3), ("pushing", 15.5, "pesi_ce", 0.1)],
)
def test_replayed_learning_clips_give_the_rows_of_executing_them(
    domain, truth, method, noise, tmp_path, monkeypatch
):
    cell = SIRun(
        domain, method, truth, noise=noise, seed=1, episodes=6, eval_every=3, eval_episodes=1, data=TINY
    )
    # A PESI run at another noise level executes (and caches) the clips this run then replays.
    run_si(
        SIRun(domain, "pesi", truth, noise=0.0, seed=1, episodes=6, eval_every=3, eval_episodes=1, data=TINY)
    )
    replayed = run_si(cell)
    executed = []
    monkeypatch.setattr(si_run, "learning_clips", lambda *args: executed.append(args))
    monkeypatch.setattr(Clip, "replay", lambda *args: pytest.fail("a clip was replayed"))
    monkeypatch.setenv("HIPREF_CACHE_DIR", str(tmp_path / "second"))
    sweep.forget_artefacts()  # the run learns again rather than reading its first rows
    pd.testing.assert_frame_equal(replayed, run_si(cell))
    assert len(executed) == 1


@pytest.mark.slow
def test_every_method_meets_the_same_evaluation_episodes():
    # Before any preference the methods share SI's pretrained model: equal episodes, equal first rows.
    first = [
        run_si(SIRun("pushing", method, 12.5, seed=2, episodes=2, eval_every=2, eval_episodes=3, data=TINY))
        for method in ("osi", "pesi", "pesi_ce")
    ]
    at_start = [frame[frame.episode == 0].value.tolist() for frame in first]
    assert at_start[0] == at_start[1] == at_start[2]


def test_the_true_parameter_meets_the_learners_evaluation_episodes(monkeypatch):
    # Every episode the true parameter is executed in is one a learner of the same environment meets (and
    # another seed's are others); before any answer the Bayesian learner's estimate is the middle of the
    # range, exact at a truth there, so on those episodes it succeeds exactly where the true parameter does.
    met: list[list[Episode]] = []

    def evaluate(task, model, episodes, ground_truth):
        met.append(episodes)
        return si_evaluate(task, model, episodes, ground_truth)

    monkeypatch.setattr(si_run, "evaluate", evaluate)
    cell = SIRun("wiping", "bayes", 0.7, seed=3, episodes=1, checkpoints=(0,), eval_episodes=4, data=TINY)
    exact = si_run.run_at_truth(cell).set_index("metric").value
    bayes = run_si(cell).set_index("metric").value
    si_run.run_at_truth(dataclasses.replace(cell, seed=4))
    at_truth, learner, other_seed = met

    def same(a: list[Episode], b: list[Episode]) -> bool:
        return all(
            np.array_equal(x.slices, y.slices) and all(map(np.array_equal, x.layout, y.layout))
            for x, y in zip(a, b, strict=True)
        )

    assert same(at_truth, learner) and not same(at_truth, other_seed)
    assert exact["param_error"] == bayes["param_error"] == 0.0
    assert exact["success_rate"] == bayes["success_rate"]
    assert set(si_run.run_at_truth(cell).method) == {"true_parameter"}


@pytest.mark.parametrize(
    "make",
    [
        lambda: SIRun("juggling", "pesi", 0.7),
        lambda: SIRun("wiping", "pesi", 0.7, noise=1.5),
        lambda: SIRun("wiping", "magic", 0.7),
        lambda: SIRun("wiping", "pesi", 1.2),
        lambda: SIRun("wiping", "co_pesi", 0.7, n_candidates=3),
        lambda: SIRun("wiping", "pesi", 0.7, episodes=0),
        lambda: R2Config(episodes=0),
        lambda: R2Config(heights=(0.45,)),
        lambda: R2Config(masses=()),
        lambda: PretrainData(loss="mse"),
        lambda: FineTuning(PESIConfig(candidate_sampling="nearest")),
        lambda: FineTuning(PESIConfig(batch_size=4)),  # the run's: the domain's batch size
        lambda: FineTuning(coteaching_schedule="never"),
        lambda: R2Config(noise_levels=(0.1, -0.2)),
        lambda: R2Config(domains=("juggling",)),
        lambda: NCandidatesConfig(n_candidates=(1,)),
    ],
)
def test_bad_configs_are_refused_before_any_compute(make, monkeypatch):
    def no_compute(*args, **kwargs):
        raise AssertionError("computed before validating")

    monkeypatch.setattr("hipref.experiments.si_pretraining.collect_dataset", no_compute)
    with pytest.raises(ValueError):
        make()


@pytest.mark.parametrize(
    ("make", "message"),
    [
        # Evaluated every 40 of 66 episodes, the last 26 would be learnt by no evaluated learner.
        (lambda: R2Config(episodes=66, eval_every=40), r"episodes must be a multiple of eval_every=40"),
        (lambda: SIRun("wiping", "pesi", 0.7, episodes=66, eval_every=40), "multiple of eval_every=40"),
        (lambda: R2Config(pretrain_loss="mse"), r"pretrain_loss must be one of \['brier'"),
        (lambda: R2Config(learning_rate=True), r"learning_rate must be a finite number in \[1e-08, 1.0\]"),
    ],
)
def test_a_refusal_names_the_studys_own_parameter(make, message):
    with pytest.raises(ValueError, match=message):
        make()
    # Explicit checkpoints need not fall on multiples.
    assert SIRun("wiping", "pesi", 0.7, episodes=66, checkpoints=(0, 40, 66)).evaluated_at == (0, 40, 66)


def test_the_protocol_crosses_a_fixed_grid_of_truths_with_seeds_and_osi_ignores_the_fine_tuning():
    protocol = SIStudy(heights=(0.6, 0.8), masses=(10.0,), seeds=2)
    assert protocol.environments("wiping") == [(0.6, 0), (0.6, 1), (0.8, 0), (0.8, 1)]
    assert protocol.environments("pushing") == [(10.0, 0), (10.0, 1)]
    tuned = FineTuning(PESIConfig(candidate_sampling="belief"), coteaching_schedule="reset_every_step")
    # One OSI run per environment serves every study and variant; PESI ignores the classifier schedule.
    osi = protocol.run_cell("wiping", "osi", 0.6, 0)
    assert protocol.run_cell("wiping", "osi", 0.6, 0, tuned, noise=0.3) == osi
    pesi = protocol.run_cell("wiping", "pesi", 0.6, 0, tuned)
    assert pesi.fine_tuning.coteaching_schedule == FineTuning().coteaching_schedule
    assert pesi.fine_tuning.pesi.candidate_sampling == "belief"


def test_two_truths_with_one_seed_draw_different_evaluation_episodes():
    task = WipingTask()
    first, second = (
        evaluation_episodes(task, EvaluationSpec("wiping", truth, 0, 2, 2, 3), 1)[0] for truth in (0.6, 0.8)
    )
    assert not np.array_equal(first[0].layout[0], second[0].layout[0])
    assert first[0].slices.shape == (2, 3 * first[0].slices.shape[1] // 3)


@pytest.mark.slow
def test_a_run_with_fewer_episodes_reads_the_start_of_a_longer_ones_clips_and_checkpoints(monkeypatch):
    # Built afresh, a two-checkpoint evaluation is the start of a three-checkpoint one.
    task = WipingTask()
    spec = EvaluationSpec("wiping", 0.66, 4, 1, 1, 3)
    longer = evaluation_episodes(task, spec, 3)
    sweep.forget_artefacts()
    monkeypatch.setenv("HIPREF_CACHE_DIR", str(Path(os.environ["HIPREF_CACHE_DIR"]) / "other"))
    shorter = evaluation_episodes(task, spec, 2)
    for a, b in zip(longer[:2], shorter, strict=True):
        np.testing.assert_array_equal(a[0].slices, b[0].slices)
    # So a short run replaying a long run's clips and checkpoints gives the rows of executing its own.
    short = SIRun(
        "wiping", "pesi", 0.66, noise=0.1, seed=4, episodes=4, eval_every=2, eval_episodes=1, data=TINY
    )
    run_si(dataclasses.replace(short, episodes=8))
    replayed = run_si(short)
    sweep.forget_artefacts()
    monkeypatch.setenv("HIPREF_CACHE_DIR", str(Path(os.environ["HIPREF_CACHE_DIR"]) / "fresh"))
    pd.testing.assert_frame_equal(replayed, run_si(short))


def test_pretraining_builds_each_domains_model_once_in_the_cache_the_runs_read(tmp_path, monkeypatch):
    small = PretrainData(n_trajectories=3, trajectory_steps=10, pretrain_steps=5)
    cells = [PretrainCell("wiping", small), PretrainCell("pushing", small), PretrainCell("wiping", small)]
    with monkeypatch.context() as patched:
        built: list[str] = []
        patched.setattr(si_pretraining, "pretrained_model", lambda domain, *args, **kw: built.append(domain))
        pretrain_models(cells, sweep.NO_CACHE, workers=1)
        assert built == [], "without a cache each process builds its own, so nothing is built ahead"
        pretrain_models(cells, tmp_path / "probe", workers=1)
        assert sorted(built) == ["pushing", "wiping"], "one build per distinct cell"
    pretrain_models(cells, tmp_path, workers=1)
    models = sorted(path.name.split("-")[0] for path in (tmp_path / "artefacts").glob("si_osi_*.pkl"))
    assert models == ["si_osi_pushing", "si_osi_wiping"]
    # A run then loads the model from the cache rather than building it again.
    stored = {path: path.stat().st_mtime_ns for path in (tmp_path / "artefacts").glob("si_osi_*.pkl")}
    sweep.forget_artefacts()
    pretrained_model("wiping", small, tmp_path)
    assert {path: path.stat().st_mtime_ns for path in stored} == stored


def test_notebook_02s_held_out_grid_shares_no_environment_with_the_grid_and_is_read_at_the_end() -> None:
    from hipref.experiments.r1_pesi import R1PESIConfig, cells, held_out_cells

    config = R1PESIConfig(heights=(0.6, 0.8), masses=(11.0,), seeds=2, held_out_seeds=(100, 101))
    grid = {(c.domain, c.ground_truth, c.seed) for c in cells(config)}
    held_out = held_out_cells(config)
    assert {c.method for c in held_out} == {"osi", "pesi"}
    assert len(held_out) == 2 * 2 * (1 + 1)  # methods x domains x (one held-out truth x two seeds)
    assert not grid & {(c.domain, c.ground_truth, c.seed) for c in held_out}
    assert {c.evaluated_at for c in held_out} == {(0, config.episodes)}
    for bad, name in (
        ({"held_out_heights": (0.6,)}, "held_out_heights"),
        ({"held_out_masses": ()}, "held_out_masses"),
        ({"held_out_seeds": (1,)}, "held_out_seeds"),
        ({"held_out_seeds": ()}, "held_out_seeds"),
    ):
        with pytest.raises(ValueError, match=name):
            R1PESIConfig(**{"heights": (0.6, 0.8), "seeds": 2, **bad})


@pytest.mark.parametrize("method", sorted(si_methods.LEARNING_METHODS - si_methods.BAYES_METHODS))
def test_the_coteaching_methods_are_exactly_those_whose_learner_is_co_pesi(method: str) -> None:
    from types import SimpleNamespace

    from hipref.learners.coteaching import CoTeachingFilter
    from hipref.learners.pesi import PESILearner
    from hipref.learners.sysid import DESK_HEIGHT, SIModel

    cell = SimpleNamespace(domain="wiping", noise=0.2, fine_tuning=FineTuning())
    model = SIModel(9, DESK_HEIGHT, hidden_sizes=(8,))
    learner = si_methods.LEARNERS[method](cell, model, PESIConfig(history=1), 0)  # type: ignore[arg-type]
    assert isinstance(learner, PESILearner)
    # The co-teaching schedule of a run is kept for these methods alone (SIStudy.run_cell).
    assert isinstance(learner.filter, CoTeachingFilter) == (method in si_methods.COTEACHING_METHODS)

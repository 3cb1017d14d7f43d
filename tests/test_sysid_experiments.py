"""The SI engine: Algorithm 4 pretraining learns, runs are reproducible, bad configs fail before compute."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from hipref.experiments.n_candidates import NCandidatesConfig
from hipref.experiments.r2_noise import R2Config
from hipref.experiments.sysid import (
    PretrainData,
    SIRun,
    World,
    collect_dataset,
    pretrained_model,
    run_si,
)

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


def test_a_run_gives_identical_rows_twice():
    cell = SIRun("wiping", "pesi", noise=0.2, seed=3, episodes=4, eval_every=2, eval_episodes=2, data=TINY)
    first, second = run_si(cell), run_si(cell)
    pd.testing.assert_frame_equal(first, second)
    assert set(first.metric) == {"param_error", "success_rate"}
    assert sorted(first.episode.unique()) == [0, 2, 4]


def test_every_method_meets_the_same_evaluation_episodes():
    # Before any preference the methods share SI's pretrained model: equal episodes, equal first rows.
    first = [
        run_si(SIRun("pushing", method, seed=2, episodes=2, eval_every=2, eval_episodes=3, data=TINY))
        for method in ("osi", "pesi", "pesi_ce")
    ]
    at_start = [frame[frame.episode == 0].value.tolist() for frame in first]
    assert at_start[0] == at_start[1] == at_start[2]


@pytest.mark.parametrize(("domain", "truth", "estimate"), [("wiping", 0.62, 0.66), ("pushing", 12.0, 15.0)])
def test_a_slice_is_cut_from_the_whole_clip_at_a_uniform_place(domain, truth, estimate):
    # In wiping only the periods up to the slice's end are simulated; they must be the whole clip's.
    world = World(domain)
    layout = world.sample_layout(np.random.default_rng(5))
    clip, _ = world.rollout(truth, estimate, layout)
    firsts = []
    for seed in range(40):
        tau = world.clip_slice(truth, estimate, layout, 3, np.random.default_rng(seed))
        first = int(np.random.default_rng(seed).integers(0, len(clip) - 2))
        np.testing.assert_array_equal(tau, clip[first : first + 3].reshape(-1))
        firsts.append(first)
    assert max(firsts) > len(clip) / 2  # slices from the clip's second half too


@pytest.mark.parametrize(
    "make",
    [
        lambda: SIRun("juggling", "pesi"),
        lambda: SIRun("wiping", "pesi", noise=1.5),
        lambda: SIRun("wiping", "magic"),
        lambda: SIRun("wiping", "pesi", ground_truth=1.2),
        lambda: SIRun("wiping", "co_pesi", n_candidates=3),
        lambda: R2Config(noise_levels=(0.1, -0.2)),
        lambda: R2Config(domains=("juggling",)),
        lambda: NCandidatesConfig(n_candidates=(1,)),
    ],
)
def test_bad_configs_are_refused_before_any_compute(make, monkeypatch):
    def no_compute(*args, **kwargs):
        raise AssertionError("computed before validating")

    monkeypatch.setattr("hipref.experiments.sysid.collect_dataset", no_compute)
    with pytest.raises(ValueError):
        make()

"""The Task interface both worlds implement, and the slices SI sees cut from it."""

from __future__ import annotations

import numpy as np
import pytest

from hipref.control.tool import FEATURES_PER_PERIOD, FORCE_Z
from hipref.envs.pushing import PushingTask
from hipref.envs.task import Task, clip, probe_slice
from hipref.envs.wiping import WipingTask
from hipref.sim.render import why_no_gl

TASKS = {"wiping": WipingTask, "pushing": PushingTask}


@pytest.fixture(scope="module", params=list(TASKS))
def task(request) -> Task:
    return TASKS[request.param]()


def test_a_rollout_with_the_truth_succeeds_and_one_off_by_a_quarter_of_the_range_fails(task):
    # pi^l is only as good as the estimate it is given: the study's premise, in both worlds.
    low, high = task.parameter_range
    truth, off = (low + high) / 2, (high - low) / 4
    layout = task.sample_layout(np.random.default_rng(3))
    exact = task.rollout(truth, truth, layout)
    assert exact.features.shape[1] == FEATURES_PER_PERIOD
    assert exact.success
    assert not task.rollout(truth, truth - off, layout).success
    assert not task.rollout(truth, truth + off, layout).success
    planned = task.planned_periods(layout)
    assert planned is None or planned == len(exact.features)


def test_the_same_layout_and_estimate_give_bit_identical_features_whatever_ran_before(task):
    # Clips are replayed from a cache and shared by every run of an environment: a rollout must depend on
    # its arguments alone, not on the state an earlier rollout left in the physics.
    low, high = task.parameter_range
    truth, estimate = low + 0.4 * (high - low), low + 0.5 * (high - low)
    layout = task.sample_layout(np.random.default_rng(3))
    first = task.rollout(truth, estimate, layout).features
    task.rollout(high - 0.1 * (high - low), low, task.sample_layout(np.random.default_rng(4)))
    np.testing.assert_array_equal(task.rollout(truth, estimate, layout).features, first)
    assert not np.array_equal(task.rollout(truth, estimate + 0.05 * (high - low), layout).features, first)


def test_in_wiping_a_higher_height_estimate_presses_less_and_the_truth_keeps_the_force_in_band():
    # The sponge is aimed press_depth below the estimated surface: an estimate above the truth presses
    # less (5 cm above, not at all), one below presses harder (5 cm below, past the band's top).
    task = WipingTask()
    truth, band = 0.7, task.config.force_band
    layout = task.sample_layout(np.random.default_rng(3))
    estimates = (0.65, 0.68, 0.7, 0.72, 0.75)
    forces = [task.rollout(truth, estimate, layout).features[:, FORCE_Z] for estimate in estimates]
    means = [force.mean() for force in forces]
    assert np.all(np.diff(means) < 0)
    in_band = {e: np.mean((f >= band[0]) & (f <= band[1])) for e, f in zip(estimates, forces, strict=True)}
    assert in_band[truth] >= task.config.in_band_fraction
    assert in_band[truth] > in_band[0.65] + 0.5 and in_band[truth] > in_band[0.75] + 0.5


def test_a_push_is_executed_whole_and_a_wrong_mass_estimate_misses_the_goal():
    task = PushingTask()
    layout = task.sample_layout(np.random.default_rng(0))
    with pytest.raises(ValueError, match="executed whole"):
        task.rollout(14.0, 14.0, layout, periods=5)
    # The rollout is the whole push, until the cube rests: the same periods as the push itself.
    task.reset(14.0, *layout)
    push = task.push(14.0)
    np.testing.assert_array_equal(task.rollout(14.0, 14.0, layout).features, push.features)
    # A light estimate under-pushes, a heavy one over-pushes: both rest farther from the goal.
    miss = {
        estimate: task.episode_metrics(14.0, estimate, layout)["goal_distance"] for estimate in (11, 14, 17)
    }
    tolerance = task.config.scene.goal_tolerance
    assert miss[14] <= tolerance / 2
    assert miss[11] > tolerance and miss[17] > tolerance


@pytest.mark.parametrize(("domain", "truth", "estimate"), [("wiping", 0.62, 0.66), ("pushing", 12.0, 15.0)])
def test_a_slice_is_cut_from_the_whole_clip_at_a_uniform_place(domain, truth, estimate):
    # In wiping only the periods up to the slice's end are simulated; they must be the whole clip's.
    task = TASKS[domain]()
    layout = task.sample_layout(np.random.default_rng(5))
    whole = task.rollout(truth, estimate, layout).features
    places = len(whole) - 2  # where a slice of 3 periods can start
    starts = []
    for seed in range(40):
        cut = clip(task, truth, estimate, layout, 3, np.random.default_rng(seed))
        # Brute force: every place of the whole clip whose 3 periods are the slice, bit for bit.
        found = [f for f in range(places) if np.array_equal(cut.tau, whole[f : f + 3].reshape(-1))]
        assert cut.first in found and cut.periods == len(whole)
        starts.append(cut.first)
    # Uniform over the places: 40 draws all missing the first or the last quarter has chance 2 * 0.75^40.
    assert min(starts) < places / 4 and max(starts) >= 3 * places / 4


def test_a_replayed_clip_refuses_a_query_it_was_not_executed_for():
    task = WipingTask()
    layout = task.sample_layout(np.random.default_rng(0))
    executed = clip(task, 0.7, 0.6, layout, 3, np.random.default_rng(1))
    np.testing.assert_array_equal(executed.replay(0.6, 3, np.random.default_rng(1)), executed.tau)
    with pytest.raises(RuntimeError, match="depend on what the learner has learnt"):
        executed.replay(0.62, 3, np.random.default_rng(1))


def test_a_probing_slice_has_h_periods_of_features_that_depend_on_the_true_parameter(task):
    # Same generator, so the same estimate, layout and place: only the truth differs between the two.
    low, high = task.parameter_range
    near_low = probe_slice(task, low + 0.1 * (high - low), 3, np.random.default_rng(2))
    near_high = probe_slice(task, high - 0.1 * (high - low), 3, np.random.default_rng(2))
    assert near_low.shape == near_high.shape == (3 * 21,) and np.isfinite(near_low).all()
    assert not np.array_equal(near_low, near_high)
    np.testing.assert_array_equal(
        probe_slice(task, low + 0.1 * (high - low), 3, np.random.default_rng(2)), near_low
    )


def test_a_clip_is_rendered_frame_by_frame_where_gl_is(task):
    low, high = task.parameter_range
    layout = task.sample_layout(np.random.default_rng(4))
    truth, estimate = low + 0.3 * (high - low), low + 0.35 * (high - low)
    frames = task.clip_frames(truth, estimate, layout, frames=12)
    if frames is None:
        assert why_no_gl() is not None  # the check `make teach` runs says so too
        pytest.skip("no OpenGL context on this machine: clips are not rendered (the message says why)")
    assert why_no_gl() is None
    assert len(frames) == 12
    assert frames[0].shape == (240, 320, 3)
    assert not np.array_equal(frames[0], frames[-1])  # the arm (and the cube) moved

"""The pushing task: layouts are reachable, the cube really has the mass it is given, and the push
succeeds with the true mass but not with a mass estimate that is off by several kg."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from hipref.envs.pushing import PushingTask
from hipref.envs.pushing_config import PushingConfig


@pytest.fixture(scope="module")
def task() -> PushingTask:
    return PushingTask()


def test_layout_inside_area_and_reset_touches_cube(task: PushingTask) -> None:
    cfg = task.config
    rng = np.random.default_rng(1)
    for _ in range(5):
        start, goal = task.sample_layout(rng)
        for point in (start, goal):
            assert cfg.area_x[0] <= point[0] <= cfg.area_x[1]
            assert cfg.area_y[0] <= point[1] <= cfg.area_y[1]
        assert cfg.push_distance[0] - 1e-9 <= np.linalg.norm(goal - start) <= cfg.push_distance[1] + 1e-9
        task.reset(12.0, start, goal)
        scene = task.scene
        tip = scene.data.site_xpos[scene.tool_tip]
        expected = start - task.direction * task.poses.standoff()
        assert np.linalg.norm(tip[:2] - expected) < cfg.reach_residual


def test_cube_moves_with_the_mass_it_is_given(task: PushingTask) -> None:
    """MuJoCo caches a free body's mass matrix: reset must refresh it, or every cube weighs 10 kg."""
    start, goal = task.sample_layout(np.random.default_rng(2))
    scene = task.scene
    full = np.zeros((scene.model.nv, scene.model.nv))
    for mass in (8.0, 19.0):
        task.reset(mass, start, goal)
        mujoco.mj_fullM(scene.model, scene.data, full)
        dof = scene.cube_dof
        assert np.allclose(np.diag(full)[dof : dof + 3], mass)
        assert task.mass == pytest.approx(mass)


def test_push_features_and_mass_dependence(task: PushingTask) -> None:
    rng = np.random.default_rng(0)
    exact, off = [], []
    for _ in range(6):
        mass = rng.uniform(12.0, 16.0)  # so that mass +- 4 kg stays in range
        start, goal = task.sample_layout(rng)
        task.reset(mass, start, goal)
        push = task.push(mass)
        assert push.features.ndim == 2 and push.features.shape[1] == 21
        assert push.cube_xy.shape == (len(push.features), 2)
        assert np.all(np.isfinite(push.features))
        exact.append(push.success)
        for error in (-4.0, 4.0):
            task.reset(mass, start, goal)
            off.append(task.push(mass + error).success)
    assert np.mean(exact) >= 5 / 6
    assert np.mean(off) <= 0.25


def test_config_rejects_bad_values() -> None:
    with pytest.raises(ValueError):
        PushingConfig(tilt=1.0)
    with pytest.raises(ValueError):
        PushingConfig(push_distance=(0.2, 0.1))


def test_episode_metrics_split_the_miss_along_and_across_the_push(task: PushingTask) -> None:
    """A push planned for a heavier cube overshoots its goal, one for a lighter cube stops short; the two
    parts of the miss make up its distance, and a push refuses the routes of a learned stroke."""
    layout = task.sample_layout(np.random.default_rng(3))
    heavy = task.episode_metrics(14.0, 18.0, layout)
    light = task.episode_metrics(14.0, 10.0, layout)
    assert heavy["goal_overshoot"] > 0 > light["goal_overshoot"]
    for metrics in (heavy, light):
        miss = np.hypot(metrics["goal_overshoot"], metrics["goal_sideways"])
        assert miss == pytest.approx(metrics["goal_distance"])
        assert not metrics["success_rate"]
    with pytest.raises(ValueError, match="route"):
        task.episode_metrics(14.0, 14.0, layout, route="input")

"""The compiled push (`hipref.control.push.execute_push`): the admittance law tracks the planned force
against the cube's reaction, the brake lets the cube slide free to rest, and the features record each
control period with its own row of the perturbation."""

from __future__ import annotations

import numpy as np
import pytest

from hipref.control.tool import ARM_POSITIONS, FEATURES_PER_PERIOD
from hipref.envs.low_level import no_perturbation
from hipref.envs.pushing import PushingTask

WRIST_FORCE = slice(12, 15)
"""The wrist force's columns of a period's features."""


@pytest.fixture(scope="module")
def task() -> PushingTask:
    return PushingTask()


def _push(task: PushingTask, mass: float, estimate: float, seed: int, perturbation: np.ndarray | None = None):
    """The analytic push of a cube of `mass` planned with `estimate` from the layout of `seed`: its
    features, cube positions and tool tip positions per control period."""
    task.reset(mass, *task.sample_layout(np.random.default_rng(seed)))
    return task._expert_push(estimate, no_perturbation(1) if perturbation is None else perturbation)


def _push_periods(task: PushingTask, estimate: float) -> int:
    """Whole control periods of the push phase (before the brake)."""
    return int(task.plan(estimate)[1] / task.control_period)


@pytest.mark.parametrize("mass", [10.0, 18.0])
def test_the_wrist_feels_the_force_that_accelerates_the_cube_as_planned(
    task: PushingTask, mass: float
) -> None:
    # M_d x_d'' = F - R with F = (M_d + m) a + mu m g: with the true mass the tool and cube accelerate at
    # the planned a, so the cube's reaction R is what moves the cube alone, m (a + mu g), not F.
    cfg = task.config
    a, mu_g = cfg.planned_acceleration, cfg.scene.cube_friction * abs(cfg.scene.gravity)
    for seed in (0, 1):
        features, _, _ = _push(task, mass, mass, seed)
        direction = np.array([*task.direction, 0.0])
        reaction = -features[:, WRIST_FORCE] @ direction
        during = reaction[2 : _push_periods(task, mass)].mean()  # past the first contact's transient
        assert during == pytest.approx(mass * (a + mu_g), rel=0.15)
        assert during < 0.85 * task.plan(mass)[0]


def test_the_cube_slides_straight_to_rest_free_of_the_paddle(task: PushingTask) -> None:
    for seed in (0, 1, 2):
        features, cube_xy, _ = _push(task, 14.0, 14.0, seed)
        moved = cube_xy[-1] - task.start
        along = moved @ task.direction
        across = abs(moved[0] * task.direction[1] - moved[1] * task.direction[0])
        assert along > 0.05 and across < 0.05 * along
        # The push ends once the cube has come to rest, as its last period recorded it.
        scene = task.scene
        speed = np.linalg.norm(scene.data.qvel[scene.cube_dof : scene.cube_dof + 6])
        assert speed < task.config.rest_speed
        np.testing.assert_array_equal(cube_xy[-1], scene.data.qpos[scene.cube_qpos : scene.cube_qpos + 2])
        np.testing.assert_array_equal(features[-1, ARM_POSITIONS], scene.data.qpos[scene.arm_qpos])
        # Braked far faster than friction stops the cube, the paddle is left behind: no force at the wrist.
        push_force = np.abs(features[: _push_periods(task, 14.0), WRIST_FORCE]).max()
        assert np.abs(features[-5:, WRIST_FORCE]).max() < 0.01 * push_force


def test_each_period_tracks_its_own_row_of_the_perturbation_and_then_the_last(task: PushingTask) -> None:
    plain, _, _ = _push(task, 14.0, 14.0, 0)
    assert plain.shape[1] == FEATURES_PER_PERIOD
    zeros, _, _ = _push(task, 14.0, 14.0, 0, np.zeros((4, 6)))
    np.testing.assert_array_equal(zeros, plain)
    # Perturbed from period k on: the periods before it are the unperturbed push's, bit for bit.
    k, offset = 10, np.array([0.0, 0.02, -0.02, 0.0, 0.0, 0.0])
    short = np.zeros((k + 1, 6))
    short[k] = offset
    perturbed, _, _ = _push(task, 14.0, 14.0, 0, short)
    np.testing.assert_array_equal(perturbed[:k], plain[:k])
    assert not np.array_equal(perturbed[k], plain[k])
    # A push outlasting the perturbation keeps tracking its last row, as if it went on for every period.
    long = np.zeros((3 * len(plain), 6))
    long[k:] = offset
    np.testing.assert_array_equal(_push(task, 14.0, 14.0, 0, long)[0], perturbed)


@pytest.mark.parametrize("angle", [0.0, 0.7])
def test_the_target_yields_to_the_force_across_the_push_but_not_along_it(angle: float) -> None:
    # SPD lets the arm yield by kp^-1 J^T f. The target makes up for that yield across and above the push,
    # so the paddle stays put, and keeps it along the push, a series spring in the force loop. With J = I
    # and kp^-1 = c per joint, the yield is c f.
    from hipref.control.push import PushPlan, _push_target

    u = np.array([np.cos(angle), np.sin(angle), 0.0])
    across = np.array([-u[1], u[0], 0.0])
    c, lead, along, speed = 1e-3, 0.02, 0.1, 0.3
    plan = PushPlan(
        u, np.array([0.4, -0.1, 0.8]), np.eye(3), np.full(6, c), lead, 10.0, 100, 1.0, 100, 0.01, 10, 0, 0
    )
    reference = plan.tool_start + u * (along + lead * speed)

    def target(force: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        position, rotation = np.zeros(3), np.zeros((3, 3))
        _push_target.py_func(np.eye(6), plan, along, speed, force, np.zeros(6), position, rotation)
        return position, rotation

    position, rotation = target(30.0 * u)
    np.testing.assert_allclose(position, reference, atol=1e-12)  # along the push: no compensation
    np.testing.assert_allclose(rotation, np.eye(3), atol=1e-12)
    position, _ = target(30.0 * u + 20.0 * across + 5.0 * np.array([0.0, 0.0, 1.0]))
    np.testing.assert_allclose(position, reference - c * (20.0 * across + [0.0, 0.0, 5.0]), atol=1e-12)

"""The compiled control loop computes the paper's equations: for one state, its SPD torques match a plain
numpy evaluation of Eq. 5-6, its joint reference matches Eq. 7 and a damped least-squares IK step, and its
wrist force matches the scene's tared sensor reading."""

from __future__ import annotations

import os
import subprocess
import sys

import mujoco
import numpy as np
import pytest

from hipref.control.compiled import physics_of
from hipref.control.ik import DAMPING
from hipref.envs.wiping import WipingTask


def spd_reference(
    model: mujoco.MjModel, data: mujoco.MjData, kp: np.ndarray, kd: np.ndarray, q_ref: np.ndarray
) -> np.ndarray:
    """Eq. 5-6 in numpy at the state of `data` (after mj_step1), the arm being the first six dofs."""
    arm, dt = slice(0, 6), model.opt.timestep
    full = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, full)
    q, qdot = data.qpos[arm], data.qvel[arm]
    c = data.qfrc_bias[arm] - data.qfrc_passive[arm]
    tau_ext = data.qfrc_constraint[arm]
    position = kp * (q + qdot * dt - q_ref)
    qddot = np.linalg.solve(full[arm, arm] + np.diag(kd * dt), -c - position - kd * qdot + tau_ext)
    return -position - kd * (qdot + qddot * dt)


def close(actual: np.ndarray, expected: np.ndarray, rtol: float = 1e-9) -> bool:
    return float(np.max(np.abs(actual - expected))) <= rtol * float(np.max(np.abs(expected)))


@pytest.fixture(scope="module")
def pressing() -> WipingTask:
    """The sponge pressed on the desk and moving: contact forces and joint velocities are all non-zero."""
    task = WipingTask()
    task.reset(0.7, (-0.1, 0.05))
    task.approach(0.7)
    target = task.reference.copy()
    data = task.scene.data
    # Slide along the desk, ending on a step with the sponge in contact (it chatters while it slides).
    for period in range(100):
        target[0] += task.config.scene.tool_speed * task.config.scene.control_period
        task.controller.run(target, task.rotation)
        if period >= 3 and np.all(data.qfrc_constraint[:6] != 0.0):
            break
    task.reference[:] = target
    return task


def test_one_physics_step_of_the_kernel_is_eq_5_to_7(pressing: WipingTask) -> None:
    task, controller = pressing, pressing.controller
    model, data = task.scene.model, task.scene.data
    before = mujoco.MjData(model)
    mujoco.mj_copyData(before, model, data)
    force_before = controller.force.copy()
    admittance_before = controller.admittance.copy()
    target = task.reference + np.array([0.001, 0.0, 0.0])

    controller.substeps = 1
    try:
        controller.run(target, task.rotation)
    finally:
        controller.substeps = task.config.scene.control_substeps

    # Eq. 7 along z, implicit Euler over the control period, driven by the last period's wrist force.
    gains, dt = controller.config.admittance, task.config.scene.control_period
    offset, rate = admittance_before
    rate = (gains.inertia * rate + dt * (force_before[2] - gains.stiffness * offset)) / (
        gains.inertia + gains.damping * dt + gains.stiffness * dt * dt
    )
    offset += rate * dt
    assert np.allclose(controller.admittance, [offset, rate], rtol=1e-12, atol=0.0)
    reference = target.copy()
    reference[2] += offset

    # One damped least-squares IK step from the kinematics of the last physics step.
    site = task.scene.tool_tip
    jacp, jacr = np.zeros((3, model.nv)), np.zeros((3, model.nv))
    mujoco.mj_jacSite(model, before, jacp, jacr, site)
    jac = np.vstack([jacp[:, :6], jacr[:, :6]])
    rot = before.site_xmat[site].reshape(3, 3)
    s = task.rotation @ rot.T
    error = np.concatenate(
        [
            reference - before.site_xpos[site],
            0.5 * np.array([s[2, 1] - s[1, 2], s[0, 2] - s[2, 0], s[1, 0] - s[0, 1]]),
        ]
    )
    q_ref = before.qpos[:6] + jac.T @ np.linalg.solve(jac @ jac.T + DAMPING * np.eye(6), error)
    assert close(controller.q_ref, q_ref)

    # Eq. 5-6 between mj_step1 and mj_step2, at a state with contact and motion.
    mujoco.mj_step1(model, before)
    assert np.all(np.abs(before.qfrc_constraint[:6]) > 0.0) and np.all(np.abs(before.qvel[:6]) > 0.0)
    expected = spd_reference(model, before, controller.spd.kp, controller.spd.kd, controller.q_ref)
    assert close(data.ctrl, expected)

    # The wrist force: the tared sensor reading in the world frame.
    assert close(controller.force, task.scene.wrist_force_world(), rtol=1e-12)


def test_a_view_of_another_models_data_is_refused(pressing: WipingTask) -> None:
    other = WipingTask().scene
    with pytest.raises(ValueError, match="MjData of the given model"):
        physics_of(pressing.scene.model, other.data)


def test_a_missing_numba_names_the_package_to_install() -> None:
    script = "import sys\nsys.modules['numba'] = None\nimport hipref.control.compiled\n"
    result = subprocess.run(
        [sys.executable, "-c", script], env=dict(os.environ), capture_output=True, text=True, timeout=120
    )
    assert result.returncode != 0
    assert "pip install numba==0.68.1" in result.stderr

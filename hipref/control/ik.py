"""Inverse kinematics of the tool: damped least squares on the tool-tip site (position and orientation).

The admittance controller produces a Cartesian reference; one `ik_step` turns it into the joint reference
q-bar that SPD tracks (paper A.7, Fig. 6). `ToolIK.solve` iterates the same step to convergence and is
used to place the arm at the start of an episode."""

from __future__ import annotations

import math
from typing import NamedTuple

import mujoco
import numpy as np

from hipref.control.compiled import (
    Physics,
    kernel,
    mj_comPos,
    mj_jacSite,
    mj_kinematics,
    physics_of,
    subroutine,
)
from hipref.control.linalg import cholesky_solve
from hipref.sim.scene import Scene

DAMPING = 1e-4
"""Damping of the least-squares step, in m^2: keeps the step bounded near singular poses."""


def tool_down_rotation(yaw: float) -> np.ndarray:
    """World orientation of the tool pointing straight down (its z axis along -z), turned by `yaw`."""
    c, s = math.cos(yaw), math.sin(yaw)
    # Columns: tool x, y, z axes in the world frame.
    return np.array([[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]])


class IK(NamedTuple):
    """The tool-tip site, the arm's joints, and scratch arrays reused by every step."""

    site: int
    """The tool-tip site."""
    dof: int
    """The arm's first degree of freedom; its six joints are contiguous, at the same qpos addresses."""
    jacp: np.ndarray
    """3 x nv translational Jacobian of the site, from mj_jacSite."""
    jacr: np.ndarray
    """3 x nv rotational Jacobian."""
    jac: np.ndarray
    """6 x 6: the site's Jacobian restricted to the arm, translation rows first."""
    error: np.ndarray
    system: np.ndarray
    factor: np.ndarray
    solution: np.ndarray


def make_ik(scene: Scene) -> IK:
    """IK of the scene's tool tip over its arm's joints."""
    nv, n = scene.model.nv, len(scene.arm_dof)
    return IK(
        site=int(scene.tool_tip),
        dof=int(scene.arm_dof[0]),
        jacp=np.zeros((3, nv)),
        jacr=np.zeros((3, nv)),
        jac=np.zeros((6, n)),
        error=np.zeros(6),
        system=np.zeros((6, 6)),
        factor=np.zeros((6, 6)),
        solution=np.zeros(6),
    )


@subroutine
def tool_jacobian(ik: IK, physics: Physics) -> None:
    """ik.jac at the kinematics already computed in mjData (site poses from the last mj_step1)."""
    mj_jacSite(physics.model, physics.data, ik.jacp.ctypes.data, ik.jacr.ctypes.data, ik.site)
    for j in range(ik.jac.shape[1]):
        for r in range(3):
            ik.jac[r, j] = ik.jacp[r, ik.dof + j]
            ik.jac[3 + r, j] = ik.jacr[r, ik.dof + j]


@subroutine
def pose_error(ik: IK, physics: Physics, target_pos: np.ndarray, target_rot: np.ndarray) -> float:
    """ik.error: position error, then the small-angle orientation error (the axis-angle vector of
    target_rot @ rot.T, world frame); returns its norm."""
    rot = physics.site_xmat[ik.site]  # row-major 3 x 3
    error = ik.error
    for r in range(3):
        error[r] = target_pos[r] - physics.site_xpos[ik.site, r]

    def s(a: int, b: int) -> float:  # (target_rot @ rot.T)[a, b]
        return (
            target_rot[a, 0] * rot[3 * b]
            + target_rot[a, 1] * rot[3 * b + 1]
            + target_rot[a, 2] * rot[3 * b + 2]
        )

    error[3] = 0.5 * (s(2, 1) - s(1, 2))
    error[4] = 0.5 * (s(0, 2) - s(2, 0))
    error[5] = 0.5 * (s(1, 0) - s(0, 1))
    total = 0.0
    for r in range(6):
        total += error[r] * error[r]
    return math.sqrt(total)


@subroutine
def ik_step(
    ik: IK, physics: Physics, target_pos: np.ndarray, target_rot: np.ndarray, q_out: np.ndarray
) -> None:
    """One damped least-squares step, ik.jac at the current state (`tool_jacobian` called before):
    q_out = q + J^T (J J^T + damping I)^-1 e, the joint positions that move the tool towards the target."""
    pose_error(ik, physics, target_pos, target_rot)
    jac, system = ik.jac, ik.system
    for i in range(6):
        for j in range(i + 1):
            entry = 0.0
            for k in range(jac.shape[1]):
                entry += jac[i, k] * jac[j, k]
            system[i, j] = entry
            system[j, i] = entry
        system[i, i] += DAMPING
    cholesky_solve(system, ik.error, ik.factor, ik.solution)
    for k in range(jac.shape[1]):
        step = 0.0
        for i in range(6):
            step += jac[i, k] * ik.solution[i]
        q_out[k] = physics.qpos[ik.dof + k] + step


@kernel
def _solve(
    ik: IK,
    physics: Physics,
    target_pos: np.ndarray,
    target_rot: np.ndarray,
    iterations: int,
    tolerance: float,
    q_out: np.ndarray,
) -> float:
    """`ToolIK.solve`'s iteration on the MjData behind `physics`: the joints go to q_out, the remaining
    position error in m is returned."""
    n = q_out.shape[0]
    for _ in range(iterations):
        mj_kinematics(physics.model, physics.data)
        mj_comPos(physics.model, physics.data)  # the Jacobian needs the dof axes it computes
        if pose_error(ik, physics, target_pos, target_rot) < tolerance:
            break
        tool_jacobian(ik, physics)
        ik_step(ik, physics, target_pos, target_rot, q_out)
        for k in range(n):
            physics.qpos[ik.dof + k] = q_out[k]
    mj_kinematics(physics.model, physics.data)
    for k in range(n):
        q_out[k] = physics.qpos[ik.dof + k]
    residual = 0.0
    for r in range(3):
        error = target_pos[r] - physics.site_xpos[ik.site, r]
        residual += error * error
    return math.sqrt(residual)


class ToolIK:
    """Inverse kinematics of one scene's tool tip, to place the arm for an episode."""

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        self.ik = make_ik(scene)

    def solve(
        self,
        data: mujoco.MjData,
        target_pos: np.ndarray,
        target_rot: np.ndarray,
        *,
        iterations: int = 200,
        tolerance: float = 1e-5,
    ) -> tuple[np.ndarray, float]:
        """Iterate the damped least-squares step on `data` (a scratch MjData of the scene's model: its qpos
        is overwritten) from its arm's current joint positions until the pose error is below tolerance.
        Returns the joint positions and the remaining position error in m."""
        q = np.zeros(len(self.scene.arm_dof))
        residual = _solve(
            self.ik,
            physics_of(self.scene.model, data),
            np.array(target_pos, dtype=float, order="C"),
            np.array(target_rot, dtype=float, order="C"),
            int(iterations),
            float(tolerance),
            q,
        )
        return q, residual

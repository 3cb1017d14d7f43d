"""Inverse kinematics of the tool: damped least squares on the tool-tip site (position and orientation).

The admittance controller produces a Cartesian reference; `ik_step` turns it into the joint reference
q-bar that SPD tracks (paper A.7, Fig. 6). `solve_ik` iterates the same step to convergence and is used
to place the arm at the start of an episode."""

from __future__ import annotations

import mujoco
import numpy as np

from hipref.control.linalg import SPDSolver
from hipref.sim.scene import Scene

DAMPING = 1e-4
"""Damping of the least-squares step, in m^2: keeps the step bounded near singular poses."""


def tool_down_rotation(yaw: float) -> np.ndarray:
    """World orientation of the tool pointing straight down (its z axis along -z), turned by `yaw`."""
    c, s = np.cos(yaw), np.sin(yaw)
    # Columns: tool x, y, z axes in the world frame.
    return np.array([[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]])


class ToolIK:
    """Differential IK for the tool tip, reusing its Jacobian buffers across calls."""

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        nv = scene.model.nv
        self._jacp = np.zeros((3, nv))
        self._jacr = np.zeros((3, nv))
        self._jac = np.zeros((6, 6))
        self._error = np.zeros(6)
        self._damping = DAMPING * np.eye(6)
        self._solver = SPDSolver(6)

    def _pose_error(self, data: mujoco.MjData, target_pos: np.ndarray, target_rot: np.ndarray) -> np.ndarray:
        site = self.scene.tool_tip
        rot = data.site_xmat[site].reshape(3, 3)
        self._error[:3] = target_pos - data.site_xpos[site]
        # Small-angle orientation error, the axis-angle vector of target_rot @ rot.T (world frame).
        s = target_rot @ rot.T
        self._error[3] = 0.5 * (s[2, 1] - s[1, 2])
        self._error[4] = 0.5 * (s[0, 2] - s[2, 0])
        self._error[5] = 0.5 * (s[1, 0] - s[0, 1])
        return self._error

    def step(self, data: mujoco.MjData, target_pos: np.ndarray, target_rot: np.ndarray) -> np.ndarray:
        """One damped least-squares step: the joint positions that move the tool towards the target.

        Uses the kinematics already computed in `data` (site poses from the last mj_step)."""
        scene = self.scene
        error = self._pose_error(data, target_pos, target_rot)
        mujoco.mj_jacSite(scene.model, data, self._jacp, self._jacr, scene.tool_tip)
        jac = self._jac
        jac[:3] = self._jacp[:, scene.arm_dof]
        jac[3:] = self._jacr[:, scene.arm_dof]
        dq = jac.T @ self._solver.solve(jac @ jac.T + self._damping, error)
        return data.qpos[scene.arm_qpos] + dq

    def solve(
        self,
        data: mujoco.MjData,
        target_pos: np.ndarray,
        target_rot: np.ndarray,
        *,
        iterations: int = 200,
        tolerance: float = 1e-5,
    ) -> tuple[np.ndarray, float]:
        """Iterate `step` on `data` (a scratch MjData: its qpos is overwritten) until the pose error is
        below tolerance. Returns the joint positions and the remaining position error in m."""
        model = self.scene.model
        for _ in range(iterations):
            mujoco.mj_kinematics(model, data)
            mujoco.mj_comPos(model, data)  # the Jacobian needs the dof axes it computes
            if np.linalg.norm(self._pose_error(data, target_pos, target_rot)) < tolerance:
                break
            data.qpos[self.scene.arm_qpos] = self.step(data, target_pos, target_rot)
        mujoco.mj_kinematics(model, data)
        residual = float(np.linalg.norm(target_pos - data.site_xpos[self.scene.tool_tip]))
        return data.qpos[self.scene.arm_qpos].copy(), residual

"""Stable proportional-derivative control (Tan et al. 2011), paper A.7 Eq. 5-6.

Eq. 4, the arm's dynamics: M(q) q'' + c(q, q') = tau + tau_ext. SPD evaluates the PD law at the next
time step's state, predicting the acceleration with the full mass matrix, so high gains stay stable at
the simulator's time step."""

from __future__ import annotations

import mujoco
import numpy as np

from hipref.control.linalg import SPDSolver
from hipref.sim.scene import Scene


class SPD:
    """Joint-space SPD: call between mj_step1 (which computes M and c at the current state) and mj_step2."""

    def __init__(self, scene: Scene, kp: np.ndarray, kd: np.ndarray) -> None:
        self.scene = scene
        self.kp = np.asarray(kp, dtype=float)
        self.kd = np.asarray(kd, dtype=float)
        self.dt = scene.model.opt.timestep
        nv = scene.model.nv
        self._full_mass = np.zeros((nv, nv))
        dofs = scene.arm_dof
        # The arm's dofs come first and are contiguous, so slices (views) pick its block without copies.
        if not np.array_equal(dofs, np.arange(dofs[0], dofs[0] + len(dofs))):
            raise ValueError("the arm's degrees of freedom must be contiguous")
        self._dofs = slice(int(dofs[0]), int(dofs[0]) + len(dofs))
        self._mass = self._full_mass[self._dofs, self._dofs]  # a view, refreshed by mj_fullM
        self._kd_dt = np.diag(self.kd * self.dt)
        self._solver = SPDSolver(len(dofs))

    def torque(self, q_ref: np.ndarray) -> np.ndarray:
        """Eq. 5 with the acceleration of Eq. 6, towards the joint reference q-bar^{n+1} = q_ref."""
        m, d, dofs, dt = self.scene.model, self.scene.data, self._dofs, self.dt
        q = d.qpos[dofs]  # the arm's qpos and qvel addresses coincide with its dof addresses
        qdot = d.qvel[dofs]
        mujoco.mj_fullM(m, d, self._full_mass)
        # c: Coriolis, centrifugal and gravitational forces net of the simulator's gravity compensation.
        c = d.qfrc_bias[dofs] - d.qfrc_passive[dofs]
        # tau_ext: contact and other constraint forces on the joints, as measured at the last step.
        tau_ext = d.qfrc_constraint[dofs]
        position_term = self.kp * (q + qdot * dt - q_ref)
        # Eq. 6: q''^n = (M + kd dt)^-1 (-c - kp (q^n + q'^n dt - qbar^{n+1}) - kd q'^n + tau_ext)
        qddot = self._solver.solve(self._mass + self._kd_dt, tau_ext - c - position_term - self.kd * qdot)
        # Eq. 5: tau = -kp (q^n + q'^n dt - qbar^{n+1}) - kd (q'^n + q''^n dt)
        return -position_term - self.kd * (qdot + qddot * dt)

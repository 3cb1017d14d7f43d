"""Stable proportional-derivative control (Tan et al. 2011), paper A.7 Eq. 5-6.

Eq. 4, the arm's dynamics: M(q) q'' + c(q, q') = tau + tau_ext. SPD evaluates the PD law at the next
time step's state, predicting the acceleration with the full mass matrix, so high gains stay stable at
the simulator's time step. `spd_torque` is Eq. 5-6 at the current state; `spd_physics_step` is one
physics step with it in the loop, evaluated between mj_step1 (which brings M, c and tau_ext up to the
current state) and mj_step2."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from hipref.control.compiled import Physics, mj_fullM, mj_step1, mj_step2, subroutine
from hipref.control.linalg import cholesky_solve
from hipref.sim.scene import Scene


class SPD(NamedTuple):
    """SPD's gains, the arm's place in the model, and scratch arrays reused at every physics step."""

    kp: np.ndarray
    """Diagonal of k_p, one gain per arm joint."""
    kd: np.ndarray
    """Diagonal of k_d."""
    dt: float
    """The physics time step Delta t."""
    dof: int
    """The arm's first degree of freedom; its joints are dof, ..., dof + 5, at the same qpos addresses."""
    full_mass: np.ndarray
    """nv x nv, filled by mj_fullM."""
    system: np.ndarray
    factor: np.ndarray
    rhs: np.ndarray
    qddot: np.ndarray


def make_spd(scene: Scene, kp: np.ndarray, kd: np.ndarray) -> SPD:
    """SPD for the scene's arm with gains k_p, k_d (one per joint, shoulder to wrist)."""
    m = scene.model
    dofs, qpos = scene.arm_dof, scene.arm_qpos
    n = len(dofs)
    # The arm's dofs come first and are contiguous, and hinges have one qpos per dof at the same address.
    if not (np.array_equal(dofs, np.arange(dofs[0], dofs[0] + n)) and np.array_equal(dofs, qpos)):
        raise ValueError("the arm's degrees of freedom must be contiguous and at its qpos addresses")
    # The torques are written to ctrl in joint order: actuator i must drive the arm's i-th joint.
    joints = [int(m.dof_jntid[v]) for v in dofs]
    if m.nu != n or [int(j) for j in m.actuator_trnid[:, 0]] != joints:
        raise ValueError("actuator i must drive the arm's i-th joint")
    kp = np.array(kp, dtype=float)
    kd = np.array(kd, dtype=float)
    if kp.shape != (n,) or kd.shape != (n,):
        raise ValueError(f"kp and kd must have one gain per arm joint ({n})")
    return SPD(
        kp=kp,
        kd=kd,
        dt=float(m.opt.timestep),
        dof=int(dofs[0]),
        full_mass=np.zeros((m.nv, m.nv)),
        system=np.zeros((n, n)),
        factor=np.zeros((n, n)),
        rhs=np.zeros(n),
        qddot=np.zeros(n),
    )


@subroutine
def spd_torque(spd: SPD, physics: Physics, q_ref: np.ndarray, torque: np.ndarray) -> None:
    """Eq. 5 with the acceleration of Eq. 6, towards the joint reference q-bar^{n+1} = q_ref.

    Reads q, q' and the forces from mjData and M from `spd.full_mass` (mj_fullM at the same state);
    writes the arm's torques to `torque`."""
    kp, kd, dt, dof = spd.kp, spd.kd, spd.dt, spd.dof
    system, rhs = spd.system, spd.rhs
    q, qdot = physics.qpos, physics.qvel
    n = kp.shape[0]
    for i in range(n):
        for j in range(n):
            system[i, j] = spd.full_mass[dof + i, dof + j]
        # M + kd dt, kd diagonal.
        system[i, i] += kd[i] * dt
        v = dof + i
        # c: Coriolis, centrifugal and gravitational forces net of the simulator's gravity compensation.
        c = physics.qfrc_bias[v] - physics.qfrc_passive[v]
        # tau_ext: contact and other constraint forces on the joints, as measured at the last step.
        tau_ext = physics.qfrc_constraint[v]
        position_term = kp[i] * (q[v] + qdot[v] * dt - q_ref[i])
        # Eq. 6's right-hand side: -c - kp (q^n + q'^n dt - qbar^{n+1}) - kd q'^n + tau_ext
        rhs[i] = tau_ext - c - position_term - kd[i] * qdot[v]
        torque[i] = -position_term
    # Eq. 6: q''^n = (M + kd dt)^-1 (-c - kp (q^n + q'^n dt - qbar^{n+1}) - kd q'^n + tau_ext)
    cholesky_solve(system, rhs, spd.factor, spd.qddot)
    for i in range(n):
        # Eq. 5: tau = -kp (q^n + q'^n dt - qbar^{n+1}) - kd (q'^n + q''^n dt)
        torque[i] -= kd[i] * (qdot[dof + i] + spd.qddot[i] * dt)


@subroutine
def spd_physics_step(spd: SPD, physics: Physics, q_ref: np.ndarray) -> None:
    """One physics step with SPD in the loop: mj_step1, Eq. 5-6 at that state into ctrl, mj_step2."""
    mj_step1(physics.model, physics.data)
    mj_fullM(physics.model, physics.data, spd.full_mass.ctypes.data)
    spd_torque(spd, physics, q_ref, physics.ctrl)
    mj_step2(physics.model, physics.data)

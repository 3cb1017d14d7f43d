"""The push of the pushing task as one compiled call: the admittance law along the push (Eq. 7 with
K_d = 0) driven by the planned force minus the wrist's reaction, inverse kinematics and SPD at every physics
step, then the brake and the wait for the cube to come to rest (`hipref.envs.pushing` plans it)."""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from hipref.control.admittance import AdmittanceLaw, admittance_step
from hipref.control.compiled import Physics, kernel, subroutine
from hipref.control.ik import IK, ik_step, tool_jacobian
from hipref.control.spd import SPD, spd_physics_step
from hipref.control.tool import FEATURES_PER_PERIOD, WristSensor, wrist_force, write_features


class PushPlan(NamedTuple):
    """One push as the compiled policy executes it."""

    direction: np.ndarray
    """u, the unit push direction on the desk (z = 0)."""
    tool_start: np.ndarray
    """The tool tip's position at the start, the paddle's edge touching the cube."""
    rotation: np.ndarray
    """The paddle's orientation while pushing."""
    compliance: np.ndarray
    """kp^-1 per joint: how far SPD lets each joint yield per N m."""
    lead: float
    """kd / kp in s: how far behind its reference a moving arm trails, per m/s."""
    force: float
    """The planned push force F in N."""
    push_steps: int
    """Physics steps of the push, T / h."""
    brake_deceleration: float
    settle_steps: int
    """Most physics steps the cube is given to come to rest."""
    rest_speed: float
    substeps: int
    """Physics steps per control period: features are recorded once per period."""
    cube_qpos: int
    cube_dof: int


_PUSH, _BRAKE, _SETTLE = 0, 1, 2
"""The phases of a push."""


@subroutine
def _push_target(
    jac: np.ndarray,
    plan: PushPlan,
    along: float,
    speed: float,
    force: np.ndarray,
    shift: np.ndarray,
    target_pos: np.ndarray,
    target_rot: np.ndarray,
) -> None:
    """The IK target (target_pos, target_rot) that makes SPD carry the tool at the reference x_d, `along` m
    from the tool's start and moving at `speed` m/s, given the tool's Jacobian `jac` (6 x 6) and the wrist
    force `force`; `shift` is scratch space.

    In steady state SPD holds kp (q_ref - q) = kd q' - J^T f: the arm trails its reference by kd/kp times
    its velocity and yields to the contact force f by kp^-1 J^T f. The target leads x_d by the first (a
    velocity feed-forward) and by the second except along the push: across and above the push the paddle
    must stay put (yielding, it rose and rode up the cube), while along it that compliance is a series
    spring that smooths the force loop and leaves the impulse unchanged."""
    u, rotation = plan.direction, plan.rotation
    # The pose change the measured force causes, J kp^-1 J_p^T f (its moment about the tip is neglected).
    for i in range(6):
        shift[i] = 0.0
    for k in range(jac.shape[1]):
        yielded = plan.compliance[k] * (jac[0, k] * force[0] + jac[1, k] * force[1] + jac[2, k] * force[2])
        for i in range(6):
            shift[i] += jac[i, k] * yielded
    along_push = u[0] * shift[0] + u[1] * shift[1] + u[2] * shift[2]
    for r in range(3):
        shift[r] -= u[r] * along_push
        target_pos[r] = plan.tool_start[r] + u[r] * along + plan.lead * u[r] * speed - shift[r]
    # The paddle turned back by the rotation w = -shift[3:] the force causes: (I + [w]x) rotation.
    w0, w1, w2 = -shift[3], -shift[4], -shift[5]
    for c in range(3):
        target_rot[0, c] = rotation[0, c] - w2 * rotation[1, c] + w1 * rotation[2, c]
        target_rot[1, c] = w2 * rotation[0, c] + rotation[1, c] - w0 * rotation[2, c]
        target_rot[2, c] = -w1 * rotation[0, c] + w0 * rotation[1, c] + rotation[2, c]


@subroutine
def _grown(rows: np.ndarray) -> np.ndarray:
    """`rows` copied into an array with twice as many rows."""
    grown = np.empty((2 * rows.shape[0], rows.shape[1]))
    for i in range(rows.shape[0]):
        for j in range(rows.shape[1]):
            grown[i, j] = rows[i, j]
    return grown


@subroutine
def _next_phase(phase: int, steps: int, speed: float, plan: PushPlan) -> int:
    """The phase of the coming physics step: the push lasts `push_steps`, the brake until the reference
    stops at the end of a control period, then the cube settles."""
    if phase == _PUSH and steps == plan.push_steps:
        phase = _BRAKE
    if phase == _BRAKE and speed <= 0.0 and steps % plan.substeps == 0:
        phase = _SETTLE
    return phase


@subroutine
def _move_reference(
    phase: int,
    law: AdmittanceLaw,
    plan: PushPlan,
    force: np.ndarray,
    h: float,
    offset: float,
    rate: float,
    along: float,
    speed: float,
) -> tuple[float, float, float, float]:
    """One physics step of the reference x_d (`along` the push, at `speed`) in `phase`; Eq. 7's state
    (`offset`, `rate`) moves only while pushing. Returns the new (offset, rate, along, speed)."""
    u = plan.direction
    if phase == _PUSH:
        # Push: Eq. 7 with K_d = 0, driven by the planned force minus the cube's reaction at the wrist.
        reaction = force[0] * u[0] + force[1] * u[1] + force[2] * u[2]
        offset, rate = admittance_step(law, offset, rate, plan.force + reaction)
        along, speed = offset, rate
    elif phase == _BRAKE:
        # Brake: the pusher stops far faster than friction stops the cube, which slides free.
        speed = max(0.0, speed - plan.brake_deceleration * h)
        along += speed * h
    else:
        # Settle: hold the reference and wait for the cube to come to rest.
        speed = 0.0
    return offset, rate, along, speed


@subroutine
def _cube_at_rest(physics: Physics, plan: PushPlan) -> bool:
    """Whether the cube's speed (linear and angular, as one vector) is below the rest speed."""
    cube_speed = 0.0
    for k in range(6):
        cube_speed += physics.qvel[plan.cube_dof + k] ** 2
    return math.sqrt(cube_speed) < plan.rest_speed


@subroutine
def _record_period(
    physics: Physics,
    spd: SPD,
    plan: PushPlan,
    period_force: np.ndarray,
    executed: np.ndarray,
    row: np.ndarray,
    cube_xy: np.ndarray,
) -> None:
    """At the end of a control period: its features to `row` (the wrist force summed in `period_force`
    averaged over the period, as ToolController reports it, and `period_force` cleared), the cube's place
    to `cube_xy`."""
    for r in range(3):
        period_force[r] /= plan.substeps
    write_features(physics, spd.dof, period_force, executed, row)
    for r in range(3):
        period_force[r] = 0.0
    cube_xy[0] = physics.qpos[plan.cube_qpos]
    cube_xy[1] = physics.qpos[plan.cube_qpos + 1]


@kernel
def execute_push(
    physics: Physics,
    spd: SPD,
    ik: IK,
    sensor: WristSensor,
    law: AdmittanceLaw,
    plan: PushPlan,
    perturbation: np.ndarray,
    q_ref: np.ndarray,
    force: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The whole push: the force-tracking admittance law, the brake, and the wait for the cube to come to
    rest. The force loop closes through a stiff contact, so the admittance law, the IK target and step and
    SPD act at every physics step. `q_ref` and `force` are the controller's joint reference and wrist force,
    updated at every step; SPD tracks q_ref plus the period's row of `perturbation` (its last row once the
    push outlasts it; zeros but in Algorithm 3's perturbed demonstrations), and the features record that.
    Returns the per-period features (periods, 21), cube positions (periods, 2) and tool tip positions
    (periods, 3)."""
    h, substeps = spd.dt, plan.substeps
    capacity = (plan.push_steps + plan.settle_steps) // substeps + 2
    features = np.empty((capacity, FEATURES_PER_PERIOD))
    cube_xy = np.empty((capacity, 2))
    tool_pos = np.empty((capacity, 3))
    shift, target_pos, target_rot, reading = np.empty(6), np.empty(3), np.empty((3, 3)), np.empty(3)
    executed = np.empty(q_ref.shape[0])
    period_force = np.zeros(3)
    offset, rate = 0.0, 0.0  # Eq. 7's state along the push
    along, speed = 0.0, 0.0  # the reference x_d and its speed
    phase, steps, periods, settle_left = _PUSH, 0, 0, plan.settle_steps
    while True:
        phase = _next_phase(phase, steps, speed, plan)
        if phase == _SETTLE:
            if settle_left == 0:
                break
            settle_left -= 1
        offset, rate, along, speed = _move_reference(phase, law, plan, force, h, offset, rate, along, speed)
        # One physics step: the IK target, one IK step (the same state, so the same Jacobian) and SPD.
        tool_jacobian(ik, physics)
        _push_target(ik.jac, plan, along, speed, force, shift, target_pos, target_rot)
        ik_step(ik, physics, target_pos, target_rot, q_ref)
        row = min(periods, perturbation.shape[0] - 1)
        for k in range(executed.shape[0]):
            executed[k] = q_ref[k] + perturbation[row, k]
        spd_physics_step(spd, physics, executed)
        for r in range(3):
            reading[r] = physics.sensordata[sensor.adr + r]
        wrist_force(physics, sensor, reading, force)
        for r in range(3):
            period_force[r] += force[r]
        steps += 1
        if steps % substeps:
            continue
        # The end of a control period: record its features.
        if periods == features.shape[0]:
            features, cube_xy, tool_pos = _grown(features), _grown(cube_xy), _grown(tool_pos)
        _record_period(physics, spd, plan, period_force, executed, features[periods], cube_xy[periods])
        for r in range(3):
            tool_pos[periods, r] = physics.site_xpos[ik.site, r]
        periods += 1
        if phase == _SETTLE and _cube_at_rest(physics, plan):
            break
    return features[:periods].copy(), cube_xy[:periods].copy(), tool_pos[:periods].copy()

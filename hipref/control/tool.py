"""The low-level control stack of paper Fig. 6: admittance (Eq. 7) -> inverse kinematics -> SPD (Eq. 5-6).

`ToolController.run` moves the tool towards a Cartesian target for one control period: the admittance
law (or, for the ablation, nothing) turns the target into the compliant reference x_d, one IK step turns
x_d into the joint reference, and SPD computes the joint torques at every physics step of the period.
`ToolController.track` does the same for a sequence of targets, one period each, and records what the
system-identification model sees. Both are one compiled call (`track`), MuJoCo's steps included.
`ToolController.hold` is the period of a learned pi^l (Algorithm 3), which gives the joint reference
itself: SPD tracks it, so physics and the torque law are those of the analytic stack."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar, NamedTuple

import numpy as np

from hipref.control.admittance import AdmittanceGains, AdmittanceLaw, admittance_step
from hipref.control.compiled import Physics, kernel, physics_of, subroutine
from hipref.control.ik import IK, ToolIK, ik_step, tool_jacobian
from hipref.control.spd import SPD, make_spd, spd_physics_step
from hipref.sim.scene import Scene
from hipref.validation import check_fields, check_vector

FEATURES_PER_PERIOD = 21
"""What the SI model sees of one control period: joint positions (6), joint velocities (6), wrist force (3)
and joint reference (6)."""
ARM_POSITIONS = slice(0, 6)
"""The columns of a period's features holding the arm's joint positions (rad)."""
WRIST_FORCE = slice(12, 15)
"""The columns of a period's features holding the wrist force (x, y, z in the world frame, N)."""
FORCE_Z = 14
"""The column holding the wrist force's normal (z) component."""


@dataclass(frozen=True)
class ControllerConfig:
    """Gains of the low-level controllers."""

    kp: tuple[float, ...] = (3000.0, 3000.0, 3000.0, 300.0, 300.0, 300.0)
    """SPD joint stiffness k_p in N m/rad, shoulder to wrist."""
    kd: tuple[float, ...] = (300.0, 300.0, 300.0, 30.0, 30.0, 30.0)
    """SPD joint damping k_d in N m s/rad."""
    admittance: AdmittanceGains = field(default_factory=AdmittanceGains)
    """Gains of Eq. 7 along the contact normal."""

    SEQUENCES: ClassVar[tuple[str, ...]] = ("kp", "kd")
    """Per-axis gains (x, y, z, then rotations), whose values may repeat (`check_fields`)."""

    def __post_init__(self) -> None:
        check_fields(self, self.SEQUENCES)
        check_vector("kp", self.kp, 6, positive=True)
        check_vector("kd", self.kd, 6, positive=True)


class WristSensor(NamedTuple):
    """The wrist force sensor as compiled code reads it (see `Scene.wrist_force_world`)."""

    site: int
    """The sensor's site, whose frame the reading is expressed in."""
    adr: int
    """Address of the force reading in sensordata."""
    tool_weight: np.ndarray
    """The tool's weight in the world frame (N), which the sensor is tared by."""


def make_wrist_sensor(scene: Scene) -> WristSensor:
    """The scene's wrist force sensor, tared by the tool's weight as `Scene.wrist_force_world` is."""
    m = scene.model
    weight = m.body_mass[m.body("tool").id] * m.opt.gravity
    return WristSensor(site=int(scene.ft_site), adr=int(scene.force_adr), tool_weight=np.array(weight))


@subroutine
def wrist_force(physics: Physics, sensor: WristSensor, reading: np.ndarray, force: np.ndarray) -> None:
    """The force the environment exerts on the tool, world frame, from a (possibly averaged) sensor
    reading: the reading is the tool's force on the flange in the sensor frame, its weight included."""
    rot = physics.site_xmat[sensor.site]  # row-major 3 x 3
    for r in range(3):
        local = rot[3 * r] * reading[0] + rot[3 * r + 1] * reading[1] + rot[3 * r + 2] * reading[2]
        force[r] = -local - sensor.tool_weight[r]


@subroutine
def write_features(physics: Physics, dof: int, force: np.ndarray, q_ref: np.ndarray, row: np.ndarray) -> None:
    """One period's features in `row`: the arm's joint positions and velocities (its n joints are dof, ...,
    dof + n - 1), the wrist force `force` and the joint reference `q_ref` (n + n + 3 + n values)."""
    n = q_ref.shape[0]
    for k in range(n):
        row[k] = physics.qpos[dof + k]
        row[n + k] = physics.qvel[dof + k]
        row[2 * n + 3 + k] = q_ref[k]
    for r in range(3):
        row[2 * n + r] = force[r]


@kernel
def track(
    physics: Physics,
    spd: SPD,
    ik: IK,
    sensor: WristSensor,
    law: AdmittanceLaw,
    compliant: bool,
    substeps: int,
    targets: np.ndarray,
    target_rot: np.ndarray,
    perturbation: np.ndarray,
    admittance: np.ndarray,
    q_ref: np.ndarray,
    force: np.ndarray,
    features: np.ndarray,
    tool_pos: np.ndarray,
) -> None:
    """One control period of Fig. 6 towards each Cartesian target in turn (tool-tip positions, one row per
    period, all with the tool orientation `target_rot`), each followed by `substeps` physics steps of SPD.

    `admittance` holds Eq. 7's state along z (x_d - x_0, x_d' - x_0'), `q_ref` the joint reference and
    `force` the wrist force of the last period, all updated. SPD tracks q_ref plus the period's row of
    `perturbation` (zeros but in Algorithm 3's perturbed demonstrations). After each period, its features
    (see `write_features`, the reference as tracked) go to the row of `features` and the tool tip's
    position to that of `tool_pos`."""
    reference, sensed, executed = np.empty(3), np.empty(3), np.empty(q_ref.shape[0])
    for period in range(targets.shape[0]):
        for r in range(3):
            reference[r] = targets[period, r]
        if compliant:
            # Eq. 7 along the contact normal, driven by the force measured over the last period.
            offset, rate = admittance_step(law, admittance[0], admittance[1], force[2])
            admittance[0] = offset
            admittance[1] = rate
            reference[2] += offset
        # One IK step from the kinematics of the last physics step.
        tool_jacobian(ik, physics)
        ik_step(ik, physics, reference, target_rot, q_ref)
        for k in range(executed.shape[0]):
            executed[k] = q_ref[k] + perturbation[period, k]
        spd_period(
            physics, spd, ik, sensor, substeps, executed, sensed, force, features[period], tool_pos[period]
        )


@subroutine
def spd_period(
    physics: Physics,
    spd: SPD,
    ik: IK,
    sensor: WristSensor,
    substeps: int,
    q_ref: np.ndarray,
    sensed: np.ndarray,
    force: np.ndarray,
    row: np.ndarray,
    tool_pos: np.ndarray,
) -> None:
    """`substeps` physics steps of SPD towards `q_ref`; then the wrist force averaged over them to `force`,
    the period's features to `row` and the tool tip's position to `tool_pos` (`sensed` is scratch)."""
    for r in range(3):
        sensed[r] = 0.0
    for _ in range(substeps):
        spd_physics_step(spd, physics, q_ref)
        for r in range(3):
            sensed[r] += physics.sensordata[sensor.adr + r]
    # The wrist force over the period, averaged as a sensor's anti-aliasing filter does.
    for r in range(3):
        sensed[r] /= substeps
    wrist_force(physics, sensor, sensed, force)
    write_features(physics, spd.dof, force, q_ref, row)
    for r in range(3):
        tool_pos[r] = physics.site_xpos[ik.site, r]


@kernel
def hold(
    physics: Physics,
    spd: SPD,
    ik: IK,
    sensor: WristSensor,
    substeps: int,
    q_ref: np.ndarray,
    force: np.ndarray,
    row: np.ndarray,
    tool_pos: np.ndarray,
) -> None:
    """One control period of SPD towards the joint reference `q_ref` as given (a learned pi^l's q-bar):
    `force`, the period's features `row` and the tool tip's position `tool_pos` are written as `track`
    writes them."""
    spd_period(physics, spd, ik, sensor, substeps, q_ref, np.empty(3), force, row, tool_pos)


class ToolController:
    """Admittance + IK + SPD around one scene; `compliant=False` gives plain SPD on the same reference."""

    def __init__(self, scene: Scene, config: ControllerConfig, *, compliant: bool = True) -> None:
        self.scene = scene
        self.config = config
        self.compliant = compliant
        self.ik = ToolIK(scene)
        self.spd = make_spd(scene, np.asarray(config.kp), np.asarray(config.kd))
        self.sensor = make_wrist_sensor(scene)
        self.physics = physics_of(scene.model, scene.data)
        self.law = config.admittance.law(scene.config.control_period)
        self.substeps = scene.config.control_substeps
        self.admittance = np.zeros(2)
        """Eq. 7's state along z: x_d - x_0 and x_d' - x_0'."""
        self.q_ref = np.zeros(6)
        """The joint reference SPD tracks, from the last period's IK step."""
        self.force = np.zeros(3)
        """Contact force on the tool in the world frame, averaged over the last control period."""
        # Buffers of single periods (`run`): arrays of one layout, so the kernel is compiled once.
        self._target = np.zeros((1, 3))
        self._rotation = np.zeros((3, 3))
        self._features = np.zeros((1, FEATURES_PER_PERIOD))
        self._tool_pos = np.zeros((1, 3))
        self._no_perturbation = np.zeros((1, 6))

    def reset(self) -> None:
        """Hold the current pose; call after the state was set and mj_forward run."""
        self.q_ref[:] = self.scene.data.qpos[self.scene.arm_qpos]
        self.admittance[:] = 0.0
        self.force[:] = self.scene.wrist_force_world()

    def track(
        self, targets: np.ndarray, target_rot: np.ndarray, perturbation: np.ndarray | None = None
    ) -> tuple[np.ndarray, np.ndarray]:
        """One control period towards each tool-tip position of `targets` (periods, 3) in turn, the tool
        oriented as `target_rot`, SPD tracking the reference plus the period's row of `perturbation`
        (periods, 6), if given. Returns, per period, the features (joint positions (6), joint velocities
        (6), wrist force (3), joint reference as tracked (6)) and the tool tip's position (3)."""
        targets = np.array(targets, dtype=float, order="C")
        if targets.ndim != 2 or targets.shape[1] != 3:
            raise ValueError(f"targets must be (periods, 3), got shape {targets.shape}")
        if perturbation is None:
            perturbation = np.zeros((len(targets), 6))
        elif perturbation.shape != (len(targets), 6):
            raise ValueError(f"perturbation must be ({len(targets)}, 6), got shape {perturbation.shape}")
        features = np.empty((len(targets), FEATURES_PER_PERIOD))
        tool_pos = np.empty((len(targets), 3))
        self._track(targets, target_rot, np.ascontiguousarray(perturbation, dtype=float), features, tool_pos)
        return features, tool_pos

    def run(self, target_pos: np.ndarray, target_rot: np.ndarray) -> None:
        """One control period towards the Cartesian target (tool-tip position, tool orientation)."""
        self._target[0] = target_pos
        self._track(self._target, target_rot, self._no_perturbation, self._features, self._tool_pos)

    def hold(self, q_bar: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """One control period of SPD towards the joint reference `q_bar` (6) as given, no admittance or IK
        (a learned pi^l's output). Returns the period's features (21) and the tool tip's position (3)."""
        self.q_ref[:] = q_bar
        features, tool_pos = np.empty(FEATURES_PER_PERIOD), np.empty(3)
        hold(
            self.physics,
            self.spd,
            self.ik.ik,
            self.sensor,
            int(self.substeps),
            self.q_ref,
            self.force,
            features,
            tool_pos,
        )
        self.scene.check_stable()
        return features, tool_pos

    def observation(self) -> np.ndarray:
        """The features of the current state (21), laid out as a period's (`write_features`)."""
        d, scene = self.scene.data, self.scene
        return np.concatenate([d.qpos[scene.arm_qpos], d.qvel[scene.arm_dof], self.force, self.q_ref])

    def tool_position(self) -> np.ndarray:
        """The tool tip's position now (3), as `track` and `hold` record it after a period."""
        return self.scene.data.site_xpos[self.ik.ik.site].copy()

    def _track(
        self,
        targets: np.ndarray,
        target_rot: np.ndarray,
        perturbation: np.ndarray,
        features: np.ndarray,
        tool_pos: np.ndarray,
    ) -> None:
        self._rotation[:] = target_rot
        track(
            self.physics,
            self.spd,
            self.ik.ik,
            self.sensor,
            self.law,
            self.compliant,
            int(self.substeps),
            targets,
            self._rotation,
            perturbation,
            self.admittance,
            self.q_ref,
            self.force,
            features,
            tool_pos,
        )
        self.scene.check_stable()

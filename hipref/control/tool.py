"""The low-level control stack of paper Fig. 6: admittance (Eq. 7) -> inverse kinematics -> SPD (Eq. 5-6).

`ToolController.run` moves the tool towards a Cartesian target for one control period: the admittance
law (or, for the ablation, nothing) turns the target into the compliant reference x_d, one IK step turns
x_d into the joint reference, and SPD computes the joint torques at every physics step of the period."""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from hipref.control.admittance import Admittance, AdmittanceGains
from hipref.control.ik import ToolIK
from hipref.control.spd import SPD
from hipref.sim.scene import Scene
from hipref.validation import check_vector


@dataclass(frozen=True)
class ControllerConfig:
    """Gains of the low-level controllers."""

    kp: tuple[float, ...] = (3000.0, 3000.0, 3000.0, 300.0, 300.0, 300.0)
    """SPD joint stiffness k_p in N m/rad, shoulder to wrist."""
    kd: tuple[float, ...] = (300.0, 300.0, 300.0, 30.0, 30.0, 30.0)
    """SPD joint damping k_d in N m s/rad."""
    admittance: AdmittanceGains = field(default_factory=AdmittanceGains)
    """Gains of Eq. 7 along the contact normal."""

    def __post_init__(self) -> None:
        check_vector("kp", self.kp, 6, positive=True)
        check_vector("kd", self.kd, 6, positive=True)


class ToolController:
    """Admittance + IK + SPD around one scene; `compliant=False` gives plain SPD on the same reference."""

    def __init__(self, scene: Scene, config: ControllerConfig, *, compliant: bool = True) -> None:
        self.scene = scene
        self.config = config
        self.compliant = compliant
        self.ik = ToolIK(scene)
        self.spd = SPD(scene, np.asarray(config.kp), np.asarray(config.kd))
        self.admittance = Admittance(config.admittance, scene.config.control_period)
        self.substeps = scene.config.control_substeps
        self.q_ref = np.zeros(6)
        self._reference = np.zeros(3)
        self._sensed = np.zeros(3)
        self.force = np.zeros(3)
        """Contact force on the tool in the world frame, averaged over the last control period."""

    def reset(self) -> None:
        """Hold the current pose; call after the state was set and mj_forward run."""
        self.q_ref = self.scene.data.qpos[self.scene.arm_qpos].copy()
        self.admittance.reset()
        self.force[:] = self.scene.wrist_force_world()

    def run(self, target_pos: np.ndarray, target_rot: np.ndarray, substeps: int | None = None) -> None:
        """One control period towards the Cartesian target (tool-tip position, tool orientation).

        `substeps` overrides the period's physics steps, for a loop that must run faster."""
        scene = self.scene
        m, d = scene.model, scene.data
        reference = self._reference
        reference[:] = target_pos
        if self.compliant:
            reference[2] = self.admittance.update(target_pos[2], self.force[2])
        self.q_ref = self.ik.step(d, reference, target_rot)
        substeps = substeps or self.substeps
        sensed = self._sensed
        sensed[:] = 0.0
        reading = d.sensordata[scene.force_adr : scene.force_adr + 3]
        for _ in range(substeps):
            mujoco.mj_step1(m, d)
            d.ctrl[:] = self.spd.torque(self.q_ref)
            mujoco.mj_step2(m, d)
            sensed += reading
        # The wrist force over the period, averaged as a sensor's anti-aliasing filter does.
        self.force[:] = scene.wrist_force_world(sensed / substeps)

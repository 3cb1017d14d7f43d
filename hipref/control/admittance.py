"""Admittance control, paper A.7 Eq. 7.

M_d (x_d'' - x_0'') + D_d (x_d' - x_0') + K_d (x_d - x_0) = F_ext

The measured external force moves the compliant reference x_d away from the desired trajectory x_0;
inverse kinematics turns x_d into the joint reference that SPD tracks (Fig. 6). The law acts along the
contact normal (world z): in x and y the tool follows x_0, so a goal on the desk is still reached."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from hipref.validation import check_range


@dataclass(frozen=True)
class AdmittanceGains:
    """Desired inertia, damping and stiffness of Eq. 7 along the contact normal."""

    inertia: float = 1.0
    """M_d in kg (Table 1)."""
    stiffness: float = 1000.0
    """K_d in N/m: the contact force settles at about K_d times the commanded depth below the surface."""
    damping_ratio: float = 5.0
    """D_d as a multiple of critical damping, D_d = 2 ratio sqrt(K_d M_d): overdamped, so the compliant
    reference settles on a stiff desk without bouncing."""

    def __post_init__(self) -> None:
        check_range("inertia", self.inertia, 1e-3, 100.0)
        check_range("stiffness", self.stiffness, 0.0, 1e5)
        check_range("damping_ratio", self.damping_ratio, 0.1, 100.0)

    @property
    def damping(self) -> float:
        return 2.0 * self.damping_ratio * float(np.sqrt(self.stiffness * self.inertia))


class Admittance:
    """Eq. 7 along z, integrated with implicit Euler at the control period (stable for any gains)."""

    def __init__(self, gains: AdmittanceGains, dt: float) -> None:
        self.gains = gains
        self.dt = dt
        self.offset = 0.0  # x_d - x_0
        self.offset_rate = 0.0  # x_d' - x_0'

    def reset(self) -> None:
        self.offset = 0.0
        self.offset_rate = 0.0

    def update(self, desired_z: float, external_force_z: float) -> float:
        """Advance Eq. 7 by one control period; returns the compliant reference height x_d."""
        g, dt = self.gains, self.dt
        # v' = (F - D v' - K (e + dt v')) / M solved for the new rate v', then e' = e + dt v'.
        self.offset_rate = (
            g.inertia * self.offset_rate + dt * (external_force_z - g.stiffness * self.offset)
        ) / (g.inertia + g.damping * dt + g.stiffness * dt * dt)
        self.offset += self.offset_rate * dt
        return desired_z + self.offset

"""Admittance control, paper A.7 Eq. 7.

M_d (x_d'' - x_0'') + D_d (x_d' - x_0') + K_d (x_d - x_0) = F_ext

The measured external force moves the compliant reference x_d away from the desired trajectory x_0;
inverse kinematics turns x_d into the joint reference that SPD tracks (Fig. 6). The tool controller
applies the law along the contact normal (world z): in x and y the tool follows x_0, so a goal on the desk
is still reached. The pushing policy applies it along the push direction with K_d = 0 (envs/pushing.py).
`admittance_step` integrates the law inside the compiled control loop."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, NamedTuple

import numpy as np

from hipref.control.compiled import subroutine
from hipref.validation import Range, check_fields


@dataclass(frozen=True)
class AdmittanceGains:
    """Desired inertia, damping and stiffness of Eq. 7 along the contact normal."""

    inertia: Annotated[float, Range(1e-3, 100.0)] = 1.0
    """M_d in kg (Table 1)."""
    stiffness: Annotated[float, Range(0.0, 1e5)] = 1000.0
    """K_d in N/m: the contact force settles at about K_d times the commanded depth below the surface."""
    damping_ratio: Annotated[float, Range(0.1, 100.0)] = 5.0
    """D_d as a multiple of critical damping, D_d = 2 ratio sqrt(K_d M_d): overdamped, so the compliant
    reference settles on a stiff desk without bouncing."""

    def __post_init__(self) -> None:
        check_fields(self)

    @property
    def damping(self) -> float:
        return 2.0 * self.damping_ratio * float(np.sqrt(self.stiffness * self.inertia))

    def law(self, dt: float) -> AdmittanceLaw:
        """Eq. 7 with these gains, integrated at steps of `dt` s."""
        return AdmittanceLaw(float(self.inertia), float(self.damping), float(self.stiffness), float(dt))


class AdmittanceLaw(NamedTuple):
    """Eq. 7's constants as compiled code takes them, with the step `dt` the law is integrated at."""

    inertia: float
    damping: float
    stiffness: float
    dt: float


@subroutine
def admittance_step(law: AdmittanceLaw, offset: float, rate: float, force: float) -> tuple[float, float]:
    """Advance Eq. 7 by one step of law.dt with implicit Euler (stable for any gains).

    `offset` is x_d - x_0 and `rate` is x_d' - x_0'; `force` is the external force along the law's axis.
    Returns the new (offset, rate): the compliant reference is x_d = x_0 + offset."""
    m, d, k, dt = law.inertia, law.damping, law.stiffness, law.dt
    # v' = (F - D v' - K (e + dt v')) / M solved for the new rate v', then e' = e + dt v'.
    rate = (m * rate + dt * (force - k * offset)) / (m + d * dt + k * dt * dt)
    return offset + rate * dt, rate

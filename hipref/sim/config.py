"""The simulator's numbers in one place: Table 1 of the paper, and the study's own choices beside them.

Table 1 lists its values without names. Each is a default below under the role we read it in (its
field says "Table 1"); the other fields are the study's own choices and say why.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

from hipref.validation import Range, check_fields, check_range, check_vector


@dataclass(frozen=True)
class SceneConfig:
    """The physical world shared by both tasks (paper A.1, Table 1)."""

    timestep: Annotated[float, Range(1e-4, 1e-2)] = 2e-3
    """Physics time step in s (Table 1)."""
    gravity: Annotated[float, Range(-20.0, 0.0)] = -9.81
    """Gravity along z in m/s^2 (Table 1)."""
    camera_pos: tuple[float, float, float] = (0.0, 1.7, 1.0)
    """Position of the render camera in m (Table 1), seen from the far side of the desk."""
    camera_euler: tuple[float, float, float] = (4.71238898, 0.0, 3.14159265)
    """Orientation of the render camera, xyz Euler angles in rad (Table 1)."""
    table_size: tuple[float, float, float] = (1.2, 0.6, 0.05)
    """Full extent of the desk top in m (Table 1, A.1: 120 x 60 x 5 cm)."""
    tool_size: tuple[float, float, float] = (0.1, 0.05, 0.07)
    """Full extent of the sponge (the pushing paddle in the pushing task) in m (Table 1)."""
    cube_size: tuple[float, float, float] = (0.05, 0.05, 0.05)
    """Full extent of the pushed cube in m (Table 1)."""
    table_friction: Annotated[float, Range(0.0, 5.0)] = 1.0
    """Sliding friction of the desk (Table 1); the tool and cube override it by contact priority."""
    cube_friction: Annotated[float, Range(0.0, 5.0)] = 0.5
    """Sliding friction between cube and desk (Table 1)."""
    tool_friction: Annotated[float, Range(0.0, 5.0)] = 0.5
    """Sliding friction between tool and anything it touches (Table 1)."""
    gravity_compensation: Annotated[float, Range(0.0, 1.0)] = 1.0
    """Fraction of the arm's and tool's weight cancelled by the simulator (Table 1; A.1: 'gravity
    compensation is turned on')."""
    torque_range: tuple[float, float] = (-1000.0, 1000.0)
    """Range of the joint torque motors that replace the Menagerie position servos, in N m (Table 1)."""
    joint_range: tuple[float, float] = (-3.14, 3.14)
    """Range of the elbow joint in rad (Table 1; the Menagerie limit)."""
    goal_tolerance: Annotated[float, Range(1e-3, 0.5)] = 0.03
    """Distance in m within which the cube counts as at its goal (Table 1)."""
    admittance_inertia: Annotated[float, Range(1e-3, 100.0)] = 1.0
    """Desired inertia M_d of the admittance law, Eq. 7, in kg (Table 1)."""
    tool_speed: Annotated[float, Range(1e-3, 2.0)] = 0.1
    """Speed in m/s at which the tool's reference moves near the desk (Table 1)."""
    reach_tolerance: Annotated[float, Range(1e-4, 0.1)] = 0.01
    """Distance in m within which the tool counts as at its goal on the desk (Table 1)."""
    control_period: float = 0.01
    """Period in s at which admittance and inverse kinematics update the joint reference that SPD tracks;
    SPD itself runs at every physics step."""
    base_pos: tuple[float, float, float] = (0.0, -0.42, 0.95)
    """Robot base position in m; the desk is centred at the origin of x and y. High enough that the
    shoulder clears the desk at 0.9 m and the wiping area stays reachable at 0.5 m."""
    tool_softness: float = 0.01
    """Contact time constant of the tool in s (MuJoCo solref), a slightly compliant sponge."""

    def __post_init__(self) -> None:
        check_fields(self)
        check_vector("table_size", self.table_size, 3, positive=True)
        check_vector("tool_size", self.tool_size, 3, positive=True)
        check_vector("cube_size", self.cube_size, 3, positive=True)
        check_range("control_period", self.control_period, self.timestep, 0.1)
        check_range("tool_softness", self.tool_softness, 2 * self.timestep, 0.1)

    @property
    def control_substeps(self) -> int:
        """Physics steps per control period."""
        return max(1, round(self.control_period / self.timestep))

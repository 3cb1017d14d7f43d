"""The pushing task's configuration (paper section 5, Table 2): the cube's mass range, where cubes and goals
lie, and how the push is planned and executed (`hipref.envs.pushing`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Annotated

from hipref.control.admittance import AdmittanceGains
from hipref.control.tool import ControllerConfig
from hipref.sim.config import SceneConfig
from hipref.validation import Integer, Range, check_fields, check_interval, check_range


@dataclass(frozen=True)
class PushingConfig:
    """The pushing task: mass range, where cubes and goals lie, and the push plan."""

    scene: SceneConfig = field(default_factory=SceneConfig)
    """The physical world (Table 1)."""
    controller: ControllerConfig = field(default_factory=ControllerConfig)
    """Gains of SPD (the push direction uses `push_admittance`)."""
    mass_range: tuple[float, float] = (8.0, 20.0)
    """Range of the cube mass in kg, the unknown parameter (Table 2)."""
    desk_height: Annotated[float, Range(0.5, 0.9)] = 0.7
    """Height of the desk in m (known in this task)."""
    area_x: tuple[float, float] = (-0.3, 0.3)
    """Extent along the desk in m where cubes start and goals lie."""
    area_y: tuple[float, float] = (0.0, 0.25)
    """Extent across the desk in m where cubes start and goals lie: away from the base (at y = -0.42),
    where the elbow is not folded near its limit, and the cube stays on the desk (its edge at 0.3)."""
    push_distance: tuple[float, float] = (0.1, 0.2)
    """Range of the distance in m from the cube's start to its goal: some 3 to 7 goal tolerances, so that
    a mass error of a few kg moves the cube out of tolerance."""
    planned_acceleration: Annotated[float, Range(0.1, 10.0)] = 2.0
    """Acceleration in m/s^2 the push plans for the cube. The push force is then m^ (a + mu g) plus
    M_d a; lower accelerations make the outcome more sensitive to the mass error (the friction term
    dominates the force) but the push longer."""
    push_admittance: AdmittanceGains = field(
        default_factory=lambda: AdmittanceGains(inertia=20.0, stiffness=0.0, damping_ratio=1.0)
    )
    """Eq. 7 along the push direction: inertia M_d only (K_d = 0, hence D_d = 0), a force-tracking law.
    M_d of the order of the cube's mass keeps the loop through the stiff contact slow, so the reaction
    does not chatter (M_d = 5 kg made the cube bounce on the paddle and rock)."""
    brake_deceleration: Annotated[float, Range(1.0, 100.0)] = 20.0
    """Deceleration in m/s^2 of the pusher after the push, well above friction's (mu g = 4.9 m/s^2), so
    the cube leaves the paddle at once and slides free."""
    contact_height: float = 0.005
    """Height in m of the paddle's lowest (rear) edge above the desk while pushing: clear of the desk,
    so the paddle drags nothing but the cube."""
    tilt: Annotated[float, Range(0.0, 0.5)] = 0.1
    """Pitch in rad of the paddle, lower edge forward: the paddle touches the cube along one edge about
    a centimetre above the desk, far below the height (about 3.5 cm at the planned forces) above which
    the push would tip the cube forward."""
    reach_residual: Annotated[float, Range(1e-6, 0.05)] = 1e-3
    """Largest IK position error in m accepted for a layout's tool poses: beyond it the arm cannot place
    the paddle behind the cube."""
    settle_time: Annotated[float, Range(0.1, 10.0)] = 1.5
    """Longest time in s the cube is given to come to rest after the push."""
    rest_speed: Annotated[float, Range(1e-5, 0.1)] = 1e-3
    """Speed in m/s below which the cube counts as at rest and the push ends."""
    layout_attempts: Annotated[int, Integer(1)] = 1000
    """Most random draws `PushingTask.sample_layout` makes before it gives up on the config; the default
    layout needs a handful."""

    def __post_init__(self) -> None:
        check_fields(self)
        scene = self.scene
        check_interval("mass_range", self.mass_range, 0.0, math.inf, low_open=True, unit="kg")
        # The cube, centred anywhere in the area, stays on the desk.
        half_x = scene.table_size[0] / 2 - scene.cube_size[0] / 2
        half_y = scene.table_size[1] / 2 - scene.cube_size[1] / 2
        check_interval("area_x", self.area_x, -half_x, half_x, unit="m", why=" (the cube stays on the desk)")
        check_interval("area_y", self.area_y, -half_y, half_y, unit="m", why=" (the cube stays on the desk)")
        # No start and goal of the area lie further apart than its diagonal.
        diagonal = math.hypot(self.area_x[1] - self.area_x[0], self.area_y[1] - self.area_y[0])
        check_interval(
            "push_distance",
            self.push_distance,
            0.0,
            diagonal,
            low_open=True,
            high_open=True,
            point=True,
            unit="m",
            why=" (high below the diagonal of area_x x area_y, as start and goal both lie in the area)",
        )
        check_range("contact_height", self.contact_height, 0.0, self.scene.cube_size[2])
        if self.push_admittance.stiffness != 0.0:
            raise ValueError("push_admittance must have stiffness 0: the push tracks a force, not a position")

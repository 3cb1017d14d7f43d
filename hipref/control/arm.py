"""What every task asks of the arm: inverse-kinematics seeds on one posture branch, and whether a solution
is usable (close to its target, inside the joint limits)."""

from __future__ import annotations

import math

import mujoco
import numpy as np

from hipref.sim.scene import Scene

START_POSTURE = np.array([0.0, -1.3, 1.8, -2.07, -1.57, 0.0])
"""Joint seed for inverse kinematics at reset: elbow up, tool down, facing the desk."""


class PostureSeed:
    """Inverse-kinematics seeds on START_POSTURE's branch for a tool pose above any point of the desk.

    The shoulder is turned towards the target and the last wrist joint back by the same angle plus the
    tool's yaw, so the damped least-squares iteration starts close to the elbow-up, tool-down solution: from
    START_POSTURE itself it converged, at the desk corner next to the base, onto wound-up joints far outside
    their limits."""

    def __init__(self, scene: Scene) -> None:
        scratch = mujoco.MjData(scene.model)
        scratch.qpos[scene.arm_qpos] = START_POSTURE
        mujoco.mj_kinematics(scene.model, scratch)
        tip = scratch.site_xpos[scene.tool_tip]
        self.base = np.asarray(scene.config.base_pos[:2], dtype=float)
        self.start_bearing = math.atan2(tip[1] - self.base[1], tip[0] - self.base[0])
        """Bearing from the base of the tool tip at START_POSTURE."""

    def pan(self, tool_xy: np.ndarray) -> float:
        """The shoulder turn in rad that points the arm at `tool_xy`."""
        return math.atan2(tool_xy[1] - self.base[1], tool_xy[0] - self.base[0]) - self.start_bearing

    def seed(self, tool_xy: np.ndarray, yaw: float = 0.0) -> np.ndarray:
        """The seed for a tool tip at `tool_xy` turned by `yaw` about the vertical."""
        pan = self.pan(tool_xy)
        seed = START_POSTURE.copy()
        seed[0] += pan
        seed[5] += pan - yaw
        return seed


def wrap_joints(q: np.ndarray) -> np.ndarray:
    """Joint positions wrapped to [-pi, pi): the same pose, as inverse kinematics may return it wound up."""
    return (q + math.pi) % (2 * math.pi) - math.pi


def reached(scene: Scene, q: np.ndarray, residual: float, tolerance: float) -> bool:
    """Whether inverse kinematics put the tool within `tolerance` m of its target (`residual`) with every
    joint of `q` inside its range."""
    low, high = scene.model.jnt_range[scene.arm_qpos].T
    return residual <= tolerance and bool(np.all(q >= low)) and bool(np.all(q <= high))

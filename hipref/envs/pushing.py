"""Pushing (paper section 5, Fig. 2b): the UR5e pushes a cube of unknown mass to a goal on the desk.

`PushingTask.push` is the goal-conditioned low-level policy pi^l: a force-controlled push planned with an
*estimate* m^ of the cube's mass m. Along the push direction the admittance law (Eq. 7 with K_d = 0) is
driven by the planned force F minus the reaction R measured at the wrist,

    M_d x_d'' = F - R,

and the tool tracks x_d. Over the push, of duration T, the impulse the tool gives the cube is therefore
F T - M_d x_d'(T); with the tool moving with the cube at the end (x_d' = v), the cube, dragged by
friction mu m g, leaves the push at

    v = (F - mu m g) T / (M_d + m),

then the pusher brakes away and the cube slides v^2 / (2 mu g) further. `plan` chooses F and T for the
goal distance from the estimate m^, so the cube stops at the goal only if m^ is close to m: a light
estimate under-pushes, a heavy one over-pushes: each kg of m^ - m adds (a + mu g) / (M_d + m) to the
cube's acceleration, about 10 % of the planned a = 2 m/s^2.

The force acts on the cube through real contact: the paddle, tilted so that only its lower edge touches
the cube low on its face (a cube pushed high tips and rocks), is held by SPD (Eq. 5-6) at the reference
given by inverse kinematics; the controller knows the robot model and the friction coefficient, never
the cube's mass.

Given a learned pi^l (`low_level`), a push is the policy's: each control period it turns the state, the
cube's goal and start and the mass estimate into the joint reference SPD tracks (`hipref.envs.low_level`),
until the cube comes to rest after the planned push."""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from hipref.control.ik import tool_down_rotation
from hipref.control.push import PushPlan, execute_push
from hipref.control.tool import ARM_POSITIONS, ToolController
from hipref.envs.low_level import (
    Demonstration,
    JointReferencePolicy,
    Perturb,
    check_policy,
    demonstration,
    execute_policy,
    initial_state,
    no_perturbation,
)
from hipref.envs.pushing_config import PushingConfig
from hipref.envs.pushing_layout import PaddlePoses
from hipref.envs.task import Layout, Rollout, evenly_spaced
from hipref.sim.render import clip_frames, watching_camera
from hipref.sim.scene import Scene, make_scene
from hipref.validation import check_choice, check_int, check_parameter


@dataclass
class Push:
    """What one push did."""

    features: np.ndarray
    """(periods, 21): joint positions (6), joint velocities (6), wrist force (3), joint reference (6)."""
    cube_xy: np.ndarray
    """(periods, 2): the cube's position on the desk."""
    resting_xy: np.ndarray
    """(2,): the cube's resting place on the desk."""
    final_error: float
    """Distance in m from the cube's resting place to its goal."""
    success: bool


class PushingTask:
    """The pushing world with its goal-conditioned low-level policy; physics built once per instance."""

    goal_size = 4
    """A learned pi^l's goal: the cube's goal (x, y) and its start (x, y) on the desk."""

    def __init__(
        self, config: PushingConfig | None = None, *, low_level: JointReferencePolicy | None = None
    ) -> None:
        self.config = config or PushingConfig()
        self.low_level = check_policy(low_level, self.goal_size, "pushing")
        """The learned pi^l rollouts execute; None: the analytic force-controlled push."""
        self.scene: Scene = make_scene(self.config.scene, with_cube=True)
        self.scene.set_desk_height(self.config.desk_height)
        # Plain SPD on the IK reference: the push direction's admittance is run by `push` itself.
        self.controller = ToolController(self.scene, self.config.controller, compliant=False)
        self.poses = PaddlePoses(self.config, self.scene, self.controller)
        """The paddle's pushing poses and the layouts they allow (`hipref.envs.pushing_layout`)."""
        self.start = np.zeros(2)
        self.goal = np.zeros(2)
        self.direction = np.zeros(2)
        self.rotation = tool_down_rotation(0.0)
        kp = np.asarray(self.config.controller.kp)
        kd = np.asarray(self.config.controller.kd)
        self._compliance = 1.0 / kp
        # SPD's damping acts on the joint velocity itself, so a moving arm trails its reference by kd/kp
        # times its velocity; every joint has the same ratio (0.1 s), which makes it a Cartesian lead.
        self._lead = float(np.mean(kd / kp))

    @property
    def mass(self) -> float:
        return float(self.scene.model.body_mass[self.scene.cube_body])

    # --- the Task interface (hipref.envs.task) ---------------------------------------------------------

    @property
    def control_period(self) -> float:
        """Seconds between two of pi^l's joint references."""
        return self.config.scene.control_period

    @property
    def parameter_range(self) -> tuple[float, float]:
        """The cube masses in kg the task accepts (and SI's candidates cover)."""
        return self.config.mass_range

    def planned_periods(self, layout: Layout) -> None:
        """None: a push lasts until the cube comes to rest, which only its execution tells."""
        return None

    def rollout(
        self, true_parameter: float, estimate: float, layout: Layout, periods: int | None = None
    ) -> Rollout:
        """One push of a cube of mass `true_parameter` from the layout's start towards its goal, planned with
        the mass `estimate`. A push is executed whole: `periods` must be None."""
        if periods is not None:
            raise ValueError(f"a push is executed whole (planned_periods is None), got periods={periods!r}")
        start, goal = layout
        self.reset(true_parameter, start, goal)
        push = self.push(estimate)
        return Rollout(push.features, bool(push.success))

    def episode_metrics(
        self, true_parameter: float, estimate: float, layout: Layout, route: str = "both"
    ) -> dict[str, float]:
        """A push's success and the cube's final distance to its goal (`goal_distance`), its part along
        the push, past the goal positive (`goal_overshoot`), and across it (`goal_sideways`). A push takes
        the estimate only as input: `route` must be 'both'."""
        check_choice("route", route, ("both",))
        start, goal = layout
        self.reset(true_parameter, start, goal)
        push = self.push(estimate)
        along = (goal - start) / np.linalg.norm(goal - start)
        miss = push.resting_xy - goal
        return {
            "success_rate": push.success,
            "goal_distance": push.final_error,
            "goal_overshoot": float(miss @ along),
            "goal_sideways": abs(float(miss[0] * along[1] - miss[1] * along[0])),
        }

    def demonstrate(
        self,
        true_parameter: float,
        layout: Layout,
        perturb: Perturb = no_perturbation,
        estimate: float | None = None,
    ) -> Demonstration:
        """The expert P (the force-controlled push planned with `estimate`, by default the true mass)
        executing the layout's push of a cube of `true_parameter`, as a learned pi^l is taught it (Algorithm
        3, line 6), SPD tracking P's reference plus `perturb`'s; labelled with the mass P was told."""
        start, goal = layout
        told = (
            true_parameter
            if estimate is None
            else check_parameter("estimate", estimate, self.parameter_range)
        )
        self.reset(true_parameter, start, goal)
        first = initial_state(self.controller)
        perturbation = perturb(self._longest_push(told))
        features, _, tool_pos = self._expert_push(told, perturbation)
        period = self.control_period
        points = np.broadcast_to(self._goal_points(), (len(features), 2, 2))
        return demonstration(first, features, tool_pos, points, told, period, perturbation)

    def _longest_push(self, mass_estimate: float) -> int:
        """Control periods a push planned with `mass_estimate` lasts at most, settling included (a learned
        pi^l's is cut there; the analytic one's only brake can outlast it, by a few periods)."""
        cfg = self.config
        period = self.control_period
        return math.ceil(self.plan(mass_estimate)[1] / period) + math.ceil(cfg.settle_time / period) + 2

    def clip_frames(
        self, true_parameter: float, estimate: float, layout: Layout, frames: int = 40
    ) -> list[np.ndarray] | None:
        """The push of `rollout` as `frames` images evenly spaced over it, the cube at its recorded place;
        None where no GL is. Seen from above the far side of the desk, aimed between the cube's start and
        its goal."""
        check_int("frames", frames, 1)
        start, goal = layout
        self.reset(true_parameter, start, goal)
        push = self.push(estimate)
        middle = (np.asarray(start) + np.asarray(goal)) / 2.0
        camera = watching_camera((middle[0], middle[1], self.scene.desk_height), 1.0, -90.0, -35.0)
        shown = evenly_spaced(len(push.features), frames)
        positions, cube_xy = push.features[shown, ARM_POSITIONS], push.cube_xy[shown]
        return clip_frames(self.scene, positions, cube_xy, camera=camera)

    # --- layout ---------------------------------------------------------------------------------------

    def sample_layout(self, rng: np.random.Generator) -> Layout:
        """A random cube start and goal whose pushing poses the arm reaches (`PaddlePoses.sample_layout`)."""
        return self.poses.sample_layout(rng)

    def reset(self, mass: float, start: np.ndarray, goal: np.ndarray) -> None:
        """Set the cube mass, put the cube at `start` with a face square to the goal, and the paddle's
        edge touching the opposite face, at rest."""
        mass = check_parameter("cube mass", mass, self.config.mass_range)
        cfg, scene = self.config, self.scene
        m, d = scene.model, scene.data
        scene.set_cube_mass(mass)
        self.start, self.goal = np.asarray(start, float), np.asarray(goal, float)
        offset = self.goal - self.start
        if offset.shape != (2,) or not np.all(np.isfinite(offset)) or np.linalg.norm(offset) < 1e-6:
            raise ValueError(f"start and goal must be two distinct points, got {start!r}, {goal!r}")
        u = self.direction = offset / np.linalg.norm(offset)
        q, self.rotation, _ = self.poses.arm_pose(self.start - u * self.poses.standoff(), u)
        mujoco.mj_resetData(m, d)
        d.qpos[scene.arm_qpos] = q
        cube = scene.cube_qpos
        d.qpos[cube : cube + 3] = [self.start[0], self.start[1], cfg.desk_height + cfg.scene.cube_size[2] / 2]
        # The cube turned so that the paddle meets a whole face square on, not a corner (which spins it).
        yaw = math.atan2(u[1], u[0])
        d.qpos[cube + 3 : cube + 7] = [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]
        mujoco.mj_forward(m, d)
        self.controller.reset()

    # --- policy ---------------------------------------------------------------------------------------

    def plan(self, mass_estimate: float) -> tuple[float, float]:
        """Push force F (N) and duration T (s) that move a cube of the estimated mass to the goal.

        Accelerating at a for T covers a T^2 / 2; sliding from v = a T on friction mu g covers
        v^2 / (2 mu g). Pushed by F against friction and the admittance's own inertia (module docstring),
        (M_d + m^) a = F - mu m^ g."""
        cfg = self.config
        a = cfg.planned_acceleration
        mu_g = cfg.scene.cube_friction * abs(cfg.scene.gravity)
        distance = float(np.linalg.norm(self.goal - self.start))
        duration = math.sqrt(distance / (a * (0.5 + a / (2 * mu_g))))
        force = (cfg.push_admittance.inertia + mass_estimate) * a + mass_estimate * mu_g
        return force, duration

    def _cube_xy(self) -> np.ndarray:
        return self.scene.data.qpos[self.scene.cube_qpos : self.scene.cube_qpos + 2].copy()

    def _goal_points(self) -> np.ndarray:
        """A learned pi^l's goal: the cube's goal and start (2, 2)."""
        return np.stack([self.goal, self.start])

    def push(self, mass_estimate: float) -> Push:
        """Push the cube towards the goal with a force planned from `mass_estimate`, then brake and wait
        for the cube to stop; features are recorded once per control period. The analytic push, with its
        control at every physics step, is one compiled call (`execute_push`); a learned pi^l acts once per
        control period until the cube rests after the planned push's duration."""
        mass_estimate = check_parameter("mass estimate", mass_estimate, self.config.mass_range)
        if np.array_equal(self.start, self.goal):  # reset() refuses equal points: it has not run yet
            raise RuntimeError("push() before reset(): reset(mass, start, goal) places the cube first")
        if self.low_level is None:
            features, cube_xy, _ = self._expert_push(mass_estimate, no_perturbation(1))
        else:
            features, cube_xy = self._learned_push(self.low_level, mass_estimate)
        self.scene.check_stable()
        resting_xy = self._cube_xy()
        final_error = float(np.linalg.norm(resting_xy - self.goal))
        success = final_error <= self.config.scene.goal_tolerance
        return Push(features, cube_xy, resting_xy, final_error, success)

    def _learned_push(
        self, policy: JointReferencePolicy, mass_estimate: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """The push executed by the learned `policy` given `mass_estimate`: at most as many periods as the
        analytic push may take, ended at the first period after the planned push's duration with the cube
        at rest. Returns the features and the cube's positions per period."""
        cfg, scene = self.config, self.scene
        period = self.control_period
        pushing = math.ceil(self.plan(mass_estimate)[1] / period)
        capacity = self._longest_push(mass_estimate)
        cube_xy = np.empty((capacity, 2))
        dof = scene.cube_dof

        def at_rest(p: int) -> bool:
            cube_xy[p] = self._cube_xy()
            return p >= pushing and float(np.linalg.norm(scene.data.qvel[dof : dof + 6])) < cfg.rest_speed

        points = np.broadcast_to(self._goal_points(), (capacity, 2, 2))
        features, _ = execute_policy(self.controller, policy, points, mass_estimate, period, done=at_rest)
        return features, cube_xy[: len(features)].copy()

    def _expert_push(
        self, mass_estimate: float, perturbation: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The analytic push planned with `mass_estimate`, SPD tracking its reference plus `perturbation`'s
        row of each control period: per period, the features, the cube's positions and the tool tip's
        positions."""
        cfg, scene = self.config, self.scene
        controller = self.controller
        force, duration = self.plan(mass_estimate)
        h = cfg.scene.timestep
        plan = PushPlan(
            direction=np.array([*self.direction, 0.0]),
            tool_start=np.array(
                [*(self.start - self.direction * self.poses.standoff()), self.poses.tool_height()]
            ),
            rotation=np.array(self.rotation, dtype=float, order="C"),
            compliance=self._compliance,
            lead=self._lead,
            force=float(force),
            push_steps=max(1, round(duration / h)),
            brake_deceleration=float(cfg.brake_deceleration),
            settle_steps=round(cfg.settle_time / h),
            rest_speed=float(cfg.rest_speed),
            substeps=cfg.scene.control_substeps,
            cube_qpos=int(scene.cube_qpos),
            cube_dof=int(scene.cube_dof),
        )
        return execute_push(
            controller.physics,
            controller.spd,
            controller.ik.ik,
            controller.sensor,
            cfg.push_admittance.law(h),
            plan,
            np.ascontiguousarray(perturbation, dtype=float),
            controller.q_ref,
            controller.force,
        )

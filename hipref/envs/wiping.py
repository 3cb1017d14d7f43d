"""Desk wiping (paper section 5, Fig. 2a): a UR5e with a sponge wipes a desk of unknown height.

`WipingTask` is the physical task with its goal-conditioned low-level policy pi^l: `stroke` drives the
sponge to a goal on the desk using an *estimate* of the desk height (never the simulator's value),
through admittance + IK + SPD. A stroke succeeds when the sponge reaches its goal with the contact force
inside the safe band for most of the way, which needs a good height estimate. Given a learned pi^l
(`low_level`), a rollout follows the same reference path, the policy turning each of its points, the goal
of one control period, into the joint reference (`hipref.envs.low_level`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Annotated

import mujoco
import numpy as np

from hipref.control.arm import PostureSeed, reached, wrap_joints
from hipref.control.ik import tool_down_rotation
from hipref.control.tool import ARM_POSITIONS, FORCE_Z, ControllerConfig, ToolController
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
from hipref.envs.task import ROUTES, Layout, Rollout, evenly_spaced
from hipref.sim.config import SceneConfig
from hipref.sim.render import clip_frames, watching_camera
from hipref.sim.scene import Scene, make_scene
from hipref.validation import (
    Range,
    check_choice,
    check_fields,
    check_int,
    check_interval,
    check_parameter,
    check_range,
)

HOVER_CLEARANCE = 0.03
"""Least height in m of the tool tip at reset above the highest desk of the range."""
HOVER_CEILING = 1.2
"""Greatest height in m of the tool tip at reset (the arm's base stands at 0.95 m)."""


@dataclass(frozen=True)
class WipingConfig:
    """The wiping task: desk-height range, wiping area, safe force band and the policy's motion."""

    scene: SceneConfig = field(default_factory=SceneConfig)
    """The physical world (Table 1)."""
    controller: ControllerConfig = field(default_factory=ControllerConfig)
    """Gains of SPD and admittance."""
    height_range: tuple[float, float] = (0.5, 0.9)
    """Range of the desk height in m, the unknown parameter (Table 2)."""
    area_x: tuple[float, float] = (-0.3, 0.3)
    """Extent of the wiping area along the desk in m (12 cells of 0.05 m); reachable at every height."""
    area_y: tuple[float, float] = (-0.1, 0.2)
    """Extent of the wiping area across the desk in m (6 cells of 0.05 m), from the robot's side."""
    force_band: tuple[float, float] = (1.0, 60.0)
    """Safe band of the contact force in N: below it the sponge does not clean, above it risks damage
    (robosuite's Wipe uses 0.5 N and 60 N)."""
    press_depth: Annotated[float, Range(0.0, 0.05)] = 0.03
    """Depth in m below the estimated surface the sponge is aimed at; the admittance stiffness turns it
    into a contact force of about K_d times the depth."""
    in_band_fraction: Annotated[float, Range(0.0, 1.0)] = 0.8
    """Fraction of a stroke's control periods whose contact force must lie in the safe band."""
    reach_residual: Annotated[float, Range(1e-6, 0.05)] = 1e-3
    """Largest inverse-kinematics position error in m accepted when the arm is placed above the desk."""
    hover_height: float = 0.95
    """Height in m of the tool tip at reset: above the highest desk."""
    approach_speed: Annotated[float, Range(0.01, 2.0)] = 0.5
    """Speed in m/s of the descent towards the estimated surface until `approach_clearance` above it."""
    approach_clearance: Annotated[float, Range(0.0, 0.2)] = 0.03
    """Height in m above the estimated surface where the descent slows to the tool speed."""

    def __post_init__(self) -> None:
        check_fields(self)
        table = self.scene.table_size
        # The desk stands on the floor with its top below the tool's hovering height. When that coupling
        # fails, the error names the field the caller changed: the range, unless only the hover height was.
        defaults = {f.name: f.default for f in fields(self)}
        range_changed = tuple(self.height_range) != defaults["height_range"]
        if self.hover_height != defaults["hover_height"] and not range_changed:
            lowest = self.height_range[1] + HOVER_CLEARANCE
            check_range("hover_height", self.hover_height, lowest, HOVER_CEILING)
        else:
            check_range("hover_height", self.hover_height, table[2] + HOVER_CLEARANCE, HOVER_CEILING)
            check_interval(
                "height_range",
                self.height_range,
                table[2],
                self.hover_height - HOVER_CLEARANCE,
                unit="m",
                why=f" (at reset the tool hovers {HOVER_CLEARANCE} m above the highest desk, at hover_height="
                f"{self.hover_height} m)",
            )
        check_interval("area_x", self.area_x, -table[0] / 2, table[0] / 2, unit="m", why=" (on the desk)")
        check_interval("area_y", self.area_y, -table[1] / 2, table[1] / 2, unit="m", why=" (on the desk)")
        check_interval("force_band", self.force_band, 0.0, math.inf, unit="N")


@dataclass
class Stroke:
    """What one stroke did: per control period, the features the SI model sees and the contact force."""

    features: np.ndarray
    """(periods, 21): joint positions (6), joint velocities (6), wrist force (3), joint reference (6)."""
    force: np.ndarray
    """(periods,): normal contact force in N measured at the wrist."""
    tool_xy: np.ndarray
    """(periods, 2): tool tip position on the desk plane."""
    reached: bool
    """Whether the sponge ended within the reach tolerance of its goal."""
    in_band: float
    """Fraction of the stroke's periods whose contact force was inside the safe band."""
    success: bool


def _check_goal(goal_xy: np.ndarray) -> np.ndarray:
    goal = np.asarray(goal_xy, dtype=float)
    if goal.shape != (2,) or not np.all(np.isfinite(goal)):
        raise ValueError(f"goal must be two finite coordinates, got {goal_xy!r}")
    return goal


class WipingTask:
    """The wiping world with its goal-conditioned low-level policy; physics built once per instance."""

    goal_size = 3
    """A learned pi^l's goal: the next point of the stroke's reference path (approach included)."""

    def __init__(
        self,
        config: WipingConfig | None = None,
        *,
        compliant: bool = True,
        low_level: JointReferencePolicy | None = None,
    ) -> None:
        self.config = config or WipingConfig()
        self.low_level = check_policy(low_level, self.goal_size, "wiping")
        """The learned pi^l rollouts execute; None: the analytic admittance + IK + SPD."""
        self.scene: Scene = make_scene(self.config.scene, with_cube=False)
        self.controller = ToolController(self.scene, self.config.controller, compliant=compliant)
        self.rotation = tool_down_rotation(0.0)
        self._scratch = mujoco.MjData(self.scene.model)
        self._seed = PostureSeed(self.scene)
        self.reference = np.zeros(3)
        self.in_contact_phase = False

    @property
    def height(self) -> float:
        return self.scene.desk_height

    # --- the Task interface (hipref.envs.task) ---------------------------------------------------------

    @property
    def control_period(self) -> float:
        """Seconds between two of pi^l's joint references."""
        return self.config.scene.control_period

    @property
    def parameter_range(self) -> tuple[float, float]:
        """The desk heights in m the task accepts (and SI's candidates cover)."""
        return self.config.height_range

    def area_points(self, rng: np.random.Generator, count: int) -> np.ndarray:
        """`count` points drawn uniformly from the wiping area, (count, 2)."""
        cfg = self.config
        return rng.uniform([cfg.area_x[0], cfg.area_y[0]], [cfg.area_x[1], cfg.area_y[1]], (count, 2))

    def sample_layout(self, rng: np.random.Generator) -> Layout:
        """A stroke's start and goal, both uniform over the wiping area."""
        start, goal = self.area_points(rng, 2)
        return start, goal

    def planned_periods(self, layout: Layout) -> int:
        """A stroke's length is set by its layout: the distance at the tool speed, then 0.1 s settling."""
        start, goal = layout
        return self._stroke_periods(np.array([float(start[0]), float(start[1])]), _check_goal(goal))

    def rollout(
        self, true_parameter: float, estimate: float, layout: Layout, periods: int | None = None
    ) -> Rollout:
        """One stroke from the layout's start to its goal with the height `estimate` over a desk at
        `true_parameter`; its first `periods` control periods only, if given."""
        start, goal = layout
        self.reset(true_parameter, (float(start[0]), float(start[1])))
        stroke = self.execute(goal, estimate, periods=periods)
        return Rollout(stroke.features, bool(stroke.success))

    def episode_metrics(
        self, true_parameter: float, estimate: float, layout: Layout, route: str = "both"
    ) -> dict[str, float]:
        """A stroke's success and its contact force (`force_mean`, `force_std`); the path and the input
        of a learned stroke given the estimate or the truth by `route` (`ROUTES`)."""
        check_choice("route", route, ROUTES)
        start, goal = layout
        self.reset(true_parameter, (float(start[0]), float(start[1])))
        path = true_parameter if route == "input" else estimate
        stroke = self.execute(goal, path, phi=true_parameter if route == "path" else estimate)
        force = stroke.force
        return {"success_rate": stroke.success, "force_mean": force.mean(), "force_std": force.std()}

    def demonstrate(
        self,
        true_parameter: float,
        layout: Layout,
        perturb: Perturb = no_perturbation,
        estimate: float | None = None,
    ) -> Demonstration:
        """The expert P (admittance + IK + SPD, told `estimate`, by default the true height) executing the
        layout's stroke over a desk at `true_parameter`, approach included, as a learned pi^l is taught it
        (Algorithm 3, line 6), SPD tracking P's reference plus `perturb`'s; labelled with the height P was
        told, which reaches P only through its path (3 cm below the surface it was told)."""
        start, goal = layout
        told = (
            true_parameter
            if estimate is None
            else check_parameter("estimate", estimate, self.parameter_range)
        )
        self.reset(true_parameter, (float(start[0]), float(start[1])))
        first = initial_state(self.controller)
        targets = self._path(_check_goal(goal), told, None)
        perturbation = perturb(len(targets))
        features, tool_pos = self.controller.track(targets, self.rotation, perturbation)
        period = self.control_period
        points = targets[:, None, :]
        return demonstration(first, features, tool_pos, points, told, period, perturbation)

    def clip_frames(
        self, true_parameter: float, estimate: float, layout: Layout, frames: int = 40
    ) -> list[np.ndarray] | None:
        """The stroke of `rollout` as `frames` images evenly spaced over it; None where no GL is.

        Seen from the far side of the desk, level with its surface and close to the stroke, where a
        sponge hovering above the desk or pressing into it shows."""
        check_int("frames", frames, 1)
        features = self.rollout(true_parameter, estimate, layout).features
        middle = (np.asarray(layout[0]) + np.asarray(layout[1])) / 2.0
        camera = watching_camera((middle[0], middle[1], true_parameter), 0.8, -90.0, -5.0)
        shown = evenly_spaced(len(features), frames)
        return clip_frames(self.scene, features[shown, ARM_POSITIONS], camera=camera)

    def observation(self) -> np.ndarray:
        """The features of the current state, laid out as each period's in `Stroke.features`."""
        return self.controller.observation()

    # --- the stroke --------------------------------------------------------------------------------------

    def reset(self, height: float, tool_xy: tuple[float, float] = (0.0, 0.05)) -> None:
        """Set the desk height and place the tool hovering above `tool_xy`, at rest."""
        height = check_parameter("desk height", height, self.config.height_range)
        scene = self.scene
        m, d = scene.model, scene.data
        scene.set_desk_height(height)
        target = np.array([tool_xy[0], tool_xy[1], self.config.hover_height])
        self._scratch.qpos[scene.arm_qpos] = self._seed.seed(target[:2])
        q, residual = self.controller.ik.solve(self._scratch, target, self.rotation)
        q = wrap_joints(q)
        if not reached(scene, q, residual, self.config.reach_residual):
            raise ValueError(
                f"the arm cannot place the tool above {tuple(tool_xy)}: inverse kinematics ends "
                f"{residual:.4f} m off (tolerance {self.config.reach_residual} m) at joints "
                f"{np.round(q, 3).tolist()}"
            )
        mujoco.mj_resetData(m, d)
        d.qpos[scene.arm_qpos] = q
        mujoco.mj_forward(m, d)
        self.controller.reset()
        self.reference[:] = target
        self.in_contact_phase = False

    def contact_force(self) -> float:
        """Normal force of the desk on the sponge, from the wrist sensor (N, upward positive)."""
        return float(self.controller.force[2])

    def approach(self, estimate: float) -> None:
        """Descend from hover to the estimated surface minus the press depth (fast, then at tool speed)."""
        targets = self._approach_targets(estimate)
        self.controller.track(targets, self.rotation)
        self.reference[2] = targets[-1, 2]
        self.in_contact_phase = True

    def _approach_targets(self, estimate: float) -> np.ndarray:
        """The approach's reference, one tool-tip position per control period, from the reference now."""
        cfg, scene_cfg = self.config, self.config.scene
        estimate = check_parameter("height estimate", estimate, self.config.height_range)
        dt = scene_cfg.control_period
        slow_from = estimate + cfg.approach_clearance
        bottom = estimate - cfg.press_depth
        height = float(self.reference[2])
        heights: list[float] = []
        while height > bottom + 1e-9:
            speed = cfg.approach_speed if height > slow_from else scene_cfg.tool_speed
            height = max(bottom, height - speed * dt)
            heights.append(height)
        # Let the admittance settle on the surface before moving.
        heights += [height] * round(0.2 / dt)
        targets = np.empty((len(heights), 3))
        targets[:, :2] = self.reference[:2]
        targets[:, 2] = heights
        return targets

    def _moving_periods(self, origin: np.ndarray, goal: np.ndarray) -> int:
        """Control periods the reference takes from `origin` to `goal` at the tool speed."""
        scene_cfg = self.config.scene
        distance = float(np.linalg.norm(goal - origin))
        return max(1, math.ceil(distance / (scene_cfg.tool_speed * scene_cfg.control_period)))

    def _stroke_periods(self, origin: np.ndarray, goal: np.ndarray) -> int:
        return self._moving_periods(origin, goal) + round(0.1 / self.config.scene.control_period)

    def stroke_periods(self, goal_xy: np.ndarray) -> int:
        """Control periods a stroke from the sponge's place to `goal_xy` lasts, whatever the estimate:
        moving at the tool speed, then settling for 0.1 s."""
        return self._stroke_periods(self.reference[:2], _check_goal(goal_xy))

    def stroke(self, goal_xy: np.ndarray, estimate: float, *, periods: int | None = None) -> Stroke:
        """Move the sponge on the desk to `goal_xy` at tool speed, pressing at the estimated surface.

        `periods` executes only the stroke's first `periods` control periods, bit for bit the same as the
        whole stroke's (what a trajectory slice needs); `reached` and `success` then describe that part."""
        if not self.in_contact_phase:
            self.approach(estimate)
        goal = _check_goal(goal_xy)
        targets = self._stroke_targets(goal, estimate, periods)
        features, tool_pos = self.controller.track(targets, self.rotation)
        self.reference[:] = targets[-1]
        return self._outcome(features, tool_pos[:, :2], goal)

    def _stroke_targets(self, goal: np.ndarray, estimate: float, periods: int | None) -> np.ndarray:
        """The stroke's reference from the reference now to `goal`, pressing at the estimated surface, one
        tool-tip position per control period (its first `periods` only, if given)."""
        estimate = check_parameter("height estimate", estimate, self.config.height_range)
        total = self.stroke_periods(goal)
        if periods is not None and not 1 <= periods <= total:
            raise ValueError(f"periods must be in [1, {total}] for this stroke, got {periods!r}")
        moving = self._moving_periods(self.reference[:2], goal)
        start = self.reference[:2].copy()
        # The reference moves at tool speed to the goal, then stays there while the sponge settles.
        fraction = np.minimum(1.0, np.arange(1, (periods or total) + 1) / moving)
        targets = np.empty((len(fraction), 3))
        targets[:, :2] = start + (goal - start) * fraction[:, None]
        targets[:, 2] = estimate - self.config.press_depth
        return targets

    def _path(self, goal: np.ndarray, estimate: float, periods: int | None) -> np.ndarray:
        """From hover: the approach's reference, then the stroke's (its first `periods` only, if given)."""
        approach = self._approach_targets(estimate)
        return np.concatenate([approach, self._stroke_targets(goal, estimate, periods)])

    def execute(
        self, goal_xy: np.ndarray, estimate: float, *, periods: int | None = None, phi: float | None = None
    ) -> Stroke:
        """From hover (after `reset`): the approach and the stroke to `goal_xy`, executed by the task's pi^l
        given `estimate` (the analytic `stroke`, or the learned `low_level`'s). The estimate reaches a
        learned pi^l twice, through the path it follows and as its parameter input; `phi` (None: the
        estimate) sets the input alone, the path staying the estimate's. The analytic stack has no input
        but its path, so `phi` does not change its stroke."""
        if self.low_level is None:
            return self.stroke(goal_xy, estimate, periods=periods)
        phi = estimate if phi is None else check_parameter("phi", phi, self.parameter_range)
        return self._learned_stroke(self.low_level, goal_xy, estimate, periods, phi)

    def _learned_stroke(
        self,
        policy: JointReferencePolicy,
        goal_xy: np.ndarray,
        estimate: float,
        periods: int | None,
        phi: float,
    ) -> Stroke:
        """The stroke from hover, approach included, executed by the learned `policy` given `phi` along the
        path of `estimate`, each control period's goal the path's next point; only the stroke's periods are
        kept."""
        goal = _check_goal(goal_xy)
        approach = len(self._approach_targets(estimate))
        targets = self._path(goal, estimate, periods)
        period = self.control_period
        features, tool_pos = execute_policy(self.controller, policy, targets[:, None, :], phi, period)
        self.reference[:] = targets[-1]
        self.in_contact_phase = True
        return self._outcome(features[approach:], tool_pos[approach:, :2], goal)

    def _outcome(self, features: np.ndarray, tool_xy: np.ndarray, goal: np.ndarray) -> Stroke:
        """A stroke's success: the sponge ends within the reach tolerance of `goal`, the contact force in the
        safe band for the required fraction of its periods."""
        cfg = self.config
        force = features[:, FORCE_Z].copy()
        low, high = cfg.force_band
        in_band = float(np.mean((force >= low) & (force <= high)))
        reached = bool(np.linalg.norm(tool_xy[-1] - goal) <= cfg.scene.reach_tolerance)
        return Stroke(features, force, tool_xy, reached, in_band, reached and in_band >= cfg.in_band_fraction)

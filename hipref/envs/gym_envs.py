"""Gymnasium faces of the two tasks, registered as `hipref/DeskWiping-v0` and `hipref/Pushing-v0`.

Both are goal-level environments: one `step` runs the low-level policy pi^l (admittance + IK + SPD) for a
whole stroke or push, at the simulator's 2 ms time step, given the agent's estimate of the unknown
parameter. `reset(seed=..., options={"param": value})` sets the unknown parameter (desk height in m, cube
mass in kg); it is drawn uniformly from its range when absent. Stepping before the first `reset`, or after
the episode terminated or was truncated, raises `gymnasium.error.ResetNeeded`.

Actions are normalised, as gymnasium's checker asks: each entry in [-1, 1] stands for its physical range
linearly (-1 its low end, 1 its high end); `env.action_for(...)` turns physical values into an action and
`info` reports the physical values a step used. Observations are any finite float32 values."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from hipref.control.tool import FEATURES_PER_PERIOD, WRIST_FORCE
from hipref.envs.pushing import PushingTask
from hipref.envs.pushing_config import PushingConfig
from hipref.envs.wiping import WipingConfig, WipingTask
from hipref.validation import check_int, check_parameter

RESET_OPTIONS = frozenset({"param"})


def _parameter(env: gym.Env, options: dict[str, Any] | None, bounds: tuple[float, float], name: str) -> float:
    if options is not None and not isinstance(options, dict):
        raise ValueError(f"options must be a dict such as {{'param': value}} or None, got {options!r}")
    options = dict(options or {})
    unknown = set(options) - RESET_OPTIONS
    if unknown:
        raise ValueError(f"unknown reset option(s) {sorted(unknown)}; allowed: {sorted(RESET_OPTIONS)}")
    if options.get("param") is None:
        return float(env.np_random.uniform(*bounds))
    return check_parameter(name, options["param"], bounds)


def _check_config(config: object, kind: type) -> None:
    if config is not None and not isinstance(config, kind):
        raise ValueError(f"config must be a {kind.__name__} or None, got {type(config).__name__}: {config!r}")


def _check_running(env: gym.Env, episode_over: bool | None) -> None:
    """Refuse a step outside an episode: the task's state would be the last episode's, or none at all."""
    if episode_over is None:
        raise gym.error.ResetNeeded(
            f"{type(env).__name__}.step was called before reset (or after a reset that failed): call reset()"
        )
    if episode_over:
        raise gym.error.ResetNeeded(
            f"{type(env).__name__}.step was called after the episode ended (terminated, truncated or "
            "voided by an error): call reset() to start a new episode"
        )


FINITE_FLOAT32 = float(np.finfo(np.float32).max)
"""The observation spaces' bound: an observation is finite, nothing more is promised of a force or speed."""


def _observation_space(size: int) -> gym.spaces.Box:
    return gym.spaces.Box(-FINITE_FLOAT32, FINITE_FLOAT32, shape=(size,), dtype=np.float32)


class _NormalisedActions:
    """An action space [-1, 1]^n standing for the physical box [low, high] entry by entry."""

    def __init__(self, low: np.ndarray, high: np.ndarray, meaning: str) -> None:
        self.low, self.high, self.meaning = low, high, meaning
        self.space = gym.spaces.Box(-1.0, 1.0, shape=low.shape, dtype=np.float64)

    def physical(self, action: Any) -> np.ndarray:
        """The physical values of `action`; ValueError naming it unless it holds n finite numbers in [-1, 1]
        (a string, bool or None is no number, and is not converted)."""
        n = self.low.size
        try:
            values = np.asarray(action)
            ok = values.dtype.kind in "iuf" and values.size == n
        except (TypeError, ValueError):  # ragged nesting
            ok = False
        if not ok:
            raise ValueError(
                f"action must be {n} finite number(s) in [-1, 1] ({self.meaning}), got {action!r}"
            )
        values = values.astype(np.float64).reshape(self.low.shape)
        if not np.all(np.isfinite(values)):
            raise ValueError(f"action must be finite, got {action!r}")
        if np.any(np.abs(values) > 1.0):
            raise ValueError(f"action must lie in [-1, 1] ({self.meaning}), got {action!r}")
        return self.low + (values + 1.0) / 2.0 * (self.high - self.low)

    def action(self, *physical: float) -> np.ndarray:
        """The action standing for `physical` (one value per entry, in the entries' units)."""
        values = np.array(physical, dtype=np.float64)
        return 2.0 * (values - self.low) / (self.high - self.low) - 1.0


class DeskWipingEnv(gym.Env):
    """Wipe a desk of unknown height.

    Observation (float32, 21 = FEATURES_PER_PERIOD): joint positions (6, rad), joint velocities (6, rad/s),
    wrist force on the sponge (3, N, world frame), the joint reference SPD tracks (6, rad), at the end of
    the last step.
    Action (3, normalised to [-1, 1]): goal x, goal y on the desk (m, over the wiping area) and the
    desk-height estimate (m, over the height range); `action_for(x, y, estimate)` makes one.
    Reward: 1 for a successful stroke (goal reached with the contact force in the safe band for most of
    the way), else 0. An episode is truncated after `max_strokes` strokes.
    Info: `contact_force` (mean normal force of the stroke, N), `force_max` (N), `in_band` (fraction of
    the stroke in the safe band), `reached`, `success`, `param` (the true desk height, m), `goal` (m) and
    `estimate` (m), the action's physical values."""

    metadata = {"render_modes": []}  # noqa: RUF012 - gymnasium's convention
    action_space: gym.spaces.Box

    def __init__(self, config: WipingConfig | None = None, max_strokes: int = 20) -> None:
        _check_config(config, WipingConfig)
        check_int("max_strokes", max_strokes, 1)
        self.task = WipingTask(config)
        cfg = self.task.config
        self.max_strokes = max_strokes
        self.observation_space = _observation_space(FEATURES_PER_PERIOD)
        low = np.array([cfg.area_x[0], cfg.area_y[0], cfg.height_range[0]])
        high = np.array([cfg.area_x[1], cfg.area_y[1], cfg.height_range[1]])
        self._actions = _NormalisedActions(low, high, "goal x, goal y, desk-height estimate")
        self.action_space = self._actions.space
        self._strokes = 0
        self._observation = np.zeros(FEATURES_PER_PERIOD, dtype=np.float32)
        self._episode_over: bool | None = None
        """None outside an episode (before the first successful reset); else whether it has ended."""

    def action_for(self, goal_x: float, goal_y: float, estimate: float) -> np.ndarray:
        """The normalised action of a stroke to (goal_x, goal_y) (m) under the desk-height `estimate` (m)."""
        return self._actions.action(goal_x, goal_y, estimate)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self._episode_over = None
        cfg = self.task.config
        height = _parameter(self, options, cfg.height_range, "desk height")
        self.task.reset(height, (float(np.mean(cfg.area_x)), float(np.mean(cfg.area_y))))
        self._strokes = 0
        self._observation = self.task.observation().astype(np.float32)
        self._episode_over = False
        return self._observation.copy(), {"param": height}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        _check_running(self, self._episode_over)
        goal_x, goal_y, estimate = self._actions.physical(action)
        self._episode_over = True  # until the stroke completes: a failed one leaves no episode to go on with
        stroke = self.task.stroke(np.array([goal_x, goal_y]), float(estimate))
        self._strokes += 1
        self._observation = stroke.features[-1].astype(np.float32)
        info = {
            "contact_force": float(stroke.force.mean()),
            "force_max": float(stroke.force.max()),
            "in_band": stroke.in_band,
            "reached": stroke.reached,
            "success": stroke.success,
            "param": self.task.height,
            "goal": (float(goal_x), float(goal_y)),
            "estimate": float(estimate),
        }
        truncated = self._strokes >= self.max_strokes
        self._episode_over = truncated
        return self._observation.copy(), float(stroke.success), False, truncated, info


class PushingEnv(gym.Env):
    """Push a cube of unknown mass to a goal.

    Observation (float32, 16): cube position on the desk (2, m), goal position (2, m), joint positions
    (6, rad), joint velocities (6, rad/s).
    Action (1, normalised to [-1, 1] over the mass range): the cube-mass estimate (kg) the push is planned
    with; `action_for(estimate)` makes one. One step is one push; the episode then terminates.
    Reward: 1 when the cube rests within the goal tolerance, else 0.
    Info: `final_error` (m, distance from cube to goal), `contact_force` (largest push force at the wrist,
    N), `success`, `param` (the true cube mass, kg), `estimate` (kg), the action's physical value."""

    metadata = {"render_modes": []}  # noqa: RUF012 - gymnasium's convention
    action_space: gym.spaces.Box

    def __init__(self, config: PushingConfig | None = None) -> None:
        _check_config(config, PushingConfig)
        self.task = PushingTask(config)
        cfg = self.task.config
        self.observation_space = _observation_space(16)
        self._actions = _NormalisedActions(
            np.array([cfg.mass_range[0]]), np.array([cfg.mass_range[1]]), "cube-mass estimate"
        )
        self.action_space = self._actions.space
        self._episode_over: bool | None = None
        """None outside an episode (before the first successful reset); else whether it has ended."""

    def _observe(self) -> np.ndarray:
        scene = self.task.scene
        d = scene.data
        cube = d.qpos[scene.cube_qpos : scene.cube_qpos + 2]
        return np.concatenate([cube, self.task.goal, d.qpos[scene.arm_qpos], d.qvel[scene.arm_dof]]).astype(
            np.float32
        )

    def action_for(self, estimate: float) -> np.ndarray:
        """The normalised action of a push planned with the cube-mass `estimate` (kg)."""
        return self._actions.action(estimate)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict]:
        super().reset(seed=seed)
        self._episode_over = None
        mass = _parameter(self, options, self.task.config.mass_range, "cube mass")
        start, goal = self.task.sample_layout(self.np_random)
        self.task.reset(mass, start, goal)
        self._episode_over = False
        return self._observe(), {"param": mass}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict]:
        _check_running(self, self._episode_over)
        (estimate,) = self._actions.physical(action)
        self._episode_over = True  # one push per episode, and a failed push voids it
        push = self.task.push(float(estimate))
        forces = np.linalg.norm(push.features[:, WRIST_FORCE], axis=1)
        info = {
            "final_error": push.final_error,
            "contact_force": float(forces.max()),
            "success": push.success,
            "param": self.task.mass,
            "estimate": float(estimate),
        }
        return self._observe(), float(push.success), True, False, info

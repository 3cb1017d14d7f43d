"""The flat-action wiping world of the pretrained-COACH baseline (paper section 5, R1, Fig. 2c).

No grid and no goal-conditioned controller: a flat policy sees the low-level state (`observe`): the
sponge's position on the desk (normalised to [-1, 1] over the wiping area), its velocity (in units of the
tool speed) and the normal contact force (in units of the top of the safe band), 5 numbers. It picks one of
`DIRECTIONS`, eight Cartesian displacements of the sponge's reference on the desk, each held for a chunk of
`chunk_periods` control periods at the tool speed (0.1 s: 1 cm at 0.1 m/s), while the admittance
controller presses at the surface (`apply_action`). The chunk keeps the number of decisions (and of
feedbacks) per episode within reach; one control period per decision would be 10x more.

The expert (`expert_direction`) moves the sponge the way the grid expert's next goal would: the
displacement closest in angle to the direction from the sponge to U(cell, expert(cell)). It labels the
demonstrations the policy is cloned from (`collect_demonstrations`) and is what the feedback teacher
compares an action with (`low_level_expert`).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import mujoco
import numpy as np

from hipref.control.tool import FORCE_Z
from hipref.envs.gridworld import WipingGrid
from hipref.envs.wiping import WipingTask
from hipref.validation import check_int

DIRECTIONS: np.ndarray = np.array([[math.cos(k * math.pi / 4), math.sin(k * math.pi / 4)] for k in range(8)])
"""Unit displacement directions on the desk: east (+x), north-east, north (+y), ... counter-clockwise."""
OBSERVATION_SIZE = 5


def observe(task: WipingTask, grid: WipingGrid) -> np.ndarray:
    """The low-level state s: sponge position (normalised), velocity (/ tool speed), normal force
    (/ top of the safe band)."""
    scene = task.scene
    xy = scene.data.site_xpos[scene.tool_tip][:2]
    half = np.array([grid.area_x[1] - grid.area_x[0], grid.area_y[1] - grid.area_y[0]]) / 2
    mid = np.array([grid.area_x[0], grid.area_y[0]]) + half
    velocity = np.zeros(6)  # angular then linear, world frame
    mujoco.mj_objectVelocity(scene.model, scene.data, mujoco.mjtObj.mjOBJ_SITE, scene.tool_tip, velocity, 0)
    return np.concatenate(
        [
            (xy - mid) / half,
            velocity[3:5] / task.config.scene.tool_speed,
            [task.contact_force() / task.config.force_band[1]],
        ]
    ).astype(np.float32)


def position(grid: WipingGrid, state: tuple[float, ...] | np.ndarray) -> np.ndarray:
    """The sponge's desk position back from the normalised first two entries of s."""
    half = np.array([grid.area_x[1] - grid.area_x[0], grid.area_y[1] - grid.area_y[0]]) / 2
    mid = np.array([grid.area_x[0], grid.area_y[0]]) + half
    return mid + np.asarray(state[:2], dtype=float) * half


def expert_direction(grid: WipingGrid, tool_xy: np.ndarray) -> int:
    """The displacement the expert's next goal calls for: closest in angle to U(c, expert(c)) - xy, c the
    sponge's cell. The demonstrations' label, and the teacher's expert through `low_level_expert`."""
    cell = grid.nearest_cell(tool_xy)
    delta = grid.goal(cell, grid.expert(cell)) - np.asarray(tool_xy, dtype=float)
    return int(np.argmax(DIRECTIONS @ delta))


def low_level_expert(grid: WipingGrid) -> Callable[[tuple[float, ...]], int]:
    """The expert a `ScriptedFeedbackTeacher` compares a low-level action with: +1 for the expert's
    direction at the sponge's position (read from the state), -1 for any other."""
    return lambda state: expert_direction(grid, position(grid, state))


def apply_action(
    task: WipingTask, grid: WipingGrid, action: int, height: float, chunk_periods: int
) -> tuple[np.ndarray, np.ndarray]:
    """Execute one low-level action: move the reference along DIRECTIONS[action] at tool speed for a chunk,
    pressing at `height` (the true desk height: the SI is not part of R1). The reference is kept inside the
    wiping area. Returns the per-period tool positions and normal forces."""
    cfg = task.config
    dt = cfg.scene.control_period
    ref = task.reference
    ref[2] = height - cfg.press_depth
    step_x, step_y = DIRECTIONS[action] * cfg.scene.tool_speed * dt
    x, y = float(ref[0]), float(ref[1])
    targets = np.empty((chunk_periods, 3))
    targets[:, 2] = ref[2]
    for k in range(chunk_periods):
        x = min(max(x + step_x, grid.area_x[0]), grid.area_x[1])
        y = min(max(y + step_y, grid.area_y[0]), grid.area_y[1])
        targets[k, :2] = x, y
    ref[:2] = x, y
    features, tool_pos = task.controller.track(targets, task.rotation)  # the whole chunk in one kernel call
    return tool_pos[:, :2], features[:, FORCE_Z].copy()


def chunks_per_cell(task: WipingTask, grid: WipingGrid, chunk_periods: int) -> int:
    """Low-level actions that move the sponge's reference across one cell at the tool speed."""
    period = task.config.scene.control_period
    return max(1, round(grid.cell_size / (task.config.scene.tool_speed * period * chunk_periods)))


def collect_demonstrations(
    count: int, goals: int, height: float, chunk_periods: int, seed: int
) -> tuple[np.ndarray, np.ndarray]:
    """Demonstrations of the predefined force controller following the expert: each starts at a random
    cell, approaches the desk and follows the expert for `goals` cells, one chunk at a time. Short
    demonstrations from random cells cover the desk as well as full sweeps at a fraction of the cost.
    Returns (observations, expert actions)."""
    check_int("count", count, 1)
    check_int("goals", goals, 1)
    task = WipingTask()
    grid = WipingGrid(task.config.area_x, task.config.area_y)
    rng = np.random.default_rng(seed)
    cells = list(grid.cells())
    per_cell = chunks_per_cell(task, grid, chunk_periods)
    observations, actions = [], []
    for _ in range(count):
        start = cells[rng.integers(len(cells))]
        task.reset(height, tuple(grid.center(start)))
        task.approach(height)
        for _ in range(goals * per_cell):
            s = observe(task, grid)
            a = expert_direction(grid, task.scene.data.site_xpos[task.scene.tool_tip][:2])
            observations.append(s)
            actions.append(a)
            apply_action(task, grid, a, height, chunk_periods)
    return np.stack(observations), np.asarray(actions, dtype=np.int64)

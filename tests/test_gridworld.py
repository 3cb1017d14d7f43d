"""The high-level grid world of desk wiping (A.7): coverage expert, the mapping U, re-alignment."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from hipref.control.arm import START_POSTURE
from hipref.envs.gridworld import DOWN, LEFT, RIGHT, UP, WipingGrid
from hipref.envs.wiping import WipingTask


@pytest.fixture(scope="module")
def grid() -> WipingGrid:
    return WipingGrid()


def test_grid_has_twelve_by_six_cells_of_five_centimetres(grid: WipingGrid) -> None:
    assert (grid.n_cols, grid.n_rows, grid.n_states) == (12, 6, 72)
    assert np.allclose(grid.center((0, 0)), [-0.275, -0.075])
    assert np.allclose(grid.center((11, 5)), [0.275, 0.175])


def test_moving_off_the_grid_keeps_the_state(grid: WipingGrid) -> None:
    assert grid.move((0, 0), LEFT) == (0, 0)
    assert grid.move((0, 0), DOWN) == (0, 0)
    assert grid.move((11, 5), UP) == (11, 5)
    assert grid.move((3, 2), RIGHT) == (4, 2)


@pytest.mark.parametrize("start", [(0, 0), (5, 3), (11, 5), (0, 4)])
def test_expert_covers_every_cell_from_any_start(grid: WipingGrid, start: tuple[int, int]) -> None:
    state, seen = start, {start}
    for _ in range(grid.n_states - 1):
        nxt = grid.move(state, grid.expert(state))
        assert nxt != state, "the expert never bumps into the edge"
        state = nxt
        seen.add(state)
    assert len(seen) == grid.n_states


def test_u_is_the_centre_of_the_next_cell_and_inverts_cell_of(grid: WipingGrid) -> None:
    for cell in grid.cells():
        for action in range(grid.n_actions):
            assert grid.cell_of(grid.goal(cell, action)) == grid.move(cell, action)


@pytest.mark.parametrize("height", [0.5, 0.7, 0.9])
def test_u_maps_every_cell_to_a_reachable_goal_on_the_desk(grid: WipingGrid, height: float) -> None:
    task = WipingTask()
    scratch = mujoco.MjData(task.scene.model)
    worst = 0.0
    press = height - task.config.press_depth
    for cell in grid.cells():
        # As the task gets there: IK from the start posture to the hover pose above the goal, then down
        # to the pressing depth below the surface.
        scratch.qpos[task.scene.arm_qpos] = START_POSTURE
        hover = np.array([*grid.center(cell), task.config.hover_height])
        task.controller.ik.solve(scratch, hover, task.rotation)
        _, residual = task.controller.ik.solve(scratch, np.array([*grid.center(cell), press]), task.rotation)
        worst = max(worst, float(residual))
    assert worst < 1e-3


def test_realign_after_a_failed_reach_puts_the_state_where_the_sponge_is(grid: WipingGrid) -> None:
    target = (4, 2)
    sponge = grid.center((3, 2)) + 0.01  # stopped short, inside the previous cell
    assert grid.realign(target, False, sponge) == (3, 2)
    assert grid.realign(target, True, sponge) == target
    # A sponge pushed just outside the area is put back on the nearest cell.
    assert grid.realign((0, 0), False, np.array([-0.31, -0.11])) == (0, 0)


def test_after_a_real_stroke_the_state_is_the_sponge_cell(grid: WipingGrid) -> None:
    task = WipingTask()
    task.reset(0.7, tuple(grid.center((0, 0))))
    stroke = task.stroke(grid.center((1, 0)), 0.7)
    state = grid.realign((1, 0), stroke.reached, stroke.tool_xy[-1])
    assert stroke.reached and state == (1, 0) == grid.cell_of(stroke.tool_xy[-1])


def test_wiped_counts_only_cells_passed_while_pressing_in_band(grid: WipingGrid) -> None:
    xy = np.array([grid.center((0, 0)), grid.center((1, 0)), grid.center((2, 0))])
    force = np.array([10.0, 0.0, 80.0])
    assert grid.wiped(xy, force, (1.0, 60.0)) == {(0, 0)}

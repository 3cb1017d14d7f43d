"""R1 high level (Fig. 2c): the pretrained-COACH teacher, config validation and determinism."""

from __future__ import annotations

import dataclasses

import numpy as np
import pandas as pd
import pytest

from hipref.envs.flat_wiping import DIRECTIONS, OBSERVATION_SIZE, expert_direction, low_level_expert
from hipref.envs.gridworld import WipingGrid
from hipref.experiments.r1_feedback import METHODS, R1Cell, R1Config, run_cell
from hipref.learners.pretrained_coach import FlatPolicy, PretrainedCoach, PretrainedCoachConfig
from hipref.teachers.feedback import ScriptedFeedbackTeacher


def _policy() -> FlatPolicy:
    return FlatPolicy(OBSERVATION_SIZE, len(DIRECTIONS), 8)


def _state_at(grid: WipingGrid, xy: np.ndarray) -> tuple[float, ...]:
    half = np.array([grid.area_x[1] - grid.area_x[0], grid.area_y[1] - grid.area_y[0]]) / 2
    mid = np.array([grid.area_x[0], grid.area_y[0]]) + half
    return (*((xy - mid) / half), 0.0, 0.0, 0.2)


@pytest.mark.parametrize("cell", [(0, 0), (11, 0), (5, 1), (1, 5), (0, 3), (6, 4)])
def test_low_level_teacher_says_yes_to_the_expert_direction_no_to_the_opposite(cell: tuple[int, int]) -> None:
    grid = WipingGrid()
    teacher = ScriptedFeedbackTeacher(low_level_expert(grid))
    learner = PretrainedCoach(_policy(), PretrainedCoachConfig(hidden=8))
    xy = grid.center(cell)
    expert = expert_direction(grid, xy)
    # The expert's direction is the grid expert's move, seen as a displacement on the desk.
    move = grid.goal(cell, grid.expert(cell)) - xy
    assert np.allclose(DIRECTIONS[expert] * np.linalg.norm(move), move)
    state = _state_at(grid, xy)
    assert teacher.answer(learner.ask(np.asarray(state, np.float32), expert)) == 1
    assert teacher.answer(learner.ask(np.asarray(state, np.float32), (expert + 4) % 8)) == -1


def test_eq1_on_the_flat_policy_moves_probability_the_way_of_the_feedback() -> None:
    import torch

    torch.manual_seed(0)
    learner = PretrainedCoach(_policy(), PretrainedCoachConfig(hidden=8, learning_rate=0.5))
    s = np.zeros(5, np.float32)
    before = learner.probabilities(s)[3]
    learner.tell(learner.ask(s, 3), 1)
    assert learner.probabilities(s)[3] > before
    middle = learner.probabilities(s)[3]
    learner.tell(learner.ask(s, 3), -1)
    assert learner.probabilities(s)[3] < middle


@pytest.mark.parametrize(
    ("field", "value"), [("episodes", 0), ("desk_height", 0.95), ("max_steps", -1), ("demos", 0.5)]
)
def test_config_refuses_bad_values_naming_the_parameter(field: str, value: object) -> None:
    with pytest.raises(ValueError, match=field):
        R1Config(**{field: value})


def test_same_seed_gives_identical_rows_and_another_seed_other_rows(
    tmp_path: object, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("HIPREF_CACHE_DIR", str(tmp_path))
    config = R1Config(episodes=2, max_steps=4, seeds=1, demos=2, demo_goals=1, bc_epochs=2, hidden=8)
    for method in METHODS:
        first = run_cell(R1Cell(config, method, 7))
        second = run_cell(R1Cell(config, method, 7))
        pd.testing.assert_frame_equal(first, second)
        assert list(first.columns[:7]) == ["domain", "method", "noise", "seed", "episode", "metric", "value"]
        assert (first["metric"] == "cells_wiped").all() and (first["value"] >= 0).all()
        assert (first["value"] <= WipingGrid().n_states).all()  # a count of the grid's cells
    # The seed does reach the run: another seed draws other actions, so other strokes and physics steps.
    other = run_cell(R1Cell(config, "tabular_coach", 8))
    first = run_cell(R1Cell(config, "tabular_coach", 7))
    assert not first[["value", "decisions", "physics_steps"]].equals(
        other[["value", "decisions", "physics_steps"]]
    )


def test_equal_configs_make_equal_cells_and_any_changed_field_another_cell() -> None:
    # Cells key the sweep's cache: two separately built equal cells must be one key, any change another.
    cell = R1Cell(R1Config(), "tabular_coach", 1)
    same = R1Cell(R1Config(), "tabular_coach", 1)
    assert same is not cell and same == cell and hash(same) == hash(cell) and {cell: "rows"}[same] == "rows"
    changed = [
        R1Cell(dataclasses.replace(R1Config(), seeds=3), "tabular_coach", 1),
        R1Cell(dataclasses.replace(R1Config(), desk_height=0.71), "tabular_coach", 1),
        R1Cell(R1Config(), "pretrained_coach", 1),
        R1Cell(R1Config(), "tabular_coach", 2),
    ]
    assert len({cell, same, *changed}) == 1 + len(changed)

"""R1, high level (notebook 01, paper Fig. 2c): discrete feedback on the grid versus on a flat policy.

Both learners wipe the real MuJoCo desk and hear the same noise-free scripted teacher at every step (A.7):

- `tabular_coach` (ours): tabular COACH (Eq. 1) over the grid world of `hipref.envs.gridworld`; each
  high-level step is a stroke of the goal-conditioned force controller to U(s, a), after which the grid
  state is re-aligned to the sponge if the stroke missed its goal.
- `pretrained_coach`: the flat MLP policy of `hipref.learners.pretrained_coach`, behaviour-cloned on
  demonstrations of the same controller following the same expert, then updated by Eq. 1 on every
  low-level action. It gets the same simulated time per episode: one high-level step is worth
  `chunks_per_step` low-level actions (a stroke's moving and settling time).

The metric is physical: `cells_wiped` counts the cells the sponge really passed over while pressing with
a force inside the safe band, not the cells the abstract policy visited. The controller is given the true
desk height: the SI model is not part of R1.

Cost, kept down without changing what is measured: a grid move off the desk executes nothing (no physics),
and an episode ends once every cell is wiped (nothing more can be counted).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Annotated, Any

import numpy as np
import pandas as pd

from hipref.envs.flat_wiping import (
    DIRECTIONS,
    OBSERVATION_SIZE,
    apply_action,
    collect_demonstrations,
    low_level_expert,
    observe,
)
from hipref.envs.gridworld import Cell, WipingGrid
from hipref.envs.wiping import WipingTask
from hipref.learners.coach import CoachConfig, TabularCoach
from hipref.learners.pretrained_coach import PretrainedCoach, PretrainedCoachConfig, behaviour_cloning
from hipref.numerics import one_thread
from hipref.results import tidy_rows
from hipref.seeds import child_seeds
from hipref.sweep import NO_CACHE, CacheDir, Expect, cached_artefact, run_sweep
from hipref.teachers.feedback import ScriptedFeedbackTeacher
from hipref.validation import Integer, Range, check_choice, check_fields

START: Cell = (0, 0)
"""Every episode starts with the sponge above cell (0, 0), the start of the expert's sweep."""


@dataclass(frozen=True)
class R1Config:
    """Parameters of notebook 01 (defaults: the quick profile; the paper's values in params/full)."""

    episodes: Annotated[int, Integer(1, 10_000)] = 10
    """Learning episodes per run (A.7: 50)."""
    max_steps: Annotated[int, Integer(1, 100_000)] = 120
    """High-level steps per episode at most (A.7: 290); the flat policy gets the same simulated time."""
    seeds: Annotated[int, Integer(1, 1000)] = 2
    """Independent runs per method (paper: not given; full profile 2)."""
    desk_height: Annotated[float, Range(0.5, 0.9)] = 0.7
    """True desk height in m, given to the controller (no SI in R1); in [0.5, 0.9]."""
    coach_learning_rate: Annotated[float, Range(0.0, 100.0)] = 0.5
    """alpha of tabular COACH (Eq. 1)."""
    demos: Annotated[int, Integer(1, 100_000)] = 100
    """Demonstration trajectories for pretraining the flat policy (paper: 1000)."""
    demo_goals: Annotated[int, Integer(1, 100)] = 3
    """Cells each demonstration follows the expert for, from a random start cell."""
    chunk_periods: Annotated[int, Integer(1, 100)] = 10
    """Control periods (10 ms each) one low-level action of the flat policy lasts."""
    hidden: Annotated[int, Integer(4, 4096)] = 64
    """Hidden units per layer of the flat policy."""
    bc_epochs: Annotated[int, Integer(0, 10_000)] = 30
    """Behaviour-cloning passes over the demonstrations."""
    policy_learning_rate: Annotated[float, Range(0.0, 10.0)] = 1e-2
    """SGD step size of Eq. 1 on the flat policy, one step per feedback."""
    stop_when_wiped: bool = True
    """End an episode once every cell is wiped (saves compute; the count cannot grow further)."""
    seed: Annotated[int, Integer(0)] = 0
    """Root seed; every run's seed derives from it."""

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class R1Cell:
    """One learning run: a method and its seed under a config."""

    config: R1Config
    method: str
    seed: int


@dataclass(frozen=True)
class DemoSpec:
    """What identifies the demonstration set, shared by every pretrained run of a config."""

    count: int
    goals: int
    height: float
    chunk_periods: int
    seed: int


def demo_spec(config: R1Config) -> DemoSpec:
    return DemoSpec(config.demos, config.demo_goals, config.desk_height, config.chunk_periods, config.seed)


def demonstrations(spec: DemoSpec, cache_dir: CacheDir = None) -> tuple[np.ndarray, np.ndarray]:
    """The demonstrations, collected once per spec and cached."""
    return cached_artefact(
        "r1_demonstrations",
        spec,
        lambda: collect_demonstrations(spec.count, spec.goals, spec.height, spec.chunk_periods, spec.seed),
        cache_dir=cache_dir,
        expect=Expect(
            tuple,
            lambda d: d[0].ndim == 2 and d[0].shape[1] == OBSERVATION_SIZE and d[1].shape == (len(d[0]),),
        ),
    )


def chunks_per_step(task: WipingTask, grid: WipingGrid, chunk_periods: int) -> int:
    """Low-level actions worth one high-level step: a one-cell stroke's moving plus settling periods."""
    scene = task.config.scene
    stroke_periods = math.ceil(grid.cell_size / (scene.tool_speed * scene.control_period)) + round(
        0.1 / scene.control_period
    )
    return math.ceil(stroke_periods / chunk_periods)


def tabular_episode(
    task: WipingTask,
    grid: WipingGrid,
    coach: TabularCoach,
    teacher: ScriptedFeedbackTeacher,
    config: R1Config,
    rng: np.random.Generator,
) -> tuple[int, int, int]:
    """One feedback episode of tabular COACH; returns (cells wiped, strokes, physics steps)."""
    band = task.config.force_band
    task.reset(config.desk_height, tuple(grid.center(START)))
    coach.reset_trace()
    state, wiped, strokes, periods = START, set(), 0, 0
    for _ in range(config.max_steps):
        action = coach.act(state, rng)
        # Feedback every step (A.7), Eq. 1 on the queried (s, a).
        query = coach.ask(state, action)
        coach.tell(query, teacher.answer(query))
        target = grid.move(state, action)
        if target == state:  # off the grid: the goal is where the sponge is, nothing to execute
            continue
        stroke = task.stroke(grid.center(target), config.desk_height)
        strokes += 1
        periods += len(stroke.force)
        wiped |= grid.wiped(stroke.tool_xy, stroke.force, band)
        state = grid.realign(target, stroke.reached, stroke.tool_xy[-1])  # A.7: reset the grid on a miss
        if config.stop_when_wiped and len(wiped) == grid.n_states:
            break
    return len(wiped), strokes, periods * task.controller.substeps


def pretrained_episode(
    task: WipingTask,
    grid: WipingGrid,
    learner: PretrainedCoach,
    teacher: ScriptedFeedbackTeacher,
    config: R1Config,
    rng: np.random.Generator,
) -> tuple[int, int, int]:
    """One feedback episode of pretrained COACH; returns (cells wiped, low-level actions, physics steps)."""
    band = task.config.force_band
    task.reset(config.desk_height, tuple(grid.center(START)))
    task.approach(config.desk_height)
    budget = config.max_steps * chunks_per_step(task, grid, config.chunk_periods)
    wiped: set[Cell] = set()
    actions = 0
    for _ in range(budget):
        s = observe(task, grid)
        action = learner.act(s, rng)
        query = learner.ask(s, action)
        learner.tell(query, teacher.answer(query))  # Eq. 1 on the flat policy
        tool_xy, force = apply_action(task, grid, action, config.desk_height, config.chunk_periods)
        actions += 1
        wiped |= grid.wiped(tool_xy, force, band)
        if config.stop_when_wiped and len(wiped) == grid.n_states:
            break
    return len(wiped), actions, actions * config.chunk_periods * task.controller.substeps


Episode = Callable[[np.random.Generator], tuple[int, int, int]]
"""One learning episode of a method's learner: cells wiped, high-level decisions and physics steps."""


def tabular_learner(cell: R1Cell, task: WipingTask, grid: WipingGrid) -> Episode:
    """tabular_coach's episodes: tabular COACH told the grid expert's feedback."""
    learner = TabularCoach(grid.n_states, grid.n_actions, CoachConfig(cell.config.coach_learning_rate))
    teacher = ScriptedFeedbackTeacher(grid.expert)
    return functools.partial(tabular_episode, task, grid, learner, teacher, cell.config)


def pretrained_learner(cell: R1Cell, task: WipingTask, grid: WipingGrid) -> Episode:
    """pretrained_coach's episodes: the behaviour-cloned policy told the low-level expert's feedback."""
    config = cell.config
    coach_config = PretrainedCoachConfig(
        config.hidden, config.bc_epochs, learning_rate=config.policy_learning_rate
    )
    observations, actions = demonstrations(demo_spec(config))
    policy = behaviour_cloning(observations, actions, len(DIRECTIONS), coach_config, cell.seed)
    return functools.partial(
        pretrained_episode,
        task,
        grid,
        PretrainedCoach(policy, coach_config),
        ScriptedFeedbackTeacher(low_level_expert(grid)),
        config,
    )


LEARNERS: dict[str, Callable[[R1Cell, WipingTask, WipingGrid], Episode]] = {
    "tabular_coach": tabular_learner,
    "pretrained_coach": pretrained_learner,
}
"""Every method by name and how its learning episodes are built."""

METHODS: tuple[str, ...] = tuple(LEARNERS)
"""The methods' names, in LEARNERS' order."""


def run_cell(cell: R1Cell) -> pd.DataFrame:
    """All learning episodes of one (method, seed): cells wiped per episode, as tidy rows."""
    config = cell.config
    check_choice("method", cell.method, METHODS)
    rng = np.random.default_rng(cell.seed)
    task = WipingTask()
    grid = WipingGrid(task.config.area_x, task.config.area_y)
    with one_thread():
        episode = LEARNERS[cell.method](cell, task, grid)
        rows = []
        for k in range(config.episodes):
            cells, decisions, steps = episode(rng)
            rows.append((k, "cells_wiped", float(cells), decisions, steps))
    return tidy_rows(
        rows,
        ("episode", "metric", "value", "decisions", "physics_steps"),
        domain="wiping",
        method=cell.method,
        noise=0.0,
        seed=cell.seed,
    )


def run(config: R1Config, **sweep: Any) -> pd.DataFrame:
    """Both methods over `config.seeds` seeds (from numpy's SeedSequence of `config.seed`); the
    demonstrations are collected first, once, in this process. `sweep`: `run_sweep`'s options."""
    if sweep.get("cache_dir") is not NO_CACHE:
        demonstrations(demo_spec(config), sweep.get("cache_dir"))
    seeds = child_seeds(config.seed, config.seeds)
    cells = [R1Cell(config, method, seed) for method in METHODS for seed in seeds]
    return run_sweep(run_cell, cells, desc="R1 feedback (Fig. 2c)", **sweep)

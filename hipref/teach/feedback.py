"""Tabular COACH (Eq. 1) with a person giving the feedback: one episode on the wiping grid.

At each high-level step COACH proposes a move from the sponge's cell; the person answers +1 (good), 0
(indifferent) or -1 (bad). The answer is appended to the session file, then COACH is told (Eq. 1) and the
move is executed by the force controller in MuJoCo, as in notebook 01: the cells the sponge passes over
while pressing inside the safe band are wiped, and the grid is re-aligned when a stroke misses (A.7).
Resuming replays the stored answers: COACH draws the same moves from its seeded stream, and the physics
is deterministic, so the episode continues where it stopped (a mismatch is refused).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hipref.envs.gridworld import ACTIONS, Cell, WipingGrid
from hipref.envs.wiping import WipingTask
from hipref.experiments.r1_feedback import START
from hipref.learners.coach import CoachConfig, TabularCoach
from hipref.teach.config import TeachConfig
from hipref.teach.session import SessionFile
from hipref.teachers.feedback import validate_feedback


class FeedbackTeaching:
    """A session's feedback part: COACH's episode, the proposed move and the wiped cells."""

    def __init__(self, config: TeachConfig, session: SessionFile) -> None:
        self.config = config
        self.session = session
        self.task = WipingTask()
        self.grid = WipingGrid(self.task.config.area_x, self.task.config.area_y)
        self.coach = TabularCoach(self.grid.n_states, self.grid.n_actions, CoachConfig())
        self._rng = np.random.default_rng(np.random.SeedSequence([config.seed, 7]))
        self.task.reset(config.desk_height, tuple(self.grid.center(START)))
        self.coach.reset_trace()
        self.state: Cell = START
        self.wiped: set[Cell] = set()
        self.proposed: int | None = None
        self.steps = 0
        """Feedback answers told so far (all those stored, once the episode is replayed)."""
        self._propose()
        for record in session.of_kind("feedback"):
            if (record["state"], record["action"]) != (list(self.state), self.proposed):
                raise ValueError(
                    f"{session.path}: feedback {record['step']} was given to move {record['action']} from "
                    f"{record['state']}, but this session proposes {self.proposed} from {list(self.state)}"
                )
            self._tell(record["feedback"])

    @property
    def done(self) -> bool:
        return self.steps >= self.config.feedback_steps

    def _propose(self) -> None:
        self.proposed = None if self.done else self.coach.act(self.state, self._rng)

    def _tell(self, feedback: int) -> None:
        """Eq. 1 on the proposed move, then the move executed (a move off the grid executes nothing)."""
        action = self.proposed
        assert action is not None
        self.coach.tell(self.coach.ask(self.state, action), feedback)
        target = self.grid.move(self.state, action)
        if target != self.state:
            stroke = self.task.stroke(self.grid.center(target), self.config.desk_height)
            self.wiped |= self.grid.wiped(stroke.tool_xy, stroke.force, self.task.config.force_band)
            self.state = self.grid.realign(target, stroke.reached, stroke.tool_xy[-1])
        self.steps += 1
        self._propose()

    def answer(self, feedback: int, seconds: float) -> None:
        """The person's `feedback` on the proposed move after `seconds`: stored, then told and executed."""
        feedback = validate_feedback(feedback)
        if self.proposed is None:
            raise RuntimeError("the feedback episode is over")
        record: dict[str, Any] = {
            "kind": "feedback",
            "step": self.steps,
            "state": list(self.state),
            "action": self.proposed,
            "move": ACTIONS[self.proposed],
            "feedback": feedback,
            "seconds": round(float(seconds), 3),
            "seed": self.config.seed,
        }
        self.session.append(record)
        self._tell(feedback)

    def expert_feedback(self) -> int:
        """What the scripted teacher of notebook 01 would answer: +1 for the expert's move, else -1."""
        assert self.proposed is not None
        return 1 if self.proposed == self.grid.expert(self.state) else -1

    def svg(self, size: int = 28) -> str:
        """The grid as an SVG drawing: wiped cells filled, the sponge's cell outlined, the proposed move as
        an arrow. Row 0 (the robot's side) is drawn at the bottom."""
        cols, rows = self.grid.n_cols, self.grid.n_rows
        parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{cols * size}" height="{rows * size}">']
        for col in range(cols):
            for row in range(rows):
                fill = "#6baed6" if (col, row) in self.wiped else "#f0f0f0"
                y = (rows - 1 - row) * size
                square = f'width="{size}" height="{size}" fill="{fill}" stroke="#999"'
                parts.append(f'<rect x="{col * size}" y="{y}" {square}/>')
        col, row = self.state
        cx, cy = (col + 0.5) * size, (rows - 1 - row + 0.5) * size
        parts.append(f'<circle cx="{cx}" cy="{cy}" r="{size * 0.3}" fill="#fdae6b" stroke="#e6550d"/>')
        if self.proposed is not None:
            tcol, trow = self.grid.move(self.state, self.proposed)
            dx, dy = self._arrow(tcol - col, row - trow, size)
            parts.append(
                f'<line x1="{cx}" y1="{cy}" x2="{cx + dx}" y2="{cy + dy}" stroke="#d62728" stroke-width="4"/>'
            )
            parts.append(f'<circle cx="{cx + dx}" cy="{cy + dy}" r="5" fill="#d62728"/>')
        parts.append("</svg>")
        return "".join(parts)

    def _arrow(self, dcol: int, drow: int, size: int) -> tuple[float, float]:
        if (dcol, drow) == (0, 0):  # off the grid: point at the edge the move would cross
            dcol, drow = {0: (0, -1), 1: (0, 1), 2: (-1, 0), 3: (1, 0)}[self.proposed or 0]
        return dcol * size * 0.8, drow * size * 0.8

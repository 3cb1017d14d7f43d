"""The marks a person judges a clip by: the wiping clip's force gauge with its safe band, the pushing clip's
strip from the cube to its goal; the questions name the task and the feedback grid has a legend."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from hipref.teach.app import GRID_LEGEND, QUESTIONS
from hipref.teach.clips import CUBE, GAUGE_TOP, GOAL, HARD, SAFE, force_gauge, push_strip

FRAME = np.zeros((240, 320, 3), dtype=np.uint8)
BAND = (1.0, 60.0)


def bar(frame: np.ndarray, force: float) -> tuple[int, ...]:
    """The gauge's colour just below where `force` reaches (the bar's top), in its middle column."""
    height, width = frame.shape[:2]
    top, bottom = 22, height - 22
    y = bottom - (bottom - top) * min(force, GAUGE_TOP * BAND[1]) / (GAUGE_TOP * BAND[1]) + 2
    return tuple(int(c) for c in frame[int(y), width - 18])


@pytest.mark.parametrize(("force", "colour"), [(30.0, SAFE), (200.0, HARD), (90.0, HARD)])
def test_the_gauge_shows_a_force_in_the_safe_band_green_and_above_it_red(force, colour):
    assert bar(force_gauge(FRAME, force, BAND), force) == colour


def test_the_gauge_of_a_sponge_not_touching_shows_the_safe_band_unfilled():
    marked = force_gauge(FRAME, 0.0, BAND)
    assert bar(marked, 30.0) == (199, 233, 192)  # the band's shade, no bar over it
    assert bar(marked, 60.0) == (199, 233, 192)


def test_the_strip_puts_the_cube_before_its_goal_when_short_and_after_it_when_past():
    def cube_x(marked: np.ndarray) -> float:
        return float(np.flatnonzero(np.all(marked[-12] == CUBE, axis=-1)).mean())

    def goal_x(marked: np.ndarray) -> float:
        return float(np.flatnonzero(np.all(marked[-12 - 8] == GOAL, axis=-1)).mean())

    short, past = push_strip(FRAME, 0.10, 0.30), push_strip(FRAME, 0.40, 0.30)
    assert cube_x(short) < goal_x(short) < cube_x(past)
    assert goal_x(short) == goal_x(past)


def test_each_question_names_its_task_and_the_grid_says_the_move_is_executed_anyway():
    assert "wiping the desk" in QUESTIONS["wiping"] and "pushing the cube" in QUESTIONS["pushing"]
    assert "executed whatever you answer" in GRID_LEGEND and "wiped cell" in GRID_LEGEND


def test_the_committed_notebook_09_keeps_no_clip_in_its_widgets_state():
    """The stand-in's clips are dropped from the widgets once answered (`PreferenceApp.clear_clips`): a GIF
    (base64 'R0lGOD') left in the saved widget state would make the notebook hundreds of KB larger."""
    notebook = Path(__file__).resolve().parents[1] / "notebooks" / "09_teach.ipynb"
    assert "R0lGOD" not in notebook.read_text()

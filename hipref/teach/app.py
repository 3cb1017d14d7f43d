"""The widgets a person teaches with in JupyterLab, and the scripted stand-in that presses them.

`PreferenceApp` shows a query's two clips side by side and looping, with buttons 'left', 'right' and
"can't tell" and the keys <- -> and down (or a, d, s) while the mouse is over it; `FeedbackApp` shows the
wiping grid with COACH's proposed move and buttons +1, 0, -1 (keys 1 or +, 0, and -). Both show a progress
bar. Every press goes to the session (`hipref.teach.preferences`, `hipref.teach.feedback`), which stores the
answer before the learner is told. `answer_as_scripted` plays the person: it presses the same buttons
(`Button.click` runs the same callbacks), so papermill and nbval execute the whole path headlessly.
"""

from __future__ import annotations

import html
import time
from collections.abc import Mapping
from typing import Any, ClassVar

import ipywidgets as widgets
import numpy as np
from ipyevents import Event

from hipref.experiments.domains import domain_spec
from hipref.teach.feedback import FeedbackTeaching
from hipref.teach.preferences import ANSWERS, PreferenceTeaching
from hipref.teachers.preference import ScriptedPreferenceTeacher

PREFERENCE_KEYS: dict[str, str] = {
    "ArrowLeft": "left",
    "a": "left",
    "ArrowRight": "right",
    "d": "right",
    "ArrowDown": "cant_tell",
    "s": "cant_tell",
}
"""Keys of the preference answers, while the mouse is over the widget."""
FEEDBACK_KEYS: dict[str, int] = {"1": 1, "+": 1, "0": 0, "-": -1}
"""Keys of the feedback values, while the mouse is over the widget."""
LABELS: dict[str, str] = {"left": "◀ left", "right": "right ▶", "cant_tell": "can't tell ▼"}


class AnswerPanel:
    """A question on screen, answered with buttons or keys (while the mouse is over it), each press timed."""

    KEYS: ClassVar[Mapping[str, Any]] = {}
    """Key -> the answer it gives."""

    def _build(self, css_class: str, children: list[widgets.Widget], teacher: str) -> None:
        self.scripted = teacher == "scripted"
        """A person's answer times are measured; the scripted stand-in answers the moment a question is
        shown (0 s), so that its session file is the same bytes on every run."""
        self.widget = widgets.VBox(children)
        self.widget.add_class(css_class)
        self.keys = Event(source=self.widget, watched_events=["keydown"], prevent_default_action=True)
        self.keys.on_dom_event(self._on_key)
        self.waits: list[float] = []
        """Seconds from each press until the next question was on screen."""
        self._shown_at = time.perf_counter()
        self._show()

    def _on_key(self, event: dict[str, Any]) -> None:
        value = self.KEYS.get(event.get("key", ""))
        if value is not None:
            self.press(value)

    def press(self, value: Any) -> None:
        """The person answers the question on screen (a button or a key); nothing once all are answered."""
        if self._finished():
            return
        pressed = time.perf_counter()
        self._answer(value, 0.0 if self.scripted else pressed - self._shown_at)
        self._show()
        self._shown_at = time.perf_counter()
        self.waits.append(self._shown_at - pressed)

    def _finished(self) -> bool:
        raise NotImplementedError

    def _answer(self, value: Any, seconds: float) -> None:
        raise NotImplementedError

    def _show(self) -> None:
        raise NotImplementedError


class PreferenceApp(AnswerPanel):
    """Preference queries as two looping clips; the answer buttons, keys and progress."""

    KEYS = PREFERENCE_KEYS

    def __init__(self, teaching: PreferenceTeaching, *, reveal_truth: bool = False) -> None:
        self.teaching = teaching
        self.reveal_truth = reveal_truth
        self.buttons = {answer: widgets.Button(description=LABELS[answer]) for answer in ANSWERS}
        for answer, button in self.buttons.items():
            button.on_click(lambda _, answer=answer: self.press(answer))
        self.clips = widgets.Image(format="gif")
        self.heading = widgets.HTML()
        self.progress = widgets.IntProgress(min=0, max=teaching.config.preference_queries)
        self.status = widgets.HTML()
        buttons = widgets.HBox(list(self.buttons.values()))
        self._build(
            "hipref-preferences",
            [self.heading, self.clips, buttons, self.progress, self.status],
            teaching.config.teacher,
        )

    def _finished(self) -> bool:
        return self.teaching.current is None

    def _answer(self, value: Any, seconds: float) -> None:
        self.teaching.answer(value, seconds)

    def _show(self) -> None:
        teaching, shown = self.teaching, self.teaching.current
        planned = teaching.config.preference_queries
        self.progress.value = teaching.answered
        for button in self.buttons.values():
            button.disabled = shown is None
        if shown is None:
            self.heading.value = f"<b>All {planned} preference queries answered.</b>"
            self.clips.layout.display = "none"
        elif shown.animation is None:
            self.heading.value = (
                f"<b>Query {shown.number + 1} of {planned}.</b> The clips cannot be rendered on this machine "
                "(no OpenGL; see the message above); answer only if you can judge without them."
            )
            self.clips.layout.display = "none"
        else:
            self.heading.value = (
                f"<b>Query {shown.number + 1} of {planned}:</b> which clip shows the robot doing the task "
                "better? (keys ← → ↓ with the mouse over the clips)"
            )
            self.clips.value = shown.animation
            self.clips.layout.display = None
        self.status.value = self._status()

    def _status(self) -> str:
        teaching = self.teaching
        spec = domain_spec(teaching.config.domain)
        estimate = teaching.estimate()
        text = f"answered {teaching.answered} of {teaching.config.preference_queries}; "
        text += f"the learner's estimate of the {spec.parameter}: {estimate:.3f} {spec.unit}"
        if self.reveal_truth:
            text += f" (truth {teaching.truth:.3f}, error {abs(estimate - teaching.truth):.3f} {spec.unit})"
        return html.escape(text)


class FeedbackApp(AnswerPanel):
    """COACH's episode on the grid; the feedback buttons, keys and progress."""

    KEYS = FEEDBACK_KEYS

    def __init__(self, teaching: FeedbackTeaching) -> None:
        self.teaching = teaching
        values = {1: "+1 good", 0: "0 indifferent", -1: "−1 bad"}
        self.buttons = {value: widgets.Button(description=label) for value, label in values.items()}
        for value, button in self.buttons.items():
            button.on_click(lambda _, value=value: self.press(value))
        self.grid = widgets.HTML()
        self.heading = widgets.HTML()
        self.progress = widgets.IntProgress(min=0, max=teaching.config.feedback_steps)
        buttons = widgets.HBox(list(self.buttons.values()))
        self._build(
            "hipref-feedback", [self.heading, self.grid, buttons, self.progress], teaching.config.teacher
        )

    def _finished(self) -> bool:
        return self.teaching.done

    def _answer(self, value: Any, seconds: float) -> None:
        self.teaching.answer(value, seconds)

    def _show(self) -> None:
        teaching = self.teaching
        planned = teaching.config.feedback_steps
        self.progress.value = teaching.steps
        self.grid.value = teaching.svg()
        for button in self.buttons.values():
            button.disabled = teaching.done
        wiped = f"{len(teaching.wiped)} of {teaching.grid.n_states} cells wiped"
        if teaching.done:
            self.heading.value = f"<b>Feedback episode over:</b> {wiped}."
        else:
            self.heading.value = (
                f"<b>Step {teaching.steps + 1} of {planned}:</b> is the red move good for wiping the desk? "
                f"({wiped}; keys 1, 0, − with the mouse over the grid)"
            )


def answer_preferences_as_scripted(preferences: PreferenceApp, noise: float, seed: int) -> None:
    """Answer every planned query by pressing the buttons as `ScriptedPreferenceTeacher` would: the side
    of the candidate closest to the truth, the other with probability `noise`."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 5]))
    teacher = ScriptedPreferenceTeacher(preferences.teaching.truth, noise, rng)
    while (shown := preferences.teaching.current) is not None:
        label = teacher.answer(shown.query)
        preferences.buttons[shown.side_of(0 if label == 1 else 1)].click()


def answer_feedback_as_scripted(feedback: FeedbackApp) -> None:
    """Answer every step of the episode by pressing +1 or -1 as notebook 01's teacher would (the coverage
    expert's move is good, any other bad)."""
    while not feedback.teaching.done:
        feedback.buttons[feedback.teaching.expert_feedback()].click()

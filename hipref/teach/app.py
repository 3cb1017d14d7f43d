"""The widgets a person teaches with in JupyterLab, and the scripted stand-in that presses them.

`PreferenceApp` shows a query's two clips side by side and looping, with buttons 'left', 'right' and
"can't tell" and the keys <- -> and down (or a, d, s) while the mouse is over it; `FeedbackApp` shows the
wiping grid with COACH's proposed move and buttons +1, 0, -1 (keys 1 or +, 0, and -). Both show a progress
bar. Every press goes to the session (`hipref.teach.preferences`, `hipref.teach.feedback`), which stores the
answer before the learner is told. `answer_as_scripted` plays the person: it presses the same buttons
(`Button.click` runs the same callbacks), so papermill and nbval execute the whole path headlessly.

A press answers the question on screen only: from a press until the next question has been on screen for
`SETTLE_SECONDS`, the buttons are disabled and say why ("preparing…"), and every press or key
that arrives meanwhile (a double click, a key held, a click queued while the kernel was busy) is ignored
and counted. Keys act only while the pointer is over the widget, which then holds the keyboard focus
(ipyevents), and the widget says whether they do. A failed write (a full disk, a file made read-only) is
shown in the widget in red, nothing is recorded and the buttons stay live for another try; the scripted
stand-in raises it.
"""

from __future__ import annotations

import html
import threading
import time
from collections.abc import Callable, Mapping
from typing import Any, ClassVar

import ipywidgets as widgets
import numpy as np
from ipyevents import Event

from hipref.experiments.domains import domain_spec
from hipref.teach.feedback import FeedbackTeaching
from hipref.teach.preferences import ANSWERS, SIDES, PreferenceTeaching
from hipref.teach.session import AnswerRefused, SessionLocked
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
SETTLE_SECONDS = 0.5
"""Seconds a new question is on screen before presses count: longer than a double click's two presses
apart, shorter than anyone judges a clip in."""
PREPARING = "preparing…"
"""What the disabled buttons say between a press and the next question (it fits a button's default width)."""
KEYS_HINT = (
    "<style>.hipref-keys-on{display:none;color:#2ca02c}.ipyevents-watched .hipref-keys-on{display:inline}"
    ".ipyevents-watched .hipref-keys-off{display:none}.hipref-keys-off{color:#888}</style>"
    "<span class='hipref-keys-on'>⌨ keys on: {keys}</span>"
    "<span class='hipref-keys-off'>⌨ keys off: point at this box to answer with {keys}</span>"
)
"""Whether the keys answer: ipyevents marks the widget `ipyevents-watched` while it holds the focus."""
QUESTIONS: dict[str, str] = {
    "wiping": "wiping the desk? <i>The gauge at each clip's right is the sponge's contact force; green: the "
    "safe band (a red bar presses too hard, an empty one does not touch).</i>",
    "pushing": "pushing the cube to its goal? <i>The strip under each clip is the cube's way: the blue "
    "square is the cube, the green mark its goal.</i>",
}
"""Per domain: the task a preference query asks about, and how to read the clips' marks
(`hipref.teach.clips`)."""
GRID_LEGEND = (
    "<span style='color:#3182bd'>■</span> wiped cell · <span style='color:#e6550d'>●</span> the sponge · "
    "<span style='color:#d62728'>➜</span> COACH's proposed move. The move is executed whatever you answer: "
    "as in COACH (Eq. 1), your feedback judges the move it makes and changes the moves it proposes next."
)
"""What the feedback grid's marks mean, and what an answer does."""


class Panel(widgets.VBox):
    """A VBox whose plain text says what it is: what a notebook viewer shows where it cannot draw the widget
    (JupyterLab 4 does not redraw a widget from the state saved in a notebook, jupyterlab/jupyterlab#15361),
    in place of ipywidgets' dump of its children."""

    def __init__(self, children: list[widgets.Widget], what: str) -> None:
        super().__init__(children)
        self.what = what

    def __repr__(self) -> str:
        return f"[{self.what}: interactive, drawn while its notebook runs; run the cells to see it]"


class AnswerPanel:
    """A question on screen, answered with buttons or keys (while the mouse is over it), each press timed."""

    KEYS: ClassVar[Mapping[str, Any]] = {}
    """Key -> the answer it gives."""
    buttons: Mapping[Any, widgets.Button]

    def _build(
        self, css_class: str, children: list[widgets.Widget], keys: str, teacher: str, what: str
    ) -> None:
        self.scripted = teacher == "scripted"
        """A person's answer times are measured; the scripted stand-in answers the moment a question is
        shown (0 s), so that its session file is the same bytes on every run."""
        self.keys_hint = widgets.HTML(KEYS_HINT.replace("{keys}", html.escape(keys)))
        self.message = widgets.HTML()
        """A failed write, in red; empty otherwise."""
        self.widget = Panel([*children, self.keys_hint, self.message], what)
        self.widget.add_class(css_class)
        self.keys = Event(source=self.widget, watched_events=["keydown"], prevent_default_action=True)
        self.keys.on_dom_event(self._on_key)
        self.waits: list[float] = []
        """Seconds from each press until the next question was on screen."""
        self.ignored = 0
        """Presses and keys ignored: while a question was being prepared or settling, or after the last."""
        self.error: Exception | None = None
        """Why the last press was not recorded (a failed write), None once one is."""
        self.settle = SETTLE_SECONDS
        self.on_finished: list[Callable[[], None]] = []
        """Called once the last question is answered (by the press that answers it)."""
        self._ready = threading.Event()
        self._labels = {key: button.description for key, button in self.buttons.items()}
        self._shown_at = time.perf_counter()
        self._show()
        self._arm()

    def _on_key(self, event: dict[str, Any]) -> None:
        value = self.KEYS.get(event.get("key", ""))
        if value is not None:
            self.press(value)

    def _set_buttons(self, live: bool) -> None:
        finished = self._finished()
        for key, button in self.buttons.items():
            button.disabled = finished or not live
            button.description = self._labels[key] if live or finished else PREPARING

    def _arm(self) -> None:
        """Take presses once the question has been on screen for `settle` seconds."""
        self._ready.clear()
        self._set_buttons(False)
        generation = self._shown_at

        def ready() -> None:
            if self._shown_at == generation:  # not a question answered meanwhile
                self._set_buttons(True)
                self._ready.set()

        if self.settle > 0:
            timer = threading.Timer(self.settle, ready)
            timer.daemon = True
            timer.start()
        else:
            ready()

    def wait_ready(self, timeout: float | None = None) -> bool:
        """Block until presses count again; False if `timeout` seconds passed first."""
        return self._ready.wait(timeout)

    def press(self, value: Any) -> None:
        """The person answers the question on screen (a button or a key). Ignored (and counted) while the
        question is not yet taking presses, and once all are answered. A failed write is shown, not raised:
        nothing is recorded and the same question takes the next press. Any other failure (the answer
        written, the learner unable to go on) is shown with the buttons left off, and raised."""
        if self._finished() or not self._ready.is_set():
            self.ignored += 1
            return
        self._ready.clear()
        self._set_buttons(False)
        pressed = time.perf_counter()
        try:
            self._answer(value, 0.0 if self.scripted else pressed - self._shown_at)
        except (OSError, SessionLocked, AnswerRefused) as error:
            self.error = error
            self.message.value = (
                "<b style='color:#d62728'>Your answer was not saved:</b> "
                f"<span style='color:#d62728'>{html.escape(str(error))}</span> Answer again to retry."
            )
            self._set_buttons(True)
            self._ready.set()
            return
        except Exception as error:  # the answer is saved, but the learner cannot go on: say so, not freeze
            self.error = error
            self.message.value = (
                "<b style='color:#d62728'>Something went wrong: please tell the experimenter.</b> Your "
                f"answers so far are saved. <span style='color:#d62728'>({html.escape(str(error))})</span>"
            )
            raise  # in the server's log
        self.error, self.message.value = None, ""
        self._show()
        self._shown_at = time.perf_counter()
        self.waits.append(self._shown_at - pressed)
        self._arm()
        if self._finished():
            for callback in self.on_finished:
                callback()

    def press_as_scripted(self, value: Any) -> None:
        """Press `value` once presses count, as the stand-in does; the failed write raised."""
        self.wait_ready()
        self.buttons[value].click()
        if self.error is not None:
            raise self.error

    def _finished(self) -> bool:
        raise NotImplementedError

    def _answer(self, value: Any, seconds: float) -> None:
        raise NotImplementedError

    def _show(self) -> None:
        raise NotImplementedError


class PreferenceApp(AnswerPanel):
    """Preference queries as two looping clips; the answer buttons, keys and progress."""

    KEYS = PREFERENCE_KEYS

    def __init__(
        self, teaching: PreferenceTeaching, *, reveal_truth: bool = False, show_estimate: bool = True
    ) -> None:
        self.teaching = teaching
        self.reveal_truth = reveal_truth
        # A participant is not shown the learner's running estimate: they would answer by the number
        # instead of judging the motion.
        self.show_estimate = show_estimate
        self.buttons = {answer: widgets.Button(description=LABELS[answer]) for answer in ANSWERS}
        for answer, button in self.buttons.items():
            button.on_click(lambda _, answer=answer: self.press(answer))
        self.clips = widgets.HBox(
            [widgets.Image(format="gif") for _ in SIDES], layout=widgets.Layout(grid_gap="8px")
        )
        self.heading = widgets.HTML()
        self.progress = widgets.IntProgress(min=0, max=teaching.config.preference_queries)
        self.status = widgets.HTML()
        buttons = widgets.HBox(list(self.buttons.values()))
        children = [self.heading, self.clips, buttons, self.progress, self.status]
        teacher = teaching.config.teacher
        self._build("hipref-preferences", children, "← → ↓", teacher, "the preference queries")

    def clear_clips(self) -> None:
        """Drop the clips from the widgets: a notebook saved with its widgets' state would keep them."""
        for image in self.clips.children:
            image.value = b""

    def _finished(self) -> bool:
        return self.teaching.current is None

    def _answer(self, value: Any, seconds: float) -> None:
        self.teaching.answer(value, seconds)

    def _show(self) -> None:
        teaching, shown = self.teaching, self.teaching.current
        planned = teaching.config.preference_queries
        self.progress.value = teaching.answered
        if shown is None:
            self.heading.value = f"<b>All {planned} preference queries answered.</b>"
            self.clips.layout.display = "none"
        elif shown.animations is None:
            self.heading.value = (
                f"<b>Query {shown.number + 1} of {planned}.</b> The clips cannot be rendered on this machine "
                "(no OpenGL; see the message above); answer only if you can judge without them."
            )
            self.clips.layout.display = "none"
        else:
            self.heading.value = (
                f"<b>Query {shown.number + 1} of {planned}:</b> in which clip is the robot better at "
                f"{QUESTIONS[teaching.config.domain]}"
            )
            for image, gif in zip(self.clips.children, shown.animations, strict=True):
                image.value = gif
            self.clips.layout.display = None
        self.status.value = self._status()

    def _status(self) -> str:
        teaching = self.teaching
        spec = domain_spec(teaching.config.domain)
        text = f"answered {teaching.answered} of {teaching.config.preference_queries}"
        if not self.show_estimate:
            return html.escape(text)
        estimate = teaching.estimate()
        text += f"; the learner's estimate of the {spec.parameter}: {estimate:.3f} {spec.unit}"
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
        legend = widgets.HTML(f"<small>{GRID_LEGEND}</small>")
        children = [self.heading, self.grid, legend, buttons, self.progress]
        self._build("hipref-feedback", children, "1, 0, −", teaching.config.teacher, "the feedback steps")

    def _finished(self) -> bool:
        return self.teaching.done

    def _answer(self, value: Any, seconds: float) -> None:
        self.teaching.answer(value, seconds)

    def _show(self) -> None:
        teaching = self.teaching
        planned = teaching.config.feedback_steps
        self.progress.value = teaching.steps
        self.grid.value = teaching.svg()
        wiped = f"{len(teaching.wiped)} of {teaching.grid.n_states} cells wiped"
        if teaching.done:
            self.heading.value = f"<b>Feedback episode over:</b> {wiped}."
        else:
            self.heading.value = (
                f"<b>Step {teaching.steps + 1} of {planned}:</b> is the red move good for wiping the desk? "
                f"({wiped})"
            )


def answer_preferences_as_scripted(preferences: PreferenceApp, noise: float, seed: int) -> None:
    """Answer every planned query by pressing the buttons as `ScriptedPreferenceTeacher` would: the side
    of the candidate closest to the truth, the other with probability `noise`."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 5]))
    teacher = ScriptedPreferenceTeacher(preferences.teaching.truth, noise, rng)
    preferences.settle = 0.0  # it presses once per query, never twice
    while (shown := preferences.teaching.current) is not None:
        label = teacher.answer(shown.query)
        preferences.press_as_scripted(shown.side_of(0 if label == 1 else 1))


def answer_feedback_as_scripted(feedback: FeedbackApp) -> None:
    """Answer every step of the episode by pressing +1 or -1 as notebook 01's teacher would (the coverage
    expert's move is good, any other bad)."""
    feedback.settle = 0.0  # it presses once per step, never twice
    while not feedback.teaching.done:
        feedback.press_as_scripted(feedback.teaching.expert_feedback())

"""Participant mode: notebook 09 as a participant meets it, served by Voila without any code.

`ParticipantApp` is one widget that leads a participant through instructions, a practice query answered
with feedback (a catch pair: which clip was run with the right parameter, and what the other one got
wrong), the preference queries of each condition (`TeachConfig.conditions`, query rules in the order
given, one session file each, catch trials mixed in as `catch_every` says) and a closing screen. Each
condition is a `PreferenceApp` on its own session, `participant_<id>_<rule>.jsonl`, whose header names
the participant and the order of the conditions; the practice answer is stored apart, in
`sessions/practice/`, out of the dataset of answers. A participant who comes back resumes where they
stopped: the practice pair, once answered, and finished conditions are skipped.

`participant_view` writes the participant's view of notebook 09, its parameters cell set for the participant
and only the cells tagged `participant` kept, which `make teach` (`hipref.teach.make_teach`) serves.
"""

from __future__ import annotations

import dataclasses
import hashlib
import html
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import ipywidgets as widgets
from IPython.display import display

from hipref.experiments.domains import domain_spec
from hipref.results import results_dir
from hipref.teach.app import Panel, PreferenceApp
from hipref.teach.config import TeachConfig
from hipref.teach.notice import FINISHED_CLASS
from hipref.teach.preferences import PreferenceTeaching
from hipref.teach.server import CULL_EVERY, CULL_SECONDS
from hipref.teach.session import SessionFile, SessionLocked, SessionUnwritable

TAG = "participant"
"""The tag of notebook 09's cells a participant's view keeps (besides the parameters cell)."""


INSTRUCTIONS = """
<h2>Teach a robot</h2>
<p>A robot arm {task}. It does not know {parameter}: it has to guess, and a wrong guess shows in its
motion. {symptom}</p>
<p>You will see two clips side by side, looping: the same robot, run with two different guesses.
Choose the clip where the robot does the task <b>better</b>: <b>◀ left</b>, <b>right ▶</b>, or
<b>can't tell ▼</b> if you cannot see a difference. Keys ← → ↓ work while the pointer is over the clips.</p>
<p>{plan}{easy}
Your answers are saved as you give them; you may close the window and come back.</p>
"""
FIRST_VISIT = "First one practice pair, and its correct answer; then {queries} pairs in {parts}."
COMING_BACK = "Welcome back: you go on where you stopped ({queries} pairs in {parts} in all)."
FINISHED = (
    "<h2>Thank you!</h2><p>All {answered} answers are saved (participant {participant}). You may close this "
    "window.</p>"
)
"""The closing screen: after the last answer, and to a participant who comes back after it."""
PREPARING = (
    "Preparing the next pair of clips: a few seconds, up to half a minute the first time the robot is set up."
)
"""What a pressed button's line says while the next screen is prepared (measured: about 12 s for the practice
pair on a server just started, 1-3 s after)."""
OPEN_ELSEWHERE = (
    "This session is open in another window or tab ({queries} pairs in {parts} in all): close that one, then "
    "press the button."
)
"""The plan the instructions give: before the practice pair, to a participant who answered it, or while
another window holds the practice (a second tab, or a window closed moments ago)."""

TASKS: dict[str, tuple[str, str, str]] = {
    "wiping": (
        "wipes a desk with a sponge",
        "the height of the desk",
        "Guessed too high, the sponge hovers above the desk and wipes nothing; guessed too low, it "
        "presses hard into the desk.",
    ),
    "pushing": (
        "pushes a cube towards a goal",
        "the mass of the cube",
        "Guessed too light, it pushes too gently and the cube stops short; guessed too heavy, it pushes too "
        "hard and the cube overshoots.",
    ),
}
"""Per domain: what the robot does, what it does not know, how a wrong guess shows."""


def participant_seed(participant: str) -> int:
    """A participant's seed: the first four bytes of the SHA-256 of their id. Each participant meets pairs,
    sides and clip layouts of their own (the same on every visit and machine), so that no order or side is
    common to every participant."""
    return int.from_bytes(hashlib.sha256(participant.encode()).digest()[:4], "big")


def condition_configs(config: TeachConfig) -> list[TeachConfig]:
    """The participant's sessions, one per condition (query rule), in the order given."""
    rules = config.conditions or (config.query_rule,)
    return [dataclasses.replace(config, query_rule=rule, teacher="person", session="") for rule in rules]


def practice_config(config: TeachConfig) -> TeachConfig:
    """The practice session: one catch pair, on a seed of its own."""
    return dataclasses.replace(
        config,
        teacher="person",
        preference_queries=1,
        catch_every=1,
        conditions=(),
        seed=config.seed + 1,
        session=f"participant_{config.participant}_practice.jsonl",
    )


def practice_path(practice: TeachConfig) -> Path:
    """The practice session's file (`practice_config`): in `sessions/practice/`, out of the dataset."""
    return results_dir() / "sessions" / "practice" / practice.session_name


class ParticipantApp:
    """Instructions, a practice query with feedback, each condition's queries, a closing screen."""

    def __init__(self, config: TeachConfig, *, render: bool = True) -> None:
        if not config.participant:
            raise ValueError("participant mode needs a participant id (TeachConfig.participant)")
        self.config = config
        self.render = render
        """Render the clips (False: the queries without their clips, for tests)."""
        self.conditions = condition_configs(config)
        self.widget = Panel([], "the participant's screens")
        self.widget.add_class("hipref-participant")
        self.apps: list[PreferenceApp] = []
        """The conditions' widgets, in the order met."""
        self.answered: dict[int, int] = {}
        """Per condition (by index) finished in this window or an earlier visit, its answers: counted once
        however often a refused button press met it again."""
        self.practice: PreferenceApp | None = None
        task, parameter, symptom = TASKS[config.domain]
        queries = sum(c.preference_queries for c in self.conditions)
        practice = practice_config(config)
        try:
            back = _practised(practice_path(practice), practice)
            plan = COMING_BACK if back else FIRST_VISIT
            if back and (answered := _answered_all(self.conditions)) is not None:
                self._thank(answered)  # a visit after the last answer
                return
        except SessionLocked:  # a window still open holds it: the start button says so again
            back, plan = True, OPEN_ELSEWHERE
        parts = "one part" if len(self.conditions) == 1 else f"{len(self.conditions)} parts"
        plan = plan.format(queries=queries, parts=parts)
        every = config.catch_every
        easy = (
            " Some pairs are easy on purpose."
            if every and any(c.preference_queries >= every for c in self.conditions)
            else ""
        )
        text = INSTRUCTIONS.format(task=task, parameter=parameter, symptom=symptom, plan=plan, easy=easy)
        self._screen(text, "Continue" if back else "Start the practice pair", self._start_practice)

    def _screen(self, text: str, button: str, then: Callable[[], None]) -> None:
        """`text` and a button that runs `then` once: pressed, it is disabled and a line says the next
        screen is being prepared (a few seconds, more on a first visit); presses queued meanwhile are
        ignored. Where the session cannot be opened, the line says why and the button can be pressed again."""
        go = widgets.Button(description=button, button_style="primary")
        go.layout.width = "auto"
        status = widgets.HTML()

        def pressed(_: widgets.Button) -> None:
            if go.disabled:
                return
            go.disabled = True
            status.value = f"<p><i>{PREPARING}</i></p>"
            try:
                then()
            except (SessionLocked, SessionUnwritable) as error:
                status.value = f"<p><b>{html.escape(_why_not(error))}</b></p>"
                go.disabled = False
            except Exception as error:
                status.value = (
                    "<p><b>Something went wrong: please tell the experimenter. Your answers so far are "
                    f"saved. ({html.escape(str(error))})</b></p>"
                )
                go.disabled = False
                raise  # shown to the experimenter in the server's log

        go.on_click(pressed)
        self.widget.children = [widgets.HTML(text), go, status]

    def _start_practice(self) -> None:
        config = practice_config(self.config)
        path = practice_path(config)
        if _practised(path, config):  # in an earlier visit
            self._start_condition(0)
            return
        session = SessionFile(path, config.header(), fresh=True)
        self.practice = PreferenceApp(
            PreferenceTeaching(config, session, render=self.render), show_estimate=False
        )
        self.practice.on_finished.append(self._practice_feedback)
        self.widget.children = [widgets.HTML("<h3>Practice pair</h3>"), self.practice.widget]

    def _practice_feedback(self) -> None:
        assert self.practice is not None
        teaching = self.practice.teaching
        teaching.close()
        teaching.session.close()
        record = teaching.session.of_kind("preference")[0]
        near, far = record["candidates"]
        good = "left" if record["shown"][0] == near else "right"
        spec = domain_spec(self.config.domain)
        wrong = {"wiping": ("too low", "too high"), "pushing": ("too light", "too heavy")}[self.config.domain]
        wrong_way = wrong[far > near]
        verdict = "Correct" if record["answer"] == good else "Not quite"
        # No value is named: a participant who knew the truth could answer by number, not by the motion.
        text = (
            f"<h3>{verdict}: the {good} clip was the better one.</h3><p>It was run with the true "
            f"{spec.parameter}; the other with a guess {wrong_way}. Look for this difference in the pairs to "
            "come.</p>"
        )
        self._screen(text, "Start", lambda: self._start_condition(0))

    def _start_condition(self, index: int) -> None:
        if index == len(self.conditions):
            self._close()
            return
        config = self.conditions[index]
        session = SessionFile(results_dir() / "sessions" / config.session_name, config.header())
        app = PreferenceApp(PreferenceTeaching(config, session, render=self.render), show_estimate=False)
        self.apps.append(app)
        part = f"<h3>Part {index + 1} of {len(self.conditions)}</h3>"
        if app.teaching.done:  # answered in an earlier visit
            self.answered[index] = app.teaching.answered
            app.teaching.close()
            app.teaching.session.close()
            self._start_condition(index + 1)
            return

        def finished() -> None:
            self.answered[index] = app.teaching.answered
            app.teaching.close()
            app.teaching.session.close()  # its lock released: a later visit may open it
            if index + 1 < len(self.conditions):
                text = f"<h3>Part {index + 1} of {len(self.conditions)} done.</h3><p>Take a short break.</p>"
                self._screen(text, "Continue", lambda: self._start_condition(index + 1))
            else:
                self._close()

        app.on_finished.append(finished)
        self.widget.children = [widgets.HTML(part), app.widget]

    def _close(self) -> None:
        self._thank(sum(self.answered.values()))

    def _thank(self, answered: int) -> None:
        text = FINISHED.format(answered=answered, participant=html.escape(self.config.participant))
        self.widget.children = [widgets.HTML(text)]
        self.widget.add_class(FINISHED_CLASS)  # the page's connection notice stays away (`notice`)


def _practised(path: Path, config: TeachConfig) -> bool:
    """Whether the practice file at `path` holds this practice's answer (a participant who came back)."""
    if not path.exists():
        return False
    try:
        session = SessionFile(path, config.header())
    except ValueError:  # a practice of other settings: practised afresh
        return False
    answered = bool(session.of_kind("preference"))
    session.close()
    return answered


def _answered_all(conditions: list[TeachConfig]) -> int | None:
    """The answers of a participant who has answered every condition's queries (their sessions opened, read
    and closed), else None; a condition not yet started is not created."""
    total = 0
    for config in conditions:
        path = results_dir() / "sessions" / config.session_name
        if not path.exists():
            return None
        try:
            session = SessionFile(path, config.header())
        except ValueError:  # another session's file: the part refuses it when started
            return None
        answered = len(session.of_kind("preference"))
        session.close()
        if answered < config.preference_queries:
            return None
        total += answered
    return total


def _why_not(error: SessionLocked | SessionUnwritable) -> str:
    """What a participant is told when a part cannot open its session file."""
    if isinstance(error, SessionLocked):
        return (
            "Your answers so far are saved, but this part is still open in an earlier window (or a second "
            "tab). Close it and press the button again; if that window closed without saying so (a crash), "
            f"the part is freed within {CULL_SECONDS + 2 * CULL_EVERY} seconds."
        )
    return f"Your answers cannot be saved: please tell the experimenter ({error})."


class ParticipantMode(Exception):
    """Notebook 09's researcher sections reached with a participant set: they are not run. Shown by IPython
    as its message alone (`_render_traceback_`), no stack: nothing went wrong, Run All just stops here."""

    def __init__(self, participant: str) -> None:
        super().__init__(
            f"participant mode (participant = {participant!r}): participant {participant}'s screens are "
            "shown above, and the researcher's sections below are not run. For the researcher's session set "
            "participant = '' (and conditions = []) and run all cells again; to serve the participant "
            f"without code run `make teach PARTICIPANT={participant}`."
        )

    def _render_traceback_(self) -> list[str]:
        return [f"\x1b[1;34mStopped here:\x1b[0m {self}"]


def participant_screen(config: TeachConfig) -> None:
    """In notebook 09: the participant's screens, shown."""
    display(ParticipantApp(config).widget)


def researcher_sections(config: TeachConfig) -> None:
    """Raise `ParticipantMode` when `config` is a participant's: notebook 09's first researcher cell calls
    it, so that Run All in JupyterLab stops with that message under the participant's screens instead of
    failing on the session the participant branch did not open (Voila's view holds no such cell)."""
    if config.participant:
        raise ParticipantMode(config.participant)


WATCH_CELL: dict[str, Any] = {
    "cell_type": "code",
    "id": "connection-watch",
    "metadata": {},
    "source": "from hipref.teach.notice import connection_watch\n\nconnection_watch()",
    "outputs": [],
    "execution_count": None,
}
"""The view's first cell: the notice a page shows when it loses its learner (`hipref.teach.notice`)."""


def participant_view(notebook: Path, parameters: dict[str, Any], out: Path) -> Path:
    """Notebook `notebook` as a participant's view: `WATCH_CELL`, then its parameters cell with `parameters`
    set and only its cells tagged `TAG`, without outputs; written to `out`."""
    content = json.loads(notebook.read_text())
    cells = [WATCH_CELL]
    for cell in content["cells"]:
        tags = cell.get("metadata", {}).get("tags", [])
        if "parameters" in tags:
            source = "".join(cell["source"]).splitlines()
            for name, value in parameters.items():
                declared = next(line for line in source if line.startswith(f"{name}:"))
                kind = declared.split(":")[1].split("=")[0].strip()
                source = [
                    f"{name}: {kind} = {value!r}" if line.startswith(f"{name}:") else line for line in source
                ]
            cell["source"] = "\n".join(source)
        elif TAG not in tags:
            continue
        cell["outputs"], cell["execution_count"] = [], None
        cells.append(cell)
    content["cells"] = cells
    content["metadata"].pop("widgets", None)
    out.write_text(json.dumps(content))
    return out

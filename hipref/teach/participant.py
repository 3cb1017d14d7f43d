"""Participant mode: notebook 09 as a participant meets it, served by Voila without any code.

`ParticipantApp` is one widget that leads a participant through instructions, a practice query answered
with feedback (a catch pair: which clip was run with the right parameter, and what the other one got
wrong), the preference queries of each condition (`TeachConfig.conditions`, query rules in the order
given, one session file each, catch trials mixed in as `catch_every` says) and a closing screen. Each
condition is a `PreferenceApp` on its own session, `participant_<id>_<rule>.jsonl`, whose header names
the participant and the order of the conditions; the practice answer is stored apart, in
`sessions/practice/`, out of the dataset of answers. A participant who comes back resumes where they
stopped: the practice pair, once answered, and finished conditions are skipped.

    python -m hipref.teach.participant ID [--conditions uniform information_gain] [--port 8866]

(`make teach PARTICIPANT=ID`) writes the participant's view of notebook 09, its parameters cell set for
the participant and only the cells tagged `participant` kept, to a temporary folder, and serves it with
Voila (code cells hidden) on http://127.0.0.1:PORT until interrupted (Ctrl-C or a kill); a port already in
use is refused. A page's kernel is shut down a minute after its window closes, so a participant who closes
the window comes back to the same server.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import fcntl
import html
import json
import os
import signal
import sys
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any, NoReturn

import ipywidgets as widgets
from IPython.display import display

from hipref.experiments.domains import domain_spec
from hipref.learners.queries import QUERY_RULES
from hipref.results import repo_root, results_dir
from hipref.teach.app import PreferenceApp
from hipref.teach.config import TeachConfig
from hipref.teach.preferences import PreferenceTeaching
from hipref.teach.server import CULL_EVERY, CULL_SECONDS, port_in_use, serve, voila_command
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
<p>{plan} Some pairs are easy on purpose.
Your answers are saved as you give them; you may close the window and come back.</p>
"""
FIRST_VISIT = "First one practice pair, and its right answer; then {queries} pairs in {parts} part(s)."
COMING_BACK = "Welcome back: you go on where you stopped ({queries} pairs in {parts} part(s) in all)."
"""The plan the instructions give: before the practice pair, or to a participant who answered it."""

TRUTH_SHARE = 0.75
"""Where a participant's world lies in the domain's range unless told (0.8 m, 17 kg): away from the middle,
the learner's first estimate, so that the session has something to teach."""

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


class ParticipantApp:
    """Instructions, a practice query with feedback, each condition's queries, a closing screen."""

    def __init__(self, config: TeachConfig, *, render: bool = True) -> None:
        if not config.participant:
            raise ValueError("participant mode needs a participant id (TeachConfig.participant)")
        self.config = config
        self.render = render
        """Render the clips (False: the queries without their clips, for tests)."""
        self.conditions = condition_configs(config)
        self.widget = widgets.VBox()
        self.widget.add_class("hipref-participant")
        self.apps: list[PreferenceApp] = []
        """The conditions' widgets, in the order met."""
        self.practice: PreferenceApp | None = None
        task, parameter, symptom = TASKS[config.domain]
        queries = sum(c.preference_queries for c in self.conditions)
        practice = practice_config(config)
        back = _practised(results_dir() / "sessions" / "practice" / practice.session_name, practice)
        plan = (COMING_BACK if back else FIRST_VISIT).format(queries=queries, parts=len(self.conditions))
        text = INSTRUCTIONS.format(task=task, parameter=parameter, symptom=symptom, plan=plan)
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
            status.value = "<p><i>Preparing the next pair of clips: this takes a few seconds.</i></p>"
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
        path = results_dir() / "sessions" / "practice" / config.session_name
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
        verdict = "Right" if record["answer"] == good else "Not quite"
        # No value is named: a participant who knew the truth could answer by number, not by the motion.
        text = (
            f"<h3>{verdict}: the {good} clip was the better one.</h3><p>It was run with the right "
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
            app.teaching.close()
            app.teaching.session.close()
            self._start_condition(index + 1)
            return

        def finished() -> None:
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
        answered = sum(app.teaching.answered for app in self.apps)
        self.widget.children = [
            widgets.HTML(
                f"<h2>Thank you!</h2><p>All {answered} answers are saved (participant "
                f"{self.config.participant}). You may close this window.</p>"
            )
        ]


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


def _why_not(error: SessionLocked | SessionUnwritable) -> str:
    """What a participant is told when a part cannot open its session file."""
    if isinstance(error, SessionLocked):
        return (
            "Your answers so far are saved, but this part is still open in an earlier window (or a second "
            f"tab). Close it and press the button again in {CULL_SECONDS + 2 * CULL_EVERY} seconds."
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


def participant_view(notebook: Path, parameters: dict[str, Any], out: Path) -> Path:
    """Notebook `notebook` as a participant's view: its parameters cell with `parameters` set, and only its
    cells tagged `TAG`, without outputs; written to `out`."""
    content = json.loads(notebook.read_text())
    cells = []
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


def main(argv: list[str] | None = None) -> None:
    formatter = argparse.RawDescriptionHelpFormatter
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=formatter)
    parser.add_argument("participant", help="the participant's id (letters, digits, - and _)")
    parser.add_argument(
        "--conditions", nargs="+", default=["uniform", "information_gain"], choices=QUERY_RULES,
        help="query rules in the order the participant meets them",
    )  # fmt: skip
    parser.add_argument("--queries", type=int, default=12, help="preference queries per condition")
    parser.add_argument("--catch-every", type=int, default=4, help="every n-th query a catch trial")
    parser.add_argument("--domain", default="wiping", choices=list(TASKS))
    parser.add_argument(
        "--true-parameter", type=float, default=None,
        help="the world's true parameter (default: three quarters up the domain's range, 0.8 m or 17 kg)",
    )  # fmt: skip
    parser.add_argument("--port", type=int, default=8866)
    args = parser.parse_args(argv)
    if not 1 <= args.port <= 65535:
        refuse(f"port must be a number from 1 to 65535, got {args.port}")
    candidates = domain_spec(args.domain).candidates
    default = round(candidates.low + TRUTH_SHARE * (candidates.high - candidates.low), 6)
    truth = default if args.true_parameter is None else args.true_parameter
    parameters = {
        "teacher": "person",
        "participant": args.participant,
        "conditions": list(args.conditions),
        "preference_queries": args.queries,
        "catch_every": args.catch_every,
        "domain": args.domain,
        "true_parameter": truth,
    }
    try:
        TeachConfig(**{**parameters, "conditions": tuple(args.conditions)})  # bad values refused here
    except ValueError as error:
        refuse(str(error))
    if port_in_use(args.port):
        refuse(
            f"port {args.port} is in use, by another `make teach` or another server: stop it, or serve "
            f"this participant on another port (--port, `make teach PORT=...`)"
        )
    root = repo_root() or Path.cwd()
    # A kill (SIGTERM) ends the server as Ctrl-C does: Voila stopped, the temporary folder removed.
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    with (
        served_once(args.participant, args.port),
        tempfile.TemporaryDirectory(prefix="hipref-participant-") as folder,
    ):
        view = participant_view(
            root / "notebooks" / "09_teach.ipynb", parameters, Path(folder) / "teach.ipynb"
        )
        print(f"participant {args.participant}: starting the server ...", flush=True)
        serve(
            voila_command(view, args.port),
            args.port,
            f"participant {args.participant}: http://127.0.0.1:{args.port}/",
        )


@contextlib.contextmanager
def served_once(participant: str, port: int) -> Iterator[None]:
    """Hold `sessions/participant_<id>.serving` (an exclusive flock, which the system drops however the server
    ends) while this server runs: a second server for the same participant is refused, naming the first."""
    path = results_dir() / "sessions" / f"participant_{participant}.serving"
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        descriptor = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError as error:
        refuse(f"cannot write the sessions folder {path.parent}: {error.strerror}")
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        first = os.pread(descriptor, 128, 0).decode(errors="replace").strip() or "by another server"
        os.close(descriptor)
        refuse(
            f"participant {participant} is served already ({first}): send them to that page, or stop it first"
        )
    os.ftruncate(descriptor, 0)
    os.pwrite(descriptor, f"at http://127.0.0.1:{port}/, pid {os.getpid()}".encode(), 0)
    try:
        yield
    finally:
        path.unlink(missing_ok=True)
        os.close(descriptor)


def refuse(reason: str) -> NoReturn:
    """One line on stderr saying why the server is not started; exit status 2, as a usage error."""
    print(f"make teach: {reason}", file=sys.stderr)
    raise SystemExit(2)


if __name__ == "__main__":
    main()

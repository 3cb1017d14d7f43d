"""`make teach`: notebook 09's participant view served by Voila, after every setting is checked.

    python -m hipref.teach.make_teach ID [--conditions uniform information_gain] [--queries 12]
        [--catch-every 4] [--domain wiping] [--true-parameter 0.8] [--port 8866]

(`make teach PARTICIPANT=ID`) writes the participant's view of notebook 09 (`participant_view`) to a
temporary folder and serves it with Voila (code cells hidden) on http://127.0.0.1:PORT until interrupted
(Ctrl-C or a kill), printing the address once Voila listens. Refused in one line, before anything is served:
a bad value, a port in use or out of range, a second server for a participant already served, a participant
whose session files were started with other settings (their answers would be set aside), and a machine that
cannot render the clips. A page's kernel is shut down a minute after its window closes, so a participant who
closes the window comes back to the same server.
"""

from __future__ import annotations

import argparse
import contextlib
import fcntl
import os
import shutil
import signal
import socket
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any, NoReturn

from hipref.experiments.domains import domain_spec
from hipref.learners.queries import QUERY_RULES
from hipref.results import repo_root, results_dir
from hipref.sim.render import why_no_gl
from hipref.teach.config import TeachConfig
from hipref.teach.participant import (
    TASKS,
    condition_configs,
    participant_seed,
    participant_view,
    practice_config,
    practice_path,
)
from hipref.teach.server import end_with_parent, port_in_use, serve, voila_command
from hipref.teach.session import OtherSession, SessionFile, SessionLocked

TRUTH_SHARE = 0.75
"""Where a participant's world lies in the domain's range unless told (0.8 m, 17 kg): away from the middle,
the learner's first estimate, so that the session has something to teach."""


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:  # a malformed value: one line, as every refusal
        refuse(named(message))


def main(argv: list[str] | None = None) -> None:
    """`make teach`: check every setting, then serve the participant's view until interrupted."""
    parser = _Parser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
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
        refuse(f"PORT (--port) must be a number from 1 to 65535, got {args.port}")
    candidates = domain_spec(args.domain).candidates
    default = round(candidates.low + TRUTH_SHARE * (candidates.high - candidates.low), 6)
    truth = default if args.true_parameter is None else args.true_parameter
    parameters = {
        "teacher": "person",
        "participant": args.participant,
        "seed": participant_seed(args.participant),
        "conditions": list(args.conditions),
        "preference_queries": args.queries,
        "catch_every": args.catch_every,
        "domain": args.domain,
        "true_parameter": truth,
    }
    try:  # bad values are refused here
        config = TeachConfig(**{**parameters, "conditions": tuple(args.conditions)})
    except ValueError as error:
        refuse(named(str(error)))
    if port_in_use(args.port):
        refuse(
            f"port {args.port} is in use, by another `make teach` or another server: stop it, or serve "
            f"this participant on another port (--port, `make teach PORT=...`)"
        )
    unavailable = why_no_gl()
    if unavailable is not None:
        refuse(
            f"clips cannot be rendered here ({unavailable}), and a participant judges the clips: serve "
            "from a machine with GL (the README's EGL packages)"
        )
    # Voila starts each kernel in the view's temporary folder: a relative results folder would be read
    # there, and its answers deleted with it.
    os.environ["HIPREF_RESULTS_DIR"] = str(results_dir().resolve())
    root = repo_root() or Path.cwd()
    remove_stale_views(Path(tempfile.gettempdir()))
    # A kill (SIGTERM) ends the server as Ctrl-C does: Voila stopped, the temporary folder removed.
    signal.signal(signal.SIGTERM, signal.default_int_handler)
    with (
        served_once(args.participant, args.port),
        tempfile.TemporaryDirectory(prefix=f"{VIEW_FOLDER}{os.getpid()}-") as folder,
    ):
        check_sessions(config)
        view = participant_view(
            root / "notebooks" / "09_teach.ipynb", parameters, Path(folder) / "teach.ipynb"
        )
        spec = domain_spec(args.domain)
        catches = f"a catch trial every {args.catch_every}" if args.catch_every else "no catch trials"
        print(
            f"participant {args.participant}: {args.domain}, true {spec.parameter} {truth:g} {spec.unit}, "
            f"{args.queries} queries in each of {len(args.conditions)} part(s) "
            f"({', '.join(args.conditions)}), {catches}: starting the server",
            flush=True,
        )
        # `make teach` execs this process: killed (SIGTERM, SIGKILL), make takes it along, and it Voila.
        end_with_parent(os.getppid())
        serve(
            voila_command(view, args.port),
            args.port,
            f"participant {args.participant}: http://127.0.0.1:{args.port}/",
        )


VIEW_FOLDER = "hipref-participant-"
"""The served view's temporary folder: VIEW_FOLDER, the serving process's pid, '-' and a random part."""


def remove_stale_views(folder: Path) -> None:
    """Remove the view folders in `folder` whose serving process is gone: one killed outright (SIGKILL) could
    not remove its own. A folder whose pid is alive, or not this user's to remove, is left."""
    for view in folder.glob(f"{VIEW_FOLDER}*-*"):
        pid = view.name[len(VIEW_FOLDER) :].split("-", 1)[0]
        if not pid.isdigit() or pid_alive(int(pid)):
            continue
        shutil.rmtree(view, ignore_errors=True)


def pid_alive(pid: int) -> bool:
    """Whether a process `pid` exists (one of another user's counts: signalling it is refused)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    return True


def check_sessions(config: TeachConfig) -> None:
    """Refuse a participant whose practice or condition files were started with other settings: served
    anyway, the practice answer would be replaced and the first part refused after it. The refusal names
    every setting that differs in any of the files, and the files."""
    practice = practice_config(config)
    files = [(practice_path(practice), practice)]
    files += [(results_dir() / "sessions" / c.session_name, c) for c in condition_configs(config)]
    differ: list[str] = []
    where: list[str] = []
    for path, session_config in files:
        if not path.exists():
            continue
        try:
            SessionFile(path, session_config.header()).close()
        except SessionLocked as error:
            refuse(f"participant {config.participant}'s session is open elsewhere: {error}")
        except OSError as error:  # SessionUnwritable among them
            refuse(f"participant {config.participant}'s session cannot be opened: {error}")
        except ValueError as error:  # OtherSession among them
            differ += [
                d for d in earlier_settings(error, session_config.header()) or [str(error)] if d not in differ
            ]
            where.append(str(path.relative_to(results_dir()) if path.is_relative_to(results_dir()) else path))
    if differ:
        refuse(
            f"participant {config.participant} was served before with other settings ({', '.join(differ)}; "
            f"{', '.join(where)}): serve them with those, or give this session another id"
        )


MAKE_SETTINGS = {
    "participant": "PARTICIPANT",
    "domain": "DOMAIN",
    "true_parameter": "TRUE_PARAMETER",
    "preference_queries": "QUERIES",
    "catch_every": "CATCH_EVERY",
    "conditions": "CONDITIONS",
}
"""The session header's fields a researcher sets on `make teach`'s command line, by their names there."""

OPTIONS = {
    "--conditions": "CONDITIONS",
    "--queries": "QUERIES",
    "--catch-every": "CATCH_EVERY",
    "--domain": "DOMAIN",
    "--true-parameter": "TRUE_PARAMETER",
    "--port": "PORT",
}
"""This command's options, by the `make teach` settings that give them."""


def named(message: str) -> str:
    """A refusal naming an option ('argument --queries: ...') or a session field ('preference_queries
    must ...') with the `make teach` setting too: 'QUERIES (--queries): ...', 'QUERIES (preference_queries)
    must ...'."""
    for option, setting in OPTIONS.items():
        message = message.replace(f"argument {option}:", f"{setting} ({option}):")
    for field, setting in MAKE_SETTINGS.items():
        if message.startswith(f"{field} "):
            return f"{setting} ({field}){message[len(field) :]}"
    return message


def earlier_settings(error: ValueError, header: dict[str, Any]) -> list[str]:
    """What a session file refused as `OtherSession` was started with where it differs from `header`, as
    `make teach`'s settings ('DOMAIN=pushing then, wiping now'); empty for another refusal, or when only the
    file's format differs."""
    if not isinstance(error, OtherSession):
        return []

    def shown(value: Any) -> str:
        return " ".join(map(str, value)) if isinstance(value, list) else str(value)

    return [
        f"{MAKE_SETTINGS.get(k, k)}={shown(error.stored.get(k))} then, {shown(header.get(k))} now"
        for k in error.differ
        if k != "format"
    ]


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
    except OSError as error:  # a folder whose file system cannot lock
        os.close(descriptor)
        refuse(f"cannot lock {path}: {error.strerror}")
    os.ftruncate(descriptor, 0)
    os.pwrite(
        descriptor, f"at http://127.0.0.1:{port}/ on {socket.gethostname()}, pid {os.getpid()}".encode(), 0
    )
    try:
        yield
    finally:  # emptied, not removed: a server waiting on this file must not lock one no longer there
        os.ftruncate(descriptor, 0)
        os.close(descriptor)


def refuse(reason: str) -> NoReturn:
    """One line on stderr saying why the server is not started; exit status 2, as a usage error."""
    print(f"make teach: {reason}", file=sys.stderr)
    raise SystemExit(2)


if __name__ == "__main__":
    main()

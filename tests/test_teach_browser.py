"""Notebook 09 in JupyterLab in a real headless browser: a person's clicks and keys reach the session file; a
killed kernel resumes where the person stopped; a read-only session file and a second kernel on the same file
are refused with a message before any clip plays; a finished session reopens on its summary. In Voila, a
participant answers without seeing code, and the page says when its kernel dies or the server stops.

Needs Debian's `chromium` (`.ci/run` installs it) and Playwright's Python client (environment.txt); where
either is missing the test is skipped with the reason, never passed. The screenshot of the notebook it takes
is the README's (`results_dir()/figures/09_teach_browser.png`).
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.request
from collections.abc import Iterator
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
PERSON = {
    "teacher": "person",
    "preference_queries": 3,
    "feedback_steps": 2,
    "n_trajectories": 8,
    "pretrain_steps": 20,
    "session": "browser.jsonl",
}
"""A person's short session on a small SI model (the parameters cell is rewritten with these)."""

try:
    from playwright.sync_api import Page, sync_playwright
except ImportError:  # pragma: no cover - environment.txt installs it
    sync_playwright = None


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def person_notebook(directory: Path) -> Path:
    """Notebook 09 with the parameters cell set for `PERSON` and papermill's injected cell removed."""
    notebook = json.loads((ROOT / "notebooks" / "09_teach.ipynb").read_text())
    cells = []
    for cell in notebook["cells"]:
        tags = cell.get("metadata", {}).get("tags", [])
        if "injected-parameters" in tags:
            continue
        if "parameters" in tags:
            lines = []
            for line in "".join(cell["source"]).splitlines():
                name = line.split(":")[0]
                if name in PERSON:
                    kind = line.split(":")[1].split("=")[0].strip()
                    line = f"{name}: {kind} = {json.dumps(PERSON[name])}"
                lines.append(line)
            cell["source"] = "\n".join(lines)
        cell["outputs"] = [] if cell["cell_type"] == "code" else cell.get("outputs")
        if cell["cell_type"] != "code":
            cell.pop("outputs", None)
        cells.append(cell)
    notebook["cells"] = cells
    notebook["metadata"].pop("widgets", None)
    path = directory / "09_teach.ipynb"
    path.write_text(json.dumps(notebook))
    return path


@contextlib.contextmanager
def serving(command: list[str], port: int, env: dict[str, str]) -> Iterator[subprocess.Popen[bytes]]:
    """A server started by `command`, once it listens on `port`; stopped afterwards (if not already)."""
    server = subprocess.Popen(command, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            with socket.socket() as s:
                if s.connect_ex(("127.0.0.1", port)) == 0:
                    break
            time.sleep(0.3)
        else:
            pytest.fail(f"{command[2]} did not start within 120 s")
        yield server
    finally:
        server.terminate()
        try:
            server.wait(timeout=20)
        except subprocess.TimeoutExpired:
            server.kill()


def browser_available() -> None:
    if CHROMIUM is None or sync_playwright is None:
        pytest.skip("no browser: Debian's chromium or Playwright's Python client is not installed")


LAB_SETTINGS = {
    # Every cell attached to the page: JupyterLab's default ("contentVisibility") skips rendering the cells
    # out of view, and the browser then counts a query scrolled out of view as hidden.
    "@jupyterlab/notebook-extension/tracker": {"windowingMode": "none"},
    "@jupyterlab/apputils-extension/notification": {"fetchNews": "false"},
}


def lab_settings(directory: Path) -> dict[str, str]:
    """JupyterLab's user settings and workspaces in `directory`: each test's server starts from
    `LAB_SETTINGS` and no layout of an earlier run (which would reopen its tabs and their kernels)."""
    for plugin, values in LAB_SETTINGS.items():
        path = directory / "settings" / f"{plugin}.jupyterlab-settings"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(json.dumps(values))
    return {
        "JUPYTERLAB_SETTINGS_DIR": str(directory / "settings"),
        "JUPYTERLAB_WORKSPACES_DIR": str(directory / "workspaces"),
    }


@pytest.fixture
def lab(tmp_path: Path) -> Iterator[tuple[str, Path]]:
    """A JupyterLab server on loopback over a folder with the person's notebook; (url, results dir)."""
    browser_available()
    notebook = person_notebook(tmp_path)
    shutil.copy(notebook, tmp_path / "09_teach_second.ipynb")  # the same session from another kernel
    port, token = free_port(), "hipref-test"
    results = tmp_path / "results"
    env = {
        **os.environ, "HIPREF_RESULTS_DIR": str(results), "HIPREF_CACHE_DIR": str(tmp_path / "cache"),
        **lab_settings(tmp_path / "lab"),
    }  # fmt: skip
    command = [
        sys.executable, "-m", "jupyterlab", "--no-browser", f"--port={port}", "--ip=127.0.0.1",
        f"--ServerApp.token={token}", f"--ServerApp.root_dir={tmp_path}", "--allow-root",
        "--LabApp.news_url=", "--LabApp.check_for_updates_class=jupyterlab.NeverCheckForUpdate",
    ]  # fmt: skip
    with serving(command, port, env):
        yield f"http://127.0.0.1:{port}/lab/tree/09_teach.ipynb?token={token}", results


def run_all(page: Page) -> None:
    """Run > Run All Cells once the notebook's kernel is idle."""
    try:
        page.get_by_text("Python (hipref) | Idle").wait_for(timeout=120_000)
    except Exception:  # what the page showed instead
        page.screenshot(path=str(Path(tempfile.gettempdir()) / "hipref_run_all_failed.png"))
        raise
    page.get_by_role("menuitem", name="Run", exact=True).click()
    page.get_by_role("menuitem", name="Run All Cells", exact=True).click()


def shown(page: Page, text: str, timeout: float) -> None:
    """Wait until `text` is visible in the preference widget; when it is not, fail with what the notebook
    showed instead (its outputs' text, and a screenshot in the temporary directory)."""
    try:
        page.locator(".hipref-preferences").get_by_text(text).wait_for(timeout=timeout)
    except Exception:
        shot = Path(tempfile.gettempdir()) / "hipref_browser_failed.png"
        page.screenshot(path=str(shot), full_page=True)
        outputs = "\n".join(page.locator(".jp-OutputArea-output").all_inner_texts())
        status = page.locator(".jp-StatusBar-Widget").all_inner_texts()
        pytest.fail(
            f"{text!r} not shown within {timeout / 1000:.0f} s; status bar {status}; outputs:\n"
            f"{outputs[-3000:]}\n(screenshot: {shot})"
        )


def answers(results: Path) -> list[dict]:
    path = results / "sessions" / PERSON["session"]
    return [json.loads(line) for line in path.read_text().splitlines()[1:]] if path.exists() else []


def wait_answers(results: Path, count: int, timeout: float = 60) -> list[dict]:
    deadline = time.monotonic() + timeout
    while len(found := answers(results)) < count and time.monotonic() < deadline:
        time.sleep(0.2)
    return found


FLAGS = ["--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync"]  # fmt: skip


def session_lines(results: Path) -> list[tuple]:
    """The session file line by line: its header's format, then each answer's kind, query and answer."""
    header, *stored = (results / "sessions" / PERSON["session"]).read_text().splitlines()
    assert json.loads(header)["format"] == "hipref-teaching-session/1"
    kinds = {"preference": ("query", "answer"), "feedback": ("step", "feedback")}
    return [(a["kind"], *(a[field] for field in kinds[a["kind"]])) for a in map(json.loads, stored)]


def kernel_pid(results: Path) -> int:
    """The pid of the kernel holding the session's lock (`hipref.teach.session` writes it there)."""
    holder = (results / "sessions" / (PERSON["session"] + ".lock")).read_text()
    return int(holder.split()[1])


def kernel_processes(kernel_id: str) -> list[int]:
    """The pids of the processes of JupyterLab's kernel `kernel_id` (named by its connection file)."""
    found = []
    for proc in Path("/proc").iterdir():
        with contextlib.suppress(OSError):
            if proc.name.isdigit() and f"kernel-{kernel_id}.json".encode() in (proc / "cmdline").read_bytes():
                found.append(int(proc.name))
    return found


def kill_kernel(results: Path, url: str) -> None:
    """SIGKILL the kernel writing the session (the lock is freed), then wait until JupyterLab's server has
    started a new process for the notebook's kernel: its own restart, or one asked of its REST API when that
    gave up. The server's `execution_state` is not waited for: with no browser connected it may stay
    "starting" after the restarted kernel is idle; the next page waits for the kernel itself (`run_all`)."""
    pid = kernel_pid(results)
    os.kill(pid, signal.SIGKILL)
    server, token = url.split("/lab/")[0], "?token=" + url.split("token=")[1]
    deadline = time.monotonic() + 240
    asked = False
    while time.monotonic() < deadline:
        time.sleep(1)
        with urllib.request.urlopen(f"{server}/api/sessions{token}") as response:
            # The server may hold other kernels (e.g. one JupyterLab started on its own); the notebook's
            # session names the one that matters.
            kernels = [s["kernel"] for s in json.load(response) if s["path"] == "09_teach.ipynb"]
        if not kernels:
            continue
        (kernel,) = kernels
        alive = [p for p in kernel_processes(kernel["id"]) if p != pid]
        if alive and kernel["execution_state"] not in ("dead", "restarting", "autorestarting"):
            return
        if kernel["execution_state"] == "dead" and not asked:
            request = urllib.request.Request(
                f"{server}/api/kernels/{kernel['id']}/restart{token}", method="POST"
            )
            urllib.request.urlopen(request).close()
            asked = True
    pytest.fail("JupyterLab's server had no live kernel for the notebook 240 s after the kill")


@contextlib.contextmanager
def read_only(path: Path) -> Iterator[None]:
    """`path` made read-only for whoever runs the test: mode 0444, and immutable (chattr +i) for root, who
    writes through file modes. Skips where neither holds."""
    path.chmod(0o444)
    immutable = os.geteuid() == 0
    if immutable and subprocess.run(["chattr", "+i", str(path)], capture_output=True).returncode != 0:
        path.chmod(0o644)
        pytest.skip("cannot make a file read-only for root here (chattr +i refused)")
    try:
        yield
    finally:
        if immutable:
            subprocess.run(["chattr", "-i", str(path)], check=True)
        path.chmod(0o644)


@pytest.mark.slow
def test_a_person_teaches_through_kills_refusals_and_reopening(lab):
    """One JupyterLab server through a person's session: a double click and a key; the browser closed and
    the kernel killed mid-session; the session file made read-only (refused before a clip plays); the
    session resumed in the new kernel and finished; the finished session run again (the summary shown); a
    second kernel on the same file (refused, naming the first). The file is checked after each."""
    url, results = lab
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=FLAGS)
        page = browser.new_page(viewport={"width": 1100, "height": 1400})
        page.goto(url)
        run_all(page)
        shown(page, "Query 1 of 3", timeout=240_000)
        preferences = page.locator(".hipref-preferences")
        preferences.get_by_role("button", name="◀ left").dblclick()  # a double click answers one query
        preferences.get_by_text("Query 2 of 3").wait_for(timeout=60_000)
        preferences.get_by_role("button", name="◀ left").wait_for(timeout=60_000)  # live again
        assert session_lines(results) == [("preference", 0, "left")]
        page.mouse.move(0, 0)
        assert preferences.locator(".hipref-keys-off").is_visible()  # the widget says the keys are off
        preferences.hover()
        assert preferences.locator(".hipref-keys-on").is_visible()
        page.keyboard.press("ArrowRight")  # the hotkey, with the mouse over the clips
        preferences.get_by_text("Query 3 of 3").wait_for(timeout=60_000)
        wait_answers(results, 2)
        assert session_lines(results) == [("preference", 0, "left"), ("preference", 1, "right")]
        feedback = page.locator(".hipref-feedback")
        feedback.get_by_role("button", name="+1 good").click()
        feedback.get_by_text("Step 2 of 2").wait_for(timeout=60_000)
        page.locator(".hipref-preferences img").first.scroll_into_view_if_needed()
        shot = results / "figures" / "09_teach_browser.png"
        shot.parent.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(shot), full_page=False)
        browser.close()  # the person closes the browser mid-session, and the kernel dies
        kill_kernel(results, url)
        answered = [("preference", 0, "left"), ("preference", 1, "right"), ("feedback", 0, 1)]
        assert session_lines(results) == answered

        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=FLAGS)
        page = browser.new_page(viewport={"width": 1100, "height": 1400})
        page.goto(url)
        session = results / "sessions" / PERSON["session"]
        with read_only(session):
            run_all(page)  # the person is told the answers cannot be saved, before any clip is shown
            page.get_by_text("cannot be written").first.wait_for(timeout=120_000)
            assert page.locator(".hipref-preferences").count() == 0
        assert session_lines(results) == answered
        run_all(page)  # writable again: the session resumes where the killed kernel stopped
        shown(page, "Query 3 of 3", timeout=240_000)
        preferences = page.locator(".hipref-preferences")
        preferences.get_by_role("button", name="can't tell ▼").click()
        preferences.get_by_text("All 3 preference queries answered").wait_for(timeout=60_000)
        feedback = page.locator(".hipref-feedback")
        feedback.get_by_role("button", name="−1 bad").wait_for(timeout=60_000)
        feedback.hover()
        page.keyboard.press("-")
        feedback.get_by_text("Feedback episode over").wait_for(timeout=60_000)
        wait_answers(results, 5)
        finished = [*answered[:2], ("feedback", 0, 1), ("preference", 2, "cant_tell"), ("feedback", 1, -1)]
        assert session_lines(results) == finished
        run_all(page)  # the finished session reopened: the summary, no query
        page.get_by_text("3 answers, 1 can't tell").wait_for(timeout=240_000)
        done = page.locator(".hipref-preferences").get_by_text("All 3 preference queries answered")
        assert done.is_visible()
        assert page.locator(".hipref-feedback").get_by_text("Feedback episode over").is_visible()
        holder = kernel_pid(results)

        second = browser.new_page(viewport={"width": 1100, "height": 1400})
        second.goto(url.replace("09_teach.ipynb?", "09_teach_second.ipynb?reset&"))
        run_all(second)  # a second kernel on the same session file is refused, naming the first
        refusal = second.locator(".jp-OutputArea-output", has_text="is open in another live session").first
        refusal.wait_for(timeout=120_000)
        assert f"pid {holder} on host" in refusal.inner_text()
        assert second.locator(".hipref-preferences").count() == 0
        browser.close()
    assert session_lines(results) == finished
    assert shot.stat().st_size > 10_000


PARTICIPANT = {
    "teacher": "person",
    "participant": "P7",
    "conditions": ["uniform"],
    "preference_queries": 2,
    "catch_every": 2,
    "n_trajectories": 8,
    "pretrain_steps": 20,
}
"""A participant's short session (one condition, two queries, the second a catch trial), small SI model."""


@pytest.mark.slow
def test_a_participant_answers_in_voila_without_seeing_code(tmp_path):
    browser_available()
    from hipref.teach.notice import KERNEL_GONE, NOTICE_CLASS, SERVER_STOPPED
    from hipref.teach.participant import participant_view
    from hipref.teach.server import voila_command

    view = participant_view(ROOT / "notebooks" / "09_teach.ipynb", PARTICIPANT, tmp_path / "teach.ipynb")
    port, results = free_port(), tmp_path / "results"
    env = {**os.environ, "HIPREF_RESULTS_DIR": str(results), "HIPREF_CACHE_DIR": str(tmp_path / "cache")}
    flags = ["--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking"]
    with serving(voila_command(view, port), port, env) as server, sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=flags)
        page = browser.new_page(viewport={"width": 1100, "height": 1200})
        page.goto(f"http://127.0.0.1:{port}/", timeout=240_000)  # Voila runs the cells before serving
        screen = page.locator(".hipref-participant")
        screen.get_by_text("Teach a robot").wait_for(timeout=120_000)
        # A second window left on the instructions (it holds no session file) sees the server stop at the end.
        waiting = browser.new_page(viewport={"width": 1100, "height": 800})
        waiting.goto(f"http://127.0.0.1:{port}/", timeout=240_000)
        waiting.locator(".hipref-participant").get_by_text("Teach a robot").wait_for(timeout=120_000)
        screen.get_by_role("button", name="Start the practice pair").click()
        screen.get_by_text("Query 1 of 1").wait_for(timeout=240_000)
        # Reloaded before any answer: the closed page's kernel is shut down at once, so the practice file it
        # held is free, and the participant starts afresh rather than wait for the cull.
        page.reload(timeout=240_000)
        screen.get_by_role("button", name="Start the practice pair").click(timeout=120_000)
        screen.get_by_text("Query 1 of 1").wait_for(timeout=60_000)
        screen.get_by_role("button", name="◀ left").click()
        screen.get_by_text("clip was the better one").wait_for(timeout=60_000)
        screen.get_by_role("button", name="Start", exact=True).click()
        screen.get_by_text("Query 1 of 2").wait_for(timeout=120_000)
        screen.get_by_role("button", name="right ▶").click()
        screen.get_by_text("Query 2 of 2").wait_for(timeout=120_000)
        # Not a line of code on the page: no input area, no editor, no cell prompt.
        assert (
            page.locator(".jp-InputArea, .jp-Editor, .cm-editor, .CodeMirror, .jp-InputPrompt").count() == 0
        )
        assert "participant_screen" not in page.content()
        notice = page.locator(f".{NOTICE_CLASS}")
        assert notice.is_hidden()
        # The page's kernel dies mid-part: the page says so, rather than keep buttons that reach nothing.
        config = page.evaluate("document.getElementById('jupyter-config-data').textContent")
        kernel_id = json.loads(config)["kernelId"]
        for pid in kernel_processes(kernel_id):
            os.kill(pid, signal.SIGKILL)
        notice.get_by_text(KERNEL_GONE).wait_for(timeout=30_000)
        # Reloaded, it goes on where it stopped: the second query, then the closing screen with its count.
        page.reload(timeout=240_000)
        screen.get_by_text("Welcome back").wait_for(timeout=240_000)
        screen.get_by_role("button", name="Continue").click()
        screen.get_by_text("Query 2 of 2").wait_for(timeout=120_000)
        screen.get_by_role("button", name="right ▶").click()
        screen.get_by_text("All 2 answers are saved").wait_for(timeout=60_000)
        # Reloaded after the last answer: the closing screen again, not a welcome back to nothing left.
        page.reload(timeout=240_000)
        screen.get_by_text("All 2 answers are saved").wait_for(timeout=240_000)
        assert screen.get_by_text("Welcome back").count() == 0
        assert notice.is_hidden()
        # The experimenter stops the server: the waiting window says so; the finished one keeps its thanks.
        server.terminate()
        waiting.locator(f".{NOTICE_CLASS}").get_by_text(SERVER_STOPPED).wait_for(timeout=30_000)
        page.wait_for_timeout(2_000)  # past the finished page's next poll, had it kept asking
        assert notice.is_hidden() and screen.get_by_text("All 2 answers are saved").is_visible()
        browser.close()
    sessions = results / "sessions"
    header, *stored = [
        json.loads(line) for line in (sessions / "participant_P7_uniform.jsonl").read_text().splitlines()
    ]
    assert header["participant"] == "P7" and header["query_rule"] == "uniform"
    assert [(a["query"], a["answer"], a["catch"]) for a in stored] == [
        (0, "right", False),
        (1, "right", True),
    ]
    practice = (sessions / "practice" / "participant_P7_practice.jsonl").read_text().splitlines()
    assert json.loads(practice[1])["answer"] == "left"

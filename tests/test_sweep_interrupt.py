"""A local sweep leaves nothing running: not when its process is killed outright (a notebook kernel killed
with SIGKILL), nor when it is interrupted (the kernel's interrupt, SIGINT to that process alone)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import psutil
import pytest

from tests._sweep_cells import STUCK_WORKERS, executing_pids

REPO = Path(__file__).resolve().parent.parent

STARTUP_LIMIT = 180.0
"""Seconds the stuck sweep may take to start its workers on a busy machine before the test gives up."""
PARENT_DEATH_GRACE = 5.0
"""Seconds a worker may outlive the sweep's process after that process is killed."""
INTERRUPT_GRACE = 30.0
"""Seconds an interrupted sweep may take to stop its cells, shut its pool down and exit (the cells would
need ten minutes)."""


def _alive(process: psutil.Process) -> bool:
    """Running, and not a zombie (an orphan's exit status may wait for an init that never reaps it)."""
    try:
        return process.is_running() and process.status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False


def _survivors(processes: list[psutil.Process], grace: float) -> list[psutil.Process]:
    """The processes still alive after up to `grace` seconds of waiting for all of them to end."""
    deadline = time.monotonic() + grace
    alive = [p for p in processes if _alive(p)]
    while alive and time.monotonic() < deadline:
        time.sleep(0.05)
        alive = [p for p in alive if _alive(p)]
    return alive


@pytest.fixture
def stuck_sweep(tmp_path: Path) -> Iterator[tuple[subprocess.Popen[bytes], list[psutil.Process], Path]]:
    """A sweep of ten-minute cells in a child process, once all its workers run a cell: the process, every
    process it started (workers and multiprocessing's resource tracker) and its stderr's file. Whatever
    the test leaves alive is killed afterwards."""
    log_dir = tmp_path / "log"
    log_dir.mkdir()
    stderr = tmp_path / "stderr.txt"
    with stderr.open("wb") as sink:
        # SIGINT's default action in the child, as in a notebook kernel: a process that ignores SIGINT (a
        # pytest-xdist worker may) passes that on to its children, and the interrupt would never arrive.
        sweep = subprocess.Popen(
            [sys.executable, "-m", "tests._sweep_cells", "--stuck", str(log_dir)],
            cwd=REPO,
            stderr=sink,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
        )
    descendants: list[psutil.Process] = []
    try:
        deadline = time.monotonic() + STARTUP_LIMIT
        while len(executing_pids(log_dir)) < STUCK_WORKERS and sweep.poll() is None:
            assert time.monotonic() < deadline, f"the workers did not start:\n{stderr.read_text()}"
            time.sleep(0.05)
        assert sweep.poll() is None, f"the sweep ended early:\n{stderr.read_text()}"
        descendants = psutil.Process(sweep.pid).children(recursive=True)
        assert executing_pids(log_dir) <= {p.pid for p in descendants}
        yield sweep, descendants, stderr
    finally:
        if sweep.poll() is None:
            sweep.kill()
        sweep.wait()
        for process in descendants:
            if _alive(process):
                process.kill()


def test_workers_end_within_seconds_of_their_killed_parent(
    stuck_sweep: tuple[subprocess.Popen[bytes], list[psutil.Process], Path],
) -> None:
    sweep, descendants, _ = stuck_sweep
    os.kill(sweep.pid, signal.SIGKILL)
    sweep.wait()
    survivors = _survivors(descendants, PARENT_DEATH_GRACE)
    assert not survivors, f"still running {PARENT_DEATH_GRACE} s after the sweep was killed: {survivors}"


def test_an_interrupted_sweep_stops_its_running_cells_and_exits(
    stuck_sweep: tuple[subprocess.Popen[bytes], list[psutil.Process], Path],
) -> None:
    sweep, descendants, stderr = stuck_sweep
    os.kill(sweep.pid, signal.SIGINT)
    try:
        sweep.wait(timeout=INTERRUPT_GRACE)
    except subprocess.TimeoutExpired:
        pytest.fail(f"the interrupted sweep still runs after {INTERRUPT_GRACE} s, waiting for its cells")
    assert "KeyboardInterrupt" in stderr.read_text(), "the interrupt reached the caller"
    survivors = _survivors(descendants, PARENT_DEATH_GRACE)
    assert not survivors, f"still running after the interrupted sweep exited: {survivors}"

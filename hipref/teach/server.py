"""How `make teach` serves a participant's view of notebook 09: Voila on loopback, code hidden, the kernels
of closed pages shut down, and no server left running once the command ends, however it ends."""

from __future__ import annotations

import ctypes
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

CULL_SECONDS, CULL_EVERY = 60, 15
"""A page's kernel is shut down once no window has shown it for CULL_SECONDS (checked every CULL_EVERY s),
which releases its session files: a participant who closed the window can come back without restarting
the server. Voila leaves a closed page's kernel running otherwise."""


def voila_command(view: Path, port: int) -> list[str]:
    """Voila serving the participant's `view` on loopback at `port` (and no other port), its code cells
    hidden, the kernels of closed pages shut down (CULL_SECONDS), and a kernel that dies removed rather than
    restarted: a restarted kernel has none of the page's widgets, so its page could only pretend to work;
    removed, the page says so (`hipref.teach.notice`). A page closed or reloaded shuts its kernel down at
    once, releasing its session files: Voila's page asks so without the cross-site token its server wants,
    which the server is told not to check (it listens on loopback only)."""
    return [
        sys.executable, "-m", "voila", str(view), "--no-browser", f"--port={port}", "--Voila.ip=127.0.0.1",
        "--Voila.port_retries=0", "--strip_sources=True", "--show_tracebacks=True",
        f"--MappingKernelManager.cull_idle_timeout={CULL_SECONDS}",
        f"--MappingKernelManager.cull_interval={CULL_EVERY}", "--KernelRestarter.restart_limit=0",
        "--Voila.tornado_settings", "disable_check_xsrf=True",
    ]  # fmt: skip


def port_in_use(port: int) -> bool:
    """Whether something already listens on 127.0.0.1:`port`."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as probe:
        return probe.connect_ex(("127.0.0.1", port)) == 0


PR_SET_PDEATHSIG = 1
"""Linux's prctl option: the signal a process gets when its parent dies."""


def end_with_parent(parent: int) -> None:
    """Ask Linux to send this process SIGTERM when its parent (pid `parent`) dies, however it dies; exit at
    once if it has died already. Elsewhere, nothing."""
    if not sys.platform.startswith("linux"):
        return
    if ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM) != 0:
        raise OSError(ctypes.get_errno(), "prctl(PR_SET_PDEATHSIG) failed")
    if os.getppid() != parent:  # the parent died before the request: nobody to wait for
        os._exit(1)


def serve(command: list[str], port: int, ready: str, grace: float = 10.0) -> None:
    """Run the server until it ends or this process is interrupted (Ctrl-C, a kill), printing `ready` once
    it listens on `port` (not before: a page opened earlier would be refused); interrupted, the server is
    asked to stop (SIGTERM: it shuts its kernels down and removes its files) and killed after `grace`
    seconds if it has not. On Linux the server also gets SIGTERM when this process dies without a word
    (SIGKILL, out of memory), so it never outlives it. A server that fails by itself ends this with one line
    and exit status 1."""
    parent = os.getpid()
    server = subprocess.Popen(command, preexec_fn=lambda: end_with_parent(parent))
    try:
        while server.poll() is None and not port_in_use(port):
            time.sleep(0.1)
        if server.poll() is None:
            print(ready, flush=True)
        server.wait()
    except BaseException as error:  # Ctrl-C, a kill, or anything else here: the server does not outlive this
        server.terminate()
        try:
            server.wait(timeout=grace)
        except subprocess.TimeoutExpired:
            server.kill()
            server.wait()
        if not isinstance(error, KeyboardInterrupt):
            raise
        return
    if server.returncode > 0:  # it failed by itself (a signal's negative status is a stop asked for)
        print(
            f"make teach: the server stopped with exit status {server.returncode} (its log is above)",
            file=sys.stderr,
        )
        raise SystemExit(1)

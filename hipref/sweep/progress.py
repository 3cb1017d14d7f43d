"""A sweep's progress: a tqdm bar in a terminal, one line updated in place in a notebook, nothing otherwise.

A notebook's line is a text output re-sent under one display id, so the notebook saved after the run (by
papermill, or JupyterLab) holds its last state: the cells done, those read from the cache and the wall time.
A tqdm notebook bar is a widget, which a saved notebook shows by its first frame ("0%") where the widget is
not redrawn (JupyterLab 4). Both lines start "NN%|", as tqdm's do, which nbval's sanitizer masks
(`tests/nbval_sanitize.cfg`).

Only the standard library (and tqdm) is imported at load time, as by the engine (`hipref.sweep.engine`).
"""

from __future__ import annotations

import sys
import time
from typing import Any, Protocol

from tqdm import tqdm

EVERY = 0.5
"""Seconds at least between two updates of a notebook's line (the last one is always shown)."""


class Progress(Protocol):
    """What the engine calls: count finished cells, then close."""

    def update(self, n: int = 1) -> Any: ...

    def close(self) -> None: ...


class NotebookLine:
    """A notebook's progress line: '<desc>: NN%| done of total cells, C from the cache, T s'."""

    def __init__(self, total: int, initial: int, desc: str) -> None:
        from IPython.display import Pretty, display

        self._pretty = Pretty
        self.total, self.cached, self.done, self.desc = total, initial, initial, desc
        self.start = time.monotonic()
        self.shown = self.start
        self.handle = display(Pretty(self.text()), display_id=True)

    def text(self) -> str:
        share = 100 * self.done // self.total if self.total else 100
        seconds = time.monotonic() - self.start
        return (
            f"{self.desc}: {share}%| {self.done} of {self.total} cells, {self.cached} from the cache, "
            f"{seconds:.0f} s"
        )

    def update(self, n: int = 1) -> None:
        self.done += n
        now = time.monotonic()
        if now - self.shown >= EVERY:
            self.shown = now
            self.handle.update(self._pretty(self.text()))

    def close(self) -> None:
        self.handle.update(self._pretty(self.text()))


def in_kernel() -> bool:
    """Whether this process is a Jupyter kernel (its stderr is the kernel's stream to the notebook)."""
    return type(sys.stderr).__module__.startswith("ipykernel")


def progress(total: int, initial: int, desc: str) -> Progress:
    """The progress of a sweep of `total` cells, `initial` of them read from the cache: a line in a notebook,
    a tqdm bar on a terminal; none (a disabled bar) when stderr goes to a file or a pipe, where each update
    would only lengthen one line."""
    if in_kernel():
        return NotebookLine(total, initial, desc)
    return tqdm(
        total=total, initial=initial, desc=desc, unit="cell", file=sys.stderr, disable=not sys.stderr.isatty()
    )

"""pytest plugin for nbval (`make nbval` loads it with `-p tests.nbval_kernel`): each notebook's kernel
listens on sockets of its own, not on TCP ports, so the two notebooks nbval runs side by side never start
their kernels on the same port (`hipref.kernel`); and the notebooks are handed to the two workers longest
first."""

from __future__ import annotations

import functools
import json
from pathlib import Path

import nbval.kernel
import pytest

from hipref.kernel import IPCKernelManager


@pytest.hookimpl(tryfirst=True)
def pytest_configure(config: pytest.Config) -> None:
    # nbval 0.11 offers no option for the kernel manager: its start_new_kernel builds a KernelManager by the
    # name it imported, which is replaced here before any notebook is collected.
    nbval.kernel.KernelManager = IPCKernelManager  # type: ignore[misc]


@functools.cache
def recorded_duration(notebook: Path) -> float:
    """Seconds the notebook took when it was last executed at the quick profile, as papermill recorded them
    in its metadata (0 when it recorded none)."""
    metadata = json.loads(notebook.read_text())["metadata"]
    return float(metadata.get("papermill", {}).get("duration") or 0.0)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The longest notebooks first, by their recorded duration (`make nbval` passes `--dist=loadfile
    --no-loadscope-reorder`, so a free worker takes the next notebook in this order): two long notebooks do
    not end the run one after the other on one worker while the other has nothing left. Cells keep their
    order within a notebook."""
    items.sort(key=lambda item: -recorded_duration(item.path))

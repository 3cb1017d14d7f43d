"""pytest plugin for nbval (`make nbval` loads it with `-p tests.nbval_kernel`): each notebook's kernel
listens on sockets of its own, not on TCP ports, so the two notebooks nbval runs side by side never start
their kernels on the same port (`hipref.kernel`)."""

from __future__ import annotations

import nbval.kernel
import pytest

from hipref.kernel import IPCKernelManager


@pytest.hookimpl(tryfirst=True)
def pytest_configure(config: pytest.Config) -> None:
    # nbval 0.11 offers no option for the kernel manager: its start_new_kernel builds a KernelManager by the
    # name it imported, which is replaced here before any notebook is collected.
    nbval.kernel.KernelManager = IPCKernelManager  # type: ignore[misc]

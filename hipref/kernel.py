"""The Jupyter kernel manager every notebook execution of the study starts its kernel with.

By default a kernel listens on five TCP ports that its manager picks by binding and releasing them: two
kernels started at the same moment (`make reproduce PROFILE=quick` and nbval each run two notebooks at a time)
can pick the same port, and one of them dies with `ZMQError: Address already in use` before replying to
kernel_info. Here the kernel listens on Unix domain sockets instead, under a name no other kernel has, so
there is no port to share. jupyter_client's own IPC default names the sockets `kernel-ipc-N` relative to the
working directory, which the kernel (started in `notebooks/`) and its manager (in the checkout) do not share,
and which two managers started together would both pick.
"""

from __future__ import annotations

import tempfile
import uuid
from pathlib import Path

from jupyter_client.manager import KernelManager
from traitlets import CaselessStrEnum

SOCKET_PREFIX = "hipref-kernel-"
"""Start of the name of each kernel's sockets in the temporary directory: PREFIX + 12 hex digits + -N."""


def socket_base() -> str:
    """An absolute path no other kernel uses, kept short: a Unix socket's path has at most 107 bytes (103
    on macOS, whose temporary directory is long)."""
    return str(Path(tempfile.gettempdir()) / f"{SOCKET_PREFIX}{uuid.uuid4().hex[:12]}")


class IPCKernelManager(KernelManager):
    """A KernelManager whose kernel listens on its own Unix domain sockets, not on TCP ports."""

    transport = CaselessStrEnum(["tcp", "ipc"], default_value="ipc", config=True)

    def _ip_default(self) -> str:
        # With the IPC transport `ip` is the path the sockets' names start with.
        return socket_base() if self.transport == "ipc" else super()._ip_default()

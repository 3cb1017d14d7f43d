"""Fixtures shared by the tests."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
import torch


@pytest.fixture(autouse=True)
def single_thread() -> Iterator[None]:
    """Every test runs torch on one thread, as inside a run of the study: the tests run on every core at once,
    and two threads per test made them wait on each other (a co-teaching test took 2 s alone and 30 s beside a
    busy core). The caller's setting is restored afterwards."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)

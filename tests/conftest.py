"""Fixtures shared by the tests, and the order in which `make pytest` hands them to its workers."""

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


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers",
        "slow: a test of several seconds or more (a fresh interpreter, kernel, browser or MuJoCo runs); "
        "handed to the workers first",
    )


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    """The slow tests first, the rest in their collected order. `make pytest` hands whole test files to
    whichever worker is free, in the order their first test comes (`--dist=loadfile --no-loadscope-reorder`):
    the files holding the long tests start first, on both workers, and the many short files fill in after
    them, rather than one worker running the last long file alone while the other waits."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)

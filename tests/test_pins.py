"""An environment that overrides the study's pins (CPU dispatch, package versions) is told, once, that its
rows may differ from the committed ones."""

from __future__ import annotations

import subprocess
import sys
import warnings
from pathlib import Path

import pytest

from hipref import numerics
from hipref.sweep import run_sweep
from tests._sweep_cells import ToyCell, toy_cell

ROOT = Path(__file__).resolve().parents[1]


def test_this_environment_overrides_nothing() -> None:
    import os

    assert numerics.overrides(os.environ, ROOT / "environment.txt") == []


def test_a_version_other_than_the_pin_is_named(tmp_path: Path) -> None:
    pins = tmp_path / "environment.txt"
    pins.write_text("# a comment\nnumpy==1.0.0\nno-such-package-here==1.0\n")
    (found,) = numerics.overrides({}, pins)
    assert found.startswith("numpy ") and found.endswith("(pinned: 1.0.0)")


def test_a_sweep_warns_once_when_the_dispatch_pin_is_overridden(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    monkeypatch.setenv("ATEN_CPU_CAPABILITY", "default")
    numerics.warn_overrides.cache_clear()
    log = tmp_path / "log"
    log.mkdir()
    try:
        with pytest.warns(RuntimeWarning, match="ATEN_CPU_CAPABILITY=default .pinned: avx2.") as caught:
            run_sweep(toy_cell, [ToyCell(seed=0, log_dir=str(log))], cache_dir=False, workers=1)
        assert len([w for w in caught if w.category is RuntimeWarning]) == 1
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)
            run_sweep(toy_cell, [ToyCell(seed=1)], cache_dir=False, workers=1)  # once per process
    finally:
        numerics.warn_overrides.cache_clear()


def test_the_c_librarys_other_sine_path_is_named() -> None:
    """glibc's SSE2 sine and cosine (what a CPU without FMA and AVX2 runs) give other last bits than the FMA
    ones the committed rows were computed with, and the check says so; this machine's own path matches."""
    probe = "from hipref import numerics; print(numerics.libm_matches())"
    masked = {"GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2,-FMA"}
    answers = [
        subprocess.run(
            [sys.executable, "-c", probe],
            env={"PATH": "/usr/bin:/bin", **extra},
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        for extra in ({}, masked)
    ]
    assert answers == ["True", "False"]

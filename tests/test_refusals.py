"""Inputs that used to pass silently, or to fail deep inside with a message naming something else, are
refused where they enter, before any compute, with a message naming the input."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import hipref  # noqa: F401 - registers the environments
from hipref.envs.pushing import PushingConfig, PushingTask
from hipref.experiments.controllers import ControllersConfig
from hipref.experiments.r2_noise import R2Config
from hipref.experiments.r3_copesi import R3Config
from hipref.learners.coteaching import CoPESILearner
from hipref.sweep import run_sweep
from hipref.teachers.preference import ScriptedPreferenceTeacher, preference_label_vector
from tests._sweep_cells import ToyCell, executions, toy_cell

CASES: dict[str, tuple[Callable[[], object], str]] = {
    # A string or a bool where a number is meant no longer passes a range check.
    "string noise level": (lambda: R2Config(noise_levels=("0.3",)), r"noise_levels .* got '0.3'"),
    "bool noise level": (lambda: R2Config(noise_levels=(True,)), r"noise_levels .* got True"),
    "string desk height": (lambda: ControllersConfig(desk_height="0.81"), r"desk_height .* got '0.81'"),
    "string co-pesi noise": (lambda: CoPESILearner(None, "0.2"), r"noise_level .* got '0.2'"),  # type: ignore[arg-type]
    "string teacher noise": (
        lambda: ScriptedPreferenceTeacher(0.7, "0.1", np.random.default_rng(0)),  # type: ignore[arg-type]
        r"noise .* got '0.1'",
    ),
    "string mass range": (lambda: PushingConfig(mass_range=("8", "20")), r"mass_range .* got \('8', '20'\)"),
    # A scalar or a string where a list is meant.
    "scalar noise levels": (
        lambda: R2Config(noise_levels=1.5),
        r"noise_levels must be a list or tuple.* got 1.5",
    ),
    "string domains": (lambda: R2Config(domains="wiping"), r"domains must be a list or tuple.* got 'wiping'"),
    # A repeated entry would run the same cells twice and fail only when their rows are combined.
    "repeated heights": (lambda: R2Config(heights=(0.6, 0.6)), r"heights must not repeat a value.*0.6 twice"),
    "repeated noise levels": (lambda: R2Config(noise_levels=(0.3, 0.3)), r"noise_levels must not repeat"),
    "repeated methods": (
        lambda: R3Config(methods=("pesi", "pesi")),
        r"methods must not repeat.*'pesi' twice",
    ),
    # A float label where the integer -1 or 1 is meant.
    "float label": (lambda: preference_label_vector(1.0, 2), r"integer -1 or 1, got 1.0 \(float\)"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_a_bad_value_is_refused_naming_it(case: str) -> None:
    make, message = CASES[case]
    with pytest.raises(ValueError, match=message):
        make()


@pytest.mark.parametrize(
    ("fn", "workers", "message"),
    [
        (toy_cell, 1.5, r"workers must be an integer at least 1 or None, got 1.5"),
        (toy_cell, "2", r"workers must be an integer at least 1 or None, got '2'"),
        (lambda cell: toy_cell(cell), 1, r"fn must be a module-level function .*<lambda>"),
    ],
)
def test_a_sweep_refuses_bad_workers_and_functions_before_any_cell_runs(
    tmp_path: Path, fn: Callable, workers: object, message: str
) -> None:
    with pytest.raises(ValueError, match=message):
        run_sweep(fn, [ToyCell(seed=0, log_dir=str(tmp_path))], cache_dir=False, workers=workers)  # type: ignore[arg-type]
    assert executions(tmp_path) == []


def test_a_push_before_reset_is_refused() -> None:
    with pytest.raises(RuntimeError, match=r"push\(\) before reset\(\)"):
        PushingTask().push(10.0)


@pytest.mark.parametrize(
    ("options", "message"),
    [("height", r"options must be a dict .* got 'height'"), ({"param": "12"}, r"cube mass .* got '12'")],
)
def test_reset_options_that_are_no_dict_or_hold_a_string_are_refused(options: object, message: str) -> None:
    env = gym.make("hipref/Pushing-v0")
    with pytest.raises(ValueError, match=message):
        env.reset(seed=0, options=options)  # type: ignore[arg-type]

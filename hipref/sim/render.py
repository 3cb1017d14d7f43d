"""Frames of a scene, rendered headlessly (MUJOCO_GL=egl); skipped with a message where no GL is."""

from __future__ import annotations

import mujoco
import numpy as np

from hipref.sim.scene import Scene


def still_frame(model: mujoco.MjModel, data: mujoco.MjData, camera: str = "overview") -> np.ndarray | None:
    """An RGB image of the current state from `camera`, or None (with the reason printed) without GL."""
    try:
        with mujoco.Renderer(model, height=480, width=640) as renderer:
            renderer.update_scene(data, camera=camera)
            return renderer.render().copy()
    except Exception as error:  # any GL failure means: no rendering on this machine
        print(f"Rendering skipped: no OpenGL context available ({type(error).__name__}: {error}).")
        return None


def clip_frames(
    scene: Scene,
    arm_positions: np.ndarray,
    cube_xy: np.ndarray | None = None,
    *,
    camera: str = "overview",
    height: int = 240,
    width: int = 320,
) -> list[np.ndarray] | None:
    """The frames of a recorded clip, one per row of `arm_positions` (the arm's joint positions), with the
    cube (if any) moved to the row's `cube_xy` on the desk; or None, with the reason printed, without GL.

    Each frame poses a copy of the scene's current state by kinematics alone (bodies, camera, lights), so
    the clip is shown as it was recorded, not simulated again; the cube keeps its current height and
    orientation."""
    data = mujoco.MjData(scene.model)
    data.qpos[:] = scene.data.qpos
    try:
        with mujoco.Renderer(scene.model, height=height, width=width) as renderer:
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
        print(f"Rendering skipped: no OpenGL context available ({type(error).__name__}: {error}).")
        return None

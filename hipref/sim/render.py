"""Still frames of a scene, rendered headlessly (MUJOCO_GL=egl); skipped with a message where no GL is."""

from __future__ import annotations

import mujoco
import numpy as np


def still_frame(model: mujoco.MjModel, data: mujoco.MjData, camera: str = "overview") -> np.ndarray | None:
    """An RGB image of the current state from `camera`, or None (with the reason printed) without GL."""
    try:
        with mujoco.Renderer(model, height=480, width=640) as renderer:
            renderer.update_scene(data, camera=camera)
            return renderer.render().copy()
    except Exception as error:  # any GL failure means: no rendering on this machine
        print(f"Rendering skipped: no OpenGL context available ({type(error).__name__}: {error}).")
        return None

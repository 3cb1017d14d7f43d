"""hipref: learning robot control from human advice.

Feedback trains a high-level goal selector on a grid over the desk; noisy preferences fine-tune a
system-identification model whose estimate parameterises the low-level force controller.

Importing the package sets three environment variables where they are unset (`ATEN_CPU_CAPABILITY` and
`MKL_CBWR`: `hipref.numerics`; `MUJOCO_GL`, below, also where it names a backend whose library is
missing) and loads no numerical library; `import hipref.envs` registers the gymnasium environments.
"""

import ctypes.util
import os
import sys

# torch chooses its kernels by the CPU it runs on; this import pins them before torch first computes, so
# that the rows are the same on every x86-64 CPU with AVX2 (hipref.numerics says which and why).
import hipref.numerics  # noqa: F401 - imported for that effect

# Rendering is headless through EGL unless the user chose a backend. MuJoCo loads the chosen backend's
# library when it is first imported, and fails to import where it is missing: so rendering is disabled
# instead (said once, for a backend the user chose), and frames and clips are skipped with a message.
_BACKEND_LIBRARIES = {"egl": "EGL", "osmesa": "OSMesa"}
_chosen = os.environ.get("MUJOCO_GL")
if _chosen is None:
    os.environ["MUJOCO_GL"] = "egl" if ctypes.util.find_library("EGL") else "disable"
elif (_library := _BACKEND_LIBRARIES.get(_chosen.lower())) and not ctypes.util.find_library(_library):
    print(
        f"MUJOCO_GL={_chosen}, but lib{_library} is not found: rendering is disabled (frames and clips are "
        "skipped).",
        file=sys.stderr,
    )
    os.environ["MUJOCO_GL"] = "disable"

__version__ = "0.1.0"

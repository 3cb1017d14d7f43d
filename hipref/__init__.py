"""hipref: learning robot control from human advice.

Feedback trains a high-level goal selector on a grid over the desk; noisy preferences fine-tune a
system-identification model whose estimate parameterises the low-level force controller.

Importing the package sets three environment variables where they are unset (`ATEN_CPU_CAPABILITY` and
`MKL_CBWR`: `hipref.numerics`; `MUJOCO_GL`, below) and loads no numerical library; `import hipref.envs`
registers the gymnasium environments.
"""

import ctypes.util
import os

# torch chooses its kernels by the CPU it runs on; this import pins them before torch first computes, so
# that the rows are the same on every x86-64 CPU with AVX2 (hipref.numerics says which and why).
import hipref.numerics  # noqa: F401 - imported for that effect

# Rendering is headless through EGL unless the user chose a backend. MuJoCo loads the chosen backend's
# library when it is first imported, so where EGL is missing rendering is disabled instead, and the
# still frames are skipped with a message rather than the import failing.
os.environ.setdefault("MUJOCO_GL", "egl" if ctypes.util.find_library("EGL") else "disable")

__version__ = "0.1.0"

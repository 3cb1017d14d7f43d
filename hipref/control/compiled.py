"""MuJoCo's C API inside compiled code, so that the controllers' per-step loop runs without Python.

The controllers of paper A.7 act at every physics step: SPD (Eq. 5-6) needs the mass matrix and the
forces of the current state between mj_step1 and mj_step2. A Python loop around MuJoCo's bindings spends
more time in the interpreter than in the physics, so the loop is compiled with numba instead. The compiled
code calls the C functions of the libmujoco shipped inside the `mujoco` package (the library its bindings
already loaded, so one MuJoCo with one global state) through ctypes, on the raw mjModel*/mjData* pointers,
and reads and writes mjData through the numpy arrays the bindings expose, which alias mjData's memory.

Compiled functions that call ctypes function pointers cannot be cached on disk, so every process compiles
the kernels at their first call, once: measured at about 2.5 s for wiping (inverse kinematics and the
control period), 3.3 s for pushing (inverse kinematics and the push), 4.2 s for both, on the study's
2-core machine. A sweep cell runs hundreds of rollouts, each of which the compiled loop makes 17 ms
(wiping) to 15 ms (pushing) shorter, so the compilation pays for itself within a cell."""

from __future__ import annotations

import ctypes
from pathlib import Path
from typing import NamedTuple

import mujoco
import numpy as np

try:
    import numba
except ImportError as error:  # a missing package or one built for another numpy
    raise ImportError(
        f"The low-level controllers are compiled with numba, which failed to import ({error}): install "
        "it with `pip install numba==0.68.1 llvmlite==0.50.0` (both pinned in environment.txt)."
    ) from error

# Compiled without fastmath, so results are reproducible to the bit.
kernel = numba.njit(no_cfunc_wrapper=True)
"""Compiles a function called from Python."""
subroutine = numba.njit(no_cpython_wrapper=True, no_cfunc_wrapper=True)
"""Compiles a function called only from compiled code (no Python entry point: it compiles faster)."""

if int(mujoco.__version__.split(".")[0]) != 3:
    # MuJoCo 4 changed mj_fullM's arguments; the declarations below are those of 3.x (3.17.0 is pinned).
    raise ImportError(
        f"hipref's compiled controllers need MuJoCo 3.x (3.17.0 is pinned), found {mujoco.__version__}"
    )


def _libmujoco() -> ctypes.CDLL:
    package = Path(mujoco.__file__).parent
    candidates = sorted(package.glob("libmujoco.so.*")) + sorted(package.glob("libmujoco.*.dylib"))
    if not candidates:
        raise ImportError(
            f"libmujoco is missing from the mujoco package at {package}; reinstall mujoco==3.17.0"
        )
    return ctypes.CDLL(str(candidates[0]))


_LIB = _libmujoco()
# Pointers travel as plain integers: numba passes an int to a ctypes function declared with c_size_t.
_POINTER = ctypes.c_size_t


def _c_function(name: str, *argtypes: type) -> ctypes._CFuncPtr:  # type: ignore[name-defined]
    function = getattr(_LIB, name)
    function.argtypes = list(argtypes)
    function.restype = None
    return function


# Declarations as in MuJoCo 3.17's mujoco.h.
mj_step1 = _c_function("mj_step1", _POINTER, _POINTER)
"""void mj_step1(const mjModel* m, mjData* d): position and velocity stages, up to the forces SPD needs."""
mj_step2 = _c_function("mj_step2", _POINTER, _POINTER)
"""void mj_step2(const mjModel* m, mjData* d): actuation, acceleration, constraint solve and integration."""
mj_fullM = _c_function("mj_fullM", _POINTER, _POINTER, _POINTER)
"""void mj_fullM(const mjModel* m, const mjData* d, mjtNum* dst): the dense nv x nv mass matrix."""
mj_jacSite = _c_function("mj_jacSite", _POINTER, _POINTER, _POINTER, _POINTER, ctypes.c_int)
"""void mj_jacSite(const mjModel* m, const mjData* d, mjtNum* jacp, mjtNum* jacr, int site): 3 x nv each."""
mj_kinematics = _c_function("mj_kinematics", _POINTER, _POINTER)
"""void mj_kinematics(const mjModel* m, mjData* d): body, geom and site poses from qpos."""
mj_comPos = _c_function("mj_comPos", _POINTER, _POINTER)
"""void mj_comPos(const mjModel* m, mjData* d): the centre-of-mass frames mj_jacSite needs."""


class Physics(NamedTuple):
    """One mjModel/mjData pair as compiled code sees it: the raw pointers MuJoCo's C functions take and
    the numpy views of the mjData fields the controllers read and write. The views alias mjData's memory
    (allocated once, never moved), so they always show the current state; the MjData must outlive them."""

    model: int
    """mjModel* as an integer."""
    data: int
    """mjData* as an integer."""
    qpos: np.ndarray
    qvel: np.ndarray
    ctrl: np.ndarray
    qfrc_bias: np.ndarray
    qfrc_passive: np.ndarray
    qfrc_constraint: np.ndarray
    sensordata: np.ndarray
    site_xpos: np.ndarray
    site_xmat: np.ndarray


def physics_of(model: mujoco.MjModel, data: mujoco.MjData) -> Physics:
    """The compiled view of `data`, which must be an MjData of `model`."""
    if data.model._address != model._address:
        raise ValueError("data must be an MjData of the given model")
    return Physics(
        model=model._address,
        data=data._address,
        qpos=data.qpos,
        qvel=data.qvel,
        ctrl=data.ctrl,
        qfrc_bias=data.qfrc_bias,
        qfrc_passive=data.qfrc_passive,
        qfrc_constraint=data.qfrc_constraint,
        sensordata=data.sensordata,
        site_xpos=data.site_xpos,
        site_xmat=data.site_xmat,
    )

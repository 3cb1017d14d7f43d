"""MuJoCo's C API inside compiled code, so that the controllers' per-step loop runs without Python.

The controllers of paper A.7 act at every physics step: SPD (Eq. 5-6) needs the mass matrix and the
forces of the current state between mj_step1 and mj_step2. A Python loop around MuJoCo's bindings spends
more time in the interpreter than in the physics, so the loop is compiled with numba instead. The compiled
code calls the C functions of the libmujoco shipped inside the `mujoco` package (the library its bindings
already loaded, so one MuJoCo with one global state) by their symbol names, on the raw mjModel*/mjData*
pointers, and reads and writes mjData through the numpy arrays the bindings expose, which alias mjData's
memory.

Compiling the kernels takes about 4 s per process on the study's 2-core machine (wiping's inverse
kinematics and control period, pushing's push), and every sweep worker, notebook kernel and test process
would pay it. Because the C functions are named rather than embedded as addresses, the compiled code is
cached on disk (`CompiledCache`): the first process compiles, the others load it in well under a second.
"""

from __future__ import annotations

import hashlib
import os
import types
from pathlib import Path
from typing import Any, NamedTuple

import mujoco
import numpy as np

try:
    import llvmlite.binding
    import numba
    from numba.core import caching
except ImportError as error:  # a missing package or one built for another numpy
    raise ImportError(
        f"The low-level controllers are compiled with numba, which failed to import ({error}): install "
        "it with `pip install numba==0.68.1 llvmlite==0.50.0` (both pinned in environment.txt)."
    ) from error

if int(mujoco.__version__.split(".")[0]) != 3:
    # MuJoCo 4 changed mj_fullM's arguments; the declarations below are those of 3.x (3.17.0 is pinned).
    raise ImportError(
        f"hipref's compiled controllers need MuJoCo 3.x (3.17.0 is pinned), found {mujoco.__version__}"
    )

CONTROL = Path(__file__).resolve().parent
"""The package of the compiled controllers: every compiled function lives in one of its modules."""


def _control_sources_digest() -> str:
    """What the compiled code depends on: every module of this package and the MuJoCo version."""
    digest = hashlib.sha256(mujoco.__version__.encode())
    for source in sorted(CONTROL.glob("*.py")):
        digest.update(source.name.encode() + b"\0" + source.read_bytes())
    return digest.hexdigest()[:16]


class CompiledCache(caching._CacheLocator):
    """Where numba caches the compiled controllers: `$NUMBA_CACHE_DIR/numba-<digest>` if that is set (as
    numba's own locators do), else `__pycache__/numba-<digest>` beside this module, or, where that is not
    writable, `~/.cache/hipref/numba-<digest>`.

    numba's own locators stamp a cached function with its own source file only, so a kernel cached before
    an edit of a subroutine it calls from another module would be loaded stale. Here the stamp is the digest
    of every module of the package: editing any of them compiles afresh. Functions outside this package
    are left to numba's locators."""

    DIGEST = _control_sources_digest()

    def __init__(self, py_func: types.FunctionType, directory: Path) -> None:
        self._lineno = py_func.__code__.co_firstlineno
        self._cache_path = str(directory / f"numba-{self.DIGEST}")

    def get_cache_path(self) -> str:
        return self._cache_path

    def get_source_stamp(self) -> str:
        return self.DIGEST

    def get_disambiguator(self) -> str:
        return str(self._lineno)

    @classmethod
    def from_function(cls, py_func: types.FunctionType, py_file: str) -> CompiledCache | None:
        if Path(py_file).resolve().parent != CONTROL:
            return None
        chosen = os.environ.get("NUMBA_CACHE_DIR")
        defaults = [CONTROL / "__pycache__", Path.home() / ".cache" / "hipref"]
        for directory in [Path(chosen)] if chosen else defaults:
            locator = cls(py_func, directory)
            try:
                locator.ensure_cache_path()
            except OSError:
                continue
            return locator
        return None


caching.CacheImpl._locator_classes.insert(0, CompiledCache)

# Compiled without fastmath, so results are reproducible to the bit.
# numba's declared signature of njit lists its public options only, not the wrapper options it passes on to
# the compiler (no_cfunc_wrapper, no_cpython_wrapper).
kernel = numba.njit(no_cfunc_wrapper=True, cache=True)  # type: ignore[call-overload]
"""Compiles a function called from Python."""
subroutine = numba.njit(no_cpython_wrapper=True, no_cfunc_wrapper=True, cache=True)  # type: ignore[call-overload]
"""Compiles a function called only from compiled code (no Python entry point: it compiles faster)."""


def _load_libmujoco() -> None:
    """Make libmujoco's symbols resolvable by the compiled code: the library the bindings loaded."""
    package = Path(mujoco.__file__).parent
    candidates = sorted(package.glob("libmujoco.so.*")) + sorted(package.glob("libmujoco.*.dylib"))
    if not candidates:
        raise ImportError(
            f"libmujoco is missing from the mujoco package at {package}; reinstall mujoco==3.17.0"
        )
    llvmlite.binding.load_library_permanently(str(candidates[0]))


_load_libmujoco()
_POINTER = numba.types.uintp
"""Pointers travel as plain integers (mjModel*, mjData*, mjtNum*)."""


def _c_function(name: str, *argtypes: numba.types.Type) -> Any:
    """A C function of libmujoco, callable from compiled code only (Any: to Python, numba's declaration is a
    type, not a callable)."""
    return numba.types.ExternalFunction(name, numba.types.void(*argtypes))


# Declarations as in MuJoCo 3.17's mujoco.h.
mj_step1 = _c_function("mj_step1", _POINTER, _POINTER)
"""void mj_step1(const mjModel* m, mjData* d): position and velocity stages, up to the forces SPD needs."""
mj_step2 = _c_function("mj_step2", _POINTER, _POINTER)
"""void mj_step2(const mjModel* m, mjData* d): actuation, acceleration, constraint solve and integration."""
mj_fullM = _c_function("mj_fullM", _POINTER, _POINTER, _POINTER)
"""void mj_fullM(const mjModel* m, const mjData* d, mjtNum* dst): the dense nv x nv mass matrix."""
mj_jacSite = _c_function("mj_jacSite", _POINTER, _POINTER, _POINTER, _POINTER, numba.types.intc)
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

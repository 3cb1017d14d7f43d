"""The same seed gives byte-identical rows on every x86-64 CPU with AVX2, not only on the one that ran it.

Two libraries inside torch choose their kernels by the CPU they run on, and the kernels round differently:

- ATen, torch's own kernels (tanh, softmax, the sums of a reduction, Adam's update), runs AVX-512, AVX2 or
  plain code by the CPU's instruction sets; the vector width changes the order in which a reduction adds.
  `ATEN_CPU_CAPABILITY=avx2` gives every CPU of the study's kind the AVX2 kernels.
- MKL, which multiplies the matrices of every `nn.Linear` (the SI model, the flat policy of pretrained
  COACH), chooses its kernels by vendor and instruction set, and outside its reproducible mode also by the
  operands' alignment in memory, which follows the heap's history. Its `COMPATIBLE` branch is the one code
  path that Intel and AMD processors both run (the AVX2 branch exists only on Intel's), and in it the
  alignment no longer matters: `MKL_CBWR=COMPATIBLE`.

One bit of difference in SI's weights moves every estimate after it, and one action of the flat policy
sampled differently changes the rest of its run, so unpinned the rows of notebooks 01, 04 and 06 differed
between two machines of the same kind.

Measured not to change a row, so left alone: MuJoCo (compiled for AVX, with no dispatch at run time), the
numba controllers (no fastmath, so no fused multiply-add and no reordering, whatever CPU they are compiled
for), oneDNN (not on the study's path) and numpy as the study uses it (sums, 3 x 3 products). numpy does
dispatch elsewhere: its float64 sin, cos, exp and log have AVX-512 versions that differ in the last bit,
and its OpenBLAS runs AVX-512 kernels for larger products and solves. One such bit in the direction of a
push moved where a few pushes came to rest by one control period, and with it the slice SI was evaluated
on: 30 of the 10,020 values of notebooks 02 and 03 computed on an AVX-512 machine differed from this
study's. So the package takes sines and cosines from `math`, the C library's, and the
Makefile pins numpy and OpenBLAS to their AVX2 kernels for every process it starts
(`NPY_DISABLE_CPU_FEATURES`, `OPENBLAS_CORETYPE`): both read their setting when numpy is loaded, which a
notebook does before it imports hipref, so they cannot be pinned here (pinned in the sweep's workers only,
a run would differ between a pool and the notebook's own process). tests/test_cross_cpu.py computes its
reference with them at AVX2 too, so a row of its cells that comes to depend on them is caught.

The C library's sine and cosine are dispatched too, and cannot be pinned from inside a process: glibc picks
its FMA version on a CPU with FMA and AVX2 (every machine of the study's kind) and its SSE2 version
elsewhere, and the two differ in the last bit of about 1 in 1,500 results. MuJoCo and `math` both call them.
Run with the FMA path masked (`GLIBC_TUNABLES=glibc.cpu.hwcaps=-AVX2,-FMA`), Algorithm 4's trajectories
differed in the last bits, its pretrained SI by at most 3e-6 per weight, and 330-episode runs' errors by at
most 4e-8 m and 3e-6 kg (successes equal). So a sweep also warns when this process's sine and cosine do not
give the bits of the committed rows' (`LIBM_PROBE`).

One more path depends on the processor however the libraries are pinned: MKL's float32 square root, which
torch's default Adam update calls; every Adam of the study runs fused instead (`adam`).

Pinned, the torch parts cost more CPU time: Algorithm 4's pretraining (3000 Adam steps), built once per
domain and cached, takes about 10 s instead of 6 s; a learning run, dominated by the physics, the same.

Both settings are read when torch first computes, so they are set when this module is imported, which
`import hipref` does before anything else; sweep workers are spawned processes that import `hipref` first,
and inherit them. A value already in the environment is kept, so a person can still choose another setting
on purpose; every sweep then warns once per process that its rows may differ from the committed ones, as it
does when an installed package's version differs from environment.txt (`warn_overrides`).
"""

from __future__ import annotations

import contextlib
import functools
import math
import os
import sys
import warnings
from collections.abc import Iterable, Iterator, Mapping
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import torch

PINNED: dict[str, str] = {"ATEN_CPU_CAPABILITY": "avx2", "MKL_CBWR": "COMPATIBLE"}
"""The environment settings that make torch compute the same bits on every x86-64 CPU with AVX2."""


def pin_cpu_dispatch() -> None:
    """Set `PINNED` where the environment does not already say otherwise, and warn if torch has computed
    already: its kernels are then this CPU's, and the rows may differ on another machine."""
    for name, value in PINNED.items():
        os.environ.setdefault(name, value)
    torch = sys.modules.get("torch")
    if torch is None:
        return
    # Reading the capability fixes it; when torch has not computed yet it is fixed here, under PINNED.
    capability = torch.backends.cpu.get_cpu_capability()
    wanted = os.environ["ATEN_CPU_CAPABILITY"]
    if capability.lower() != wanted.lower():
        warnings.warn(
            f"torch computes with its {capability} kernels, not the {wanted} ones hipref asks for (torch was "
            "used before hipref was imported, or this CPU lacks them): the rows may differ from those of "
            "another machine. Import hipref before using torch.",
            RuntimeWarning,
            stacklevel=2,
        )


LIBM_PROBE: tuple[tuple[str, str, str], ...] = (
    ("sin", "-0x1.8f8a11bfd44f3p+5", "0x1.45183a5d2ad8dp-2"),
    ("sin", "-0x1.b4fdf3b645a40p-1", "-0x1.81d5fd76bfdf8p-1"),
    ("sin", "0x1.7383ece2a5348p+5", "0x1.43b839f75b902p-1"),
    ("cos", "-0x1.d5565b7a32847p+4", "-0x1.f5467c09ab2cdp-2"),
    ("cos", "-0x1.2504c756b2dc0p+2", "-0x1.118e2588cc486p-3"),
    ("cos", "0x1.6ae5604189374p+5", "0x1.84fb5f7d00c00p-3"),
)
"""(function, argument, result) in hexadecimal: results of glibc's FMA sine and cosine, the path the committed
rows were computed on, whose last bit its SSE2 path gives otherwise."""


def libm_matches() -> bool:
    """Whether the C library's sine and cosine in this process give `LIBM_PROBE`'s bits."""
    return all(
        getattr(math, function)(float.fromhex(argument)) == float.fromhex(result)
        for function, argument, result in LIBM_PROBE
    )


def overrides(environ: Mapping[str, str], pins: Path | None) -> list[str]:
    """What in this process differs from what the committed rows were computed with: a `PINNED` setting
    the environment chose otherwise, the C library's sine and cosine (`libm_matches`), and an installed
    version of a package that differs from its pin in
    `pins` (the checkout's environment.txt; None outside a checkout)."""
    from importlib import metadata

    found = [
        f"{name}={environ[name]} (pinned: {value})"
        for name, value in PINNED.items()
        if environ.get(name, value).lower() != value.lower()
    ]
    if not libm_matches():
        found.append(
            "the C library's sine and cosine (another path than glibc's FMA one, e.g. a CPU without FMA and "
            "AVX2, GLIBC_TUNABLES masking them, or another C library)"
        )
    lines = pins.read_text().splitlines() if pins is not None and pins.is_file() else []
    for name, _, version in (line.partition("==") for line in lines if "==" in line and line[0] != "#"):
        try:
            installed = metadata.version(name.strip())
        except metadata.PackageNotFoundError:
            continue
        # A local build label (torch's "+cpu") names the wheel, not another version.
        if installed.split("+")[0] != version.strip():
            found.append(f"{name.strip()} {installed} (pinned: {version.strip()})")
    return found


@functools.cache
def warn_overrides(pins: Path | None) -> None:
    """Warn, once per process, that rows computed here may differ from the committed ones, naming what
    differs from the pins (`overrides`; `pins` the checkout's environment.txt, None outside a checkout).
    Every sweep calls this before it computes."""
    found = overrides(os.environ, pins)
    if found:
        warnings.warn(
            f"this environment overrides the study's pins: {'; '.join(found)}. Rows computed here may "
            "differ from the committed ones (results/); install with `make install` and leave "
            f"{' and '.join(PINNED)} unset to compute the same.",
            RuntimeWarning,
            stacklevel=3,
        )


@contextlib.contextmanager
def one_thread() -> Iterator[None]:
    """torch on one thread for the duration of a run, the caller's setting restored after (a run may
    execute in a person's kernel): parallel runs do not oversubscribe the cores, and a reduction adds in
    one order whatever the machine. A no-op while torch is not loaded."""
    torch = sys.modules.get("torch")
    if torch is None:
        yield
        return
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(before)


def adam(parameters: Iterable[torch.nn.Parameter], learning_rate: float) -> torch.optim.Adam:
    """Adam as every learner of the study runs it: its update in ATen's fused kernel (`fused=True`).

    The default update takes Adam's square root through MKL's vector math, whose float32 square root is not
    correctly rounded and, even in MKL's COMPATIBLE branch, rounds differently on different processors (it
    refines an approximate reciprocal square root, which processor models compute differently): one last
    bit per step grew, over Algorithm 4's 3000 steps, into a different pretrained SI and different rows on
    an AVX-512 machine and an AVX2 one. The fused kernel takes the exact hardware square root."""
    import torch

    return torch.optim.Adam(parameters, lr=learning_rate, fused=True)


pin_cpu_dispatch()

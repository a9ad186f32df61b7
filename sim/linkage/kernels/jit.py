"""Provides the kernels' numba options: the batch entry points', the per-linkage helpers'
(inlined, without reference counting, their arrays `noalias`) and the one numba patch,
`enable_noalias`."""

from __future__ import annotations

NOALIAS_ENV = "LINKEVO_NUMBA_NOALIAS"
"""Set to 0 to compile every kernel without `noalias` (same results, more slowly)."""


def enable_noalias() -> dict[str, bool]:
    """Registers numba's `noalias` flag as the jit option `_noalias`; returns the option
    to pass to `numba.njit`, or {} (the fallback) where this numba lacks the flag or
    LINKEVO_NUMBA_NOALIAS=0.

    The one change linkevo makes to numba, made once at import of this module: it adds
    the `_noalias` entry to numba's CPU target options (process-wide; a function compiled
    without the option is unaffected). numba has the flag (`Flags.noalias`, which its
    parfor lowering sets on the loop bodies it outlines) but maps no decorator option to
    it. With it, LLVM knows no two array arguments of a helper overlap and vectorises
    without run-time overlap checks: measured, 1.2-1.35x evaluations per second, and 1.3x
    per AURORA training step (`algorithms.aurora_kernel`), whose training is most of a
    MAP-AU trial (docs/simulator.md, "Kernel design"). The fallback compiles the same
    code without the flag: equal outputs (`tests/sim/test_noalias_fallback.py`).
    """
    import os

    from numba.core import compiler, cpu, options

    if os.environ.get(NOALIAS_ENV, "1") == "0":
        return {}
    needed = (
        (compiler.Flags, "noalias"),
        (options.TargetOptions, "Mapping"),
        (cpu, "CPUTargetOptions"),
    )
    if not all(hasattr(owner, name) for owner, name in needed):
        return {}
    cpu.CPUTargetOptions._noalias = options.TargetOptions.Mapping("noalias")
    return {"_noalias": True}


NOALIAS = enable_noalias()
"""The jit option of every helper whose array arguments never overlap ({} in the fallback)."""

_BATCH = {"cache": True, "nogil": True, "error_model": "numpy"}
"""For the batch entry points, which allocate their scratch arrays."""
_JIT = {**_BATCH, "_nrt": False, "forceinline": True, **NOALIAS}
"""For the per-linkage helpers. They never allocate, so they are compiled without numba's
reference counting, which otherwise costs two calls per array argument per call. LLVM
inlines them into the batch loops, and their array arguments are `noalias`: no two of them
may overlap in memory while the helper runs (every caller passes distinct scratch and
output arrays; `sim.linkage.evaluating` refuses overlapping outputs). Knowing that, LLVM vectorises
their loops without run-time overlap checks, and inlined they pay no argument passing:
together a quarter of the evaluation's time (docs/simulator.md, "Kernel design")."""
_INLINE = {**_JIT, "inline": "always"}
"""For the small per-sample helpers called inside loops that must vectorise."""

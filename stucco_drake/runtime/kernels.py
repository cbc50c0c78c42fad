"""One set of numerical kernels on every machine, so that a seed gives the same run anywhere.

numpy's BLAS (OpenBLAS) and numpy's own loops each pick CPU-specific kernels when they are
loaded: a machine with AVX-512 runs other matrix products, dot products and exponentials than
one with AVX2 alone, and kernels with and without fused multiply-add round differently. The
closed loop turns one such last-bit difference (in the controller's inverse kinematics, say)
into a different episode within one action, and a grasp can flip on it.

Both libraries read their choice from the environment once, when they load. :func:`pin`, called
by ``import stucco_drake`` before anything imports numpy, sets it:

- OpenBLAS's Haswell kernels (AVX2 and FMA: every x86-64 server CPU since about 2015);
- numpy's dispatched loops capped at x86-64-v3 (AVX2 and FMA: its AVX-512 loops are off);
- one BLAS thread (OpenBLAS splits long dot products by thread count).

Set ``STUCCO_DRAKE_NATIVE_KERNELS=1`` to keep each machine's own choice. When numpy was imported
before ``stucco_drake``, the kernels are already chosen and :func:`status` says so.
"""

from __future__ import annotations

import os
import platform
import sys

NATIVE_SWITCH = "STUCCO_DRAKE_NATIVE_KERNELS"
PINNED = {
    "OPENBLAS_CORETYPE": "Haswell",
    "OPENBLAS_NUM_THREADS": "1",
    # numpy >= 2.4 names its x86 feature groups X86_V*; the AVX512* names cover earlier numpy.
    # numpy ignores names it does not know.
    "NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512F AVX512CD AVX512_KNL AVX512_KNM AVX512_SKX "
    "AVX512_CLX AVX512_CNL AVX512_ICL AVX512_SPR",
}
_REQUIRED_CPU_FLAGS = ("avx2", "fma")


def _cpu_flags() -> set[str] | None:
    """The CPU's feature flags from /proc/cpuinfo (Linux), or None where it cannot be read."""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as info:
            for line in info:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        return None
    return None


def pin() -> str:
    """Sets the kernel choice in ``os.environ`` unless the user opted out, numpy is already
    loaded, or the CPU is not an x86-64 with AVX2 and FMA. Returns :func:`status`."""
    global _STATE
    if _STATE is not None:
        return _STATE
    flags = _cpu_flags() if platform.machine() in ("x86_64", "AMD64") else None
    if os.environ.get(NATIVE_SWITCH, "") not in ("", "0"):
        _STATE = f"native ({NATIVE_SWITCH} is set)"
    elif "numpy" in sys.modules:
        _STATE = "native (numpy was imported before stucco_drake)"
    elif flags is None or not set(_REQUIRED_CPU_FLAGS) <= flags:
        _STATE = "native (not an x86-64 CPU known to have AVX2 and FMA)"
    else:
        os.environ.update(PINNED)
        _STATE = "pinned"
    return _STATE


def status() -> str:
    """'pinned', or 'native (why)': whether seeded runs here match other machines bit for bit."""
    return _STATE or "native (stucco_drake.runtime.kernels.pin was not called)"


_STATE: str | None = None

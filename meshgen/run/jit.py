"""numba, as every compiled kernel of meshgen imports it (design notes §21, "numba's start-up").

numba's CPU target imports ``numba.np.arraymath`` when it loads its first function, compiled or
from the cache, and that module asks at import whether SciPy's BLAS is there
(``numba.np.linalg.ensure_blas``: ``import scipy.linalg``, 0.44 s of a 1.0 s start, most of it
SciPy's array-API shim walking NumPy's lazy submodules). SciPy is one of meshgen's requirements,
so the answer is always yes; ``numba.np.arraymath`` is imported with the probe answering yes
without importing SciPy, just before numba's CPU target first loads its registries (the step that
imports it: ``CPUContext.load_additional_registries``), not when this module is imported: a
process that only loads kernels from the cache without the registries (the quality worker's child,
``meshgen.quality.worker``) never pays for it. A kernel that calls BLAS (none of meshgen's does)
still imports ``scipy.linalg`` when numba compiles it, through ``numba.np.linalg``'s own probe,
which is left as it was.
"""

from __future__ import annotations

import sys

import numba
from numba.core import cpu

__all__ = ["numba"]


def _load_arraymath() -> None:
    """Import ``numba.np.arraymath`` with its BLAS probe answering yes (SciPy is installed: meshgen
    requires it) instead of importing ``scipy.linalg``; the probe is restored afterwards."""
    if "numba.np.arraymath" in sys.modules:
        return
    import numba.np.linalg as _linalg

    if not callable(getattr(_linalg, "ensure_blas", None)):
        return
    probe = _linalg.ensure_blas
    _linalg.ensure_blas = lambda: None
    try:
        import numba.np.arraymath as arraymath
    finally:
        _linalg.ensure_blas = probe
    if getattr(arraymath, "ensure_blas", None) is not probe:
        arraymath.ensure_blas = probe


def _before_the_registries(load_additional_registries):
    """``CPUContext.load_additional_registries`` with ``_load_arraymath`` first."""

    def load(self):
        _load_arraymath()
        return load_additional_registries(self)

    load.meshgen_arraymath_first = True
    return load


if not getattr(cpu.CPUContext.load_additional_registries, "meshgen_arraymath_first", False):
    cpu.CPUContext.load_additional_registries = _before_the_registries(cpu.CPUContext.load_additional_registries)

"""numba, as every compiled kernel of meshgen imports it (design notes §21, "numba's start-up").

numba's CPU target imports ``numba.np.arraymath`` when it loads its first function, compiled or
from the cache, and that module asks at import whether SciPy's BLAS is there
(``numba.np.linalg.ensure_blas``: ``import scipy.linalg``, 0.44 s of a 1.0 s start, most of it
SciPy's array-API shim walking NumPy's lazy submodules). SciPy is one of meshgen's requirements,
so the answer is always yes; :data:`numba` is imported here with that module loaded while the
probe answers yes without importing SciPy. A kernel that calls BLAS (none of meshgen's does)
still imports ``scipy.linalg`` when numba compiles it, through ``numba.np.linalg``'s own probe,
which is left as it was.
"""

from __future__ import annotations

import sys

import numba
import numba.np.linalg as _linalg

__all__ = ["numba"]


def _load_arraymath() -> None:
    """Import ``numba.np.arraymath`` with its BLAS probe answering yes (SciPy is installed: meshgen
    requires it) instead of importing ``scipy.linalg``; the probe is restored afterwards."""
    if "numba.np.arraymath" in sys.modules or not callable(getattr(_linalg, "ensure_blas", None)):
        return
    probe = _linalg.ensure_blas
    _linalg.ensure_blas = lambda: None
    try:
        import numba.np.arraymath as arraymath
    finally:
        _linalg.ensure_blas = probe
    if getattr(arraymath, "ensure_blas", None) is not probe:
        arraymath.ensure_blas = probe


_load_arraymath()

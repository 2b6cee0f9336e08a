"""numba's start-up (``meshgen.run.jit``): the first kernel loads without importing SciPy's
linear algebra, and numba's own BLAS probe is left answering as it did."""

from __future__ import annotations

import subprocess
import sys

PROBE = """
import sys
import numpy as np
from meshgen.quality.compiled import finite_extent
low, high, nonfinite = finite_extent(np.array([[0.0, 1.0, 2.0], [3.0, -1.0, 5.0], [np.nan, 9.0, 9.0]]))
assert list(low) == [0.0, -1.0, 2.0] and list(high) == [3.0, 1.0, 5.0] and nonfinite == 1, (low, high, nonfinite)
print("scipy.linalg" in sys.modules)
import numba.np.arraymath as arraymath
import numba.np.linalg as linalg
print(arraymath._HAVE_BLAS, arraymath.ensure_blas is linalg.ensure_blas, linalg.ensure_blas.__module__)
linalg.ensure_blas()  # the real probe: imports scipy.linalg
print("scipy.linalg" in sys.modules)
"""


def test_the_first_kernel_loads_without_scipy_linalg_and_the_probe_is_restored():
    done = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, check=True)
    before, state, after = done.stdout.split("\n")[:3]
    assert before == "False"  # numba's import-time probe did not import scipy.linalg
    assert state == "True True numba.np.linalg"  # BLAS known present (SciPy is a requirement), probe restored
    assert after == "True"


def test_a_kernel_that_calls_blas_still_compiles():
    """np.dot of two float vectors goes to BLAS in numba: compiled after the deferred probe, it
    imports scipy.linalg's cython BLAS then and gives the product."""
    code = (
        "import numpy as np, meshgen.run.jit\n"
        "from numba import njit\n"
        "f = njit(lambda a, b: np.dot(a, b))\n"
        "print(f(np.arange(3.0), np.arange(3.0)))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert float(done.stdout) == 5.0


# The quality worker's child (``meshgen.quality.worker._numba_without_extras``): every kernel of a
# 3D report from numba's cache, and what that start leaves out; then a kernel in no cache.
CACHE_ALONE = """
import sys
import numpy as np
from meshgen.quality import worker
worker._numba_without_extras()
worker.load_compiled_kernels(3)
print("numba.np.arraymath" in sys.modules, "numba.np.linalg" in sys.modules, sys.modules.get("yaml", "absent"))
from numba import njit
twice = njit(lambda a: a.sum() * 2.0)
print(twice(np.arange(4.0)), "numba.np.arraymath" in sys.modules)
"""


def test_the_worker_loads_kernels_from_the_cache_without_the_registries_and_still_compiles(tmp_path):
    """The first run fills numba's cache where it is empty (a fresh checkout); the second loads
    every kernel from it without numba's registries, ``numba.np.arraymath`` or PyYAML (no
    ``.numba_config.yaml`` in its folder), and a kernel that is in no cache compiles, the
    registries loaded then."""
    run = [sys.executable, "-c", CACHE_ALONE]
    subprocess.run(run, capture_output=True, text=True, check=True, cwd=tmp_path)
    done = subprocess.run(run, capture_output=True, text=True, check=True, cwd=tmp_path)
    loaded, compiled = done.stdout.strip().splitlines()[-2:]
    assert loaded == "False False None"
    assert compiled == "12.0 True"

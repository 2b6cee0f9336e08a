"""Per-cell metrics of a structured node array (n1+1, n2+1[, n3+1], dim): the compiled kernels of
``meshgen.quality.compiled`` read corners and face neighbours straight from the array.

Small meshes take the NumPy kernels of ``meshgen.quality.numpy_kernels`` instead
(``kernels="auto"``): importing numba and loading the compiled kernels from its cache costs about
a second, NumPy needs less than that for ``NUMPY_CELLS`` cells. Both agree to 1e-12 (tested); the
choice depends on the mesh's size alone, never on what the process loaded before, so one mesh
always gets the same report, to the last bit."""

from __future__ import annotations

import numpy as np

from meshgen.errors import MeshgenError
from meshgen.quality import numpy_kernels
from meshgen.quality.kernels import DEGENERATE_TOLERANCE, METRICS, WORST
from meshgen.run.limits import MAX_COORDINATE

__all__ = [
    "NUMPY_CELLS",
    "apply_degenerate",
    "cell_metrics",
    "check_node_array",
    "degenerate_tolerance",
    "load_compiled_kernels",
    "orientation_2d",
    "structured_metrics",
    "use_compiled",
]

NUMPY_CELLS = 500_000  # below: the NumPy kernels (break-even with a fresh numba import about 9e5)


def use_compiled(cells: int, kernels: str = "auto") -> bool:
    """Whether ``cells`` cells take the compiled kernels: ``kernels`` "compiled", "numpy", or "auto"
    (compiled from ``NUMPY_CELLS`` cells up)."""
    if kernels not in ("auto", "compiled", "numpy"):
        raise ValueError(f"kernels must be auto, compiled or numpy, not {kernels!r}")
    if kernels == "auto":
        return cells >= NUMPY_CELLS
    return kernels == "compiled"


def load_compiled_kernels() -> None:
    """Import numba and load the first compiled kernel from its cache (numba's one-off set-up, most
    of a second), e.g. on a thread while a large mesh is read."""
    from meshgen.quality.compiled import finite_extent

    finite_extent(np.zeros((1, 3)))


def check_node_array(X) -> np.ndarray:
    X = np.asarray(X, dtype=float)
    if X.ndim not in (3, 4) or X.shape[-1] != X.ndim - 1 or min(X.shape[:-1]) < 2:
        raise MeshgenError(f"node array must have shape (n1+1, n2+1[, n3+1], dim) with >= 2 nodes per axis, got {X.shape}")
    return X


def degenerate_tolerance(points, kernels: str = "auto") -> tuple[float, int]:
    """Degenerate-edge length and the number of non-finite nodes of ``points`` (N, dim), from the
    finite coordinates' bounding box."""
    points = np.ascontiguousarray(points, dtype=float)
    if use_compiled(len(points), kernels):
        from meshgen.quality.compiled import finite_extent
    else:
        finite_extent = numpy_kernels.finite_extent
    low, high, nonfinite = finite_extent(points)
    if np.all(np.isfinite(low)):
        largest = max(float(np.abs(low).max()), float(np.abs(high).max()))
        if largest > MAX_COORDINATE:
            raise MeshgenError(f"coordinates reach {largest:.3g}, beyond {MAX_COORDINATE:g}: lengths and volumes would overflow")
    return box_tolerance(low, high), int(nonfinite)


def box_tolerance(low, high) -> float:
    """The degenerate-edge length of a bounding box (per component min ``low``, max ``high``):
    ``DEGENERATE_TOLERANCE`` times its diagonal; 0 when no node is finite (``low`` inf)."""
    if not all(np.isfinite(v) for v in low):
        return 0.0
    return DEGENERATE_TOLERANCE * float(np.sqrt(sum(float(h - lo) ** 2 for lo, h in zip(low, high))))


def signed_area_2d(X) -> float:
    """The quads' total signed area (diagonal cross products, NaN cells left out) of the 2D node
    array ``X`` (n1, n2, 2)."""
    d1 = X[1:, 1:] - X[:-1, :-1]
    d2 = X[:-1, 1:] - X[1:, :-1]
    return float(np.nansum(d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0]))


def orientation_2d(X) -> float:
    """+1 if ``signed_area_2d`` of the 2D node array ``X`` is >= 0, else -1."""
    return 1.0 if signed_area_2d(X) >= 0.0 else -1.0


def apply_degenerate(metrics: dict, degenerate: np.ndarray) -> None:
    if not degenerate.any():
        return
    for name, worst in WORST.items():
        metrics[name][degenerate] = worst
    sj = metrics["scaled_jacobian"]
    sj[degenerate] = np.minimum(np.where(np.isfinite(sj[degenerate]), sj[degenerate], 0.0), 0.0)


def structured_metrics(X, tolerance=None, orientation=None, cells=None, kernels: str = "auto"):
    """Per-cell metrics (C order of cells), the degenerate mask and info (non-finite nodes) of node
    array ``X``.

    ``tolerance`` (degenerate-edge length) and ``orientation`` (2D: +1 or -1) default to those of
    ``X`` itself; a block of a larger mesh passes the whole mesh's, so its cells get the values they
    get in the whole. ``cells``: per axis a slice of the cells to evaluate (default all); the others
    serve as face neighbours only. ``kernels``: see ``use_compiled`` (a block of cells always
    takes the compiled ones)."""
    X = np.ascontiguousarray(check_node_array(X))
    dim = X.shape[-1]
    cell_shape = tuple(n - 1 for n in X.shape[:-1])
    nonfinite = None
    if cells is None and not use_compiled(int(np.prod(cell_shape)), kernels):
        if tolerance is None:
            tolerance, nonfinite = degenerate_tolerance(X.reshape(-1, dim), kernels="numpy")
        if dim == 2 and orientation is None:
            orientation = orientation_2d(X)
        metrics, degenerate = numpy_kernels.numpy_cell_metrics(X, tolerance, orientation)
        return metrics, degenerate, {"nonfinite_nodes": nonfinite}
    from meshgen.quality import compiled, compiled_quad

    if tolerance is None:
        tolerance, nonfinite = degenerate_tolerance(X.reshape(-1, dim), kernels="compiled")
    if cells is None:
        cells = tuple(slice(0, n) for n in cell_shape)
    first = tuple(int(s.start) for s in cells)
    last = tuple(int(s.stop) for s in cells)
    shape = tuple(b - a for a, b in zip(first, last))
    n_cells = int(np.prod(shape))
    out = np.empty((len(METRICS), n_cells))
    degenerate = np.empty(n_cells, dtype=bool)
    if n_cells:
        if dim == 3:
            compiled.structured_hex(X, first, last, float(tolerance), out, degenerate)
        else:
            if orientation is None:
                orientation = orientation_2d(X)
            compiled_quad.structured_quad(X, first, last, float(tolerance), float(orientation), out, degenerate)
    metrics = dict(zip(METRICS, out))
    apply_degenerate(metrics, degenerate)
    return metrics, degenerate, {"nonfinite_nodes": nonfinite}


def cell_metrics(X) -> dict[str, np.ndarray]:
    """The seven per-cell metrics of node array ``X`` (shape ``(n1+1, n2+1[, n3+1], dim)``).

    Returns a dict keyed by ``METRICS``, each an array of length n1*n2[*n3] in C order of the
    cells (i, j[, k]), float64. Angles and non-orthogonality in degrees.
    """
    return structured_metrics(X)[0]

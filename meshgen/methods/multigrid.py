"""The one-grid multigrid of the elliptic solver (``meshgen.methods.elliptic``): the discrete
Winslow equations of ``meshgen.methods.winslow`` solved for the interior nodes of one structured
grid by nonlinear multigrid, boundary nodes fixed on the exact boundary, TFI as the initial guess.
A block set runs the same cycles on every block (``meshgen.methods.multigrid_set``).

Method (why: point-Jacobi needs ~n^2 sweeps, about 10^4 at 100^3 cells):

- Full approximation scheme (FAS): multigrid applied to the nonlinear equations N(r) = 0
  directly. On each grid, relaxation smooths the error; the smooth remainder is corrected from
  the next coarser grid, which solves N_H(r_H) = N_H(I r_h) + I' (f_h - N_h(r_h)) (I: solution
  restriction, I': residual restriction) and hands back r_h += P (r_H - I r_h). Every grid uses
  the same Winslow discretisation. V(1,1) cycles.
- Relaxation: one approximate-factorisation (line-ADI) step of the frozen-coefficient equations
  per sweep (see ``smooth``): point Jacobi stalls at a rate of ~0.7 per cycle on stretched cells
  (operator anisotropy = aspect ratio squared), the line step keeps ~0.3.
- Full-multigrid start: the coarsest grid is solved first and each finer grid starts from its own
  TFI mesh plus the interpolated departure of the coarser solution from the coarser TFI mesh, so
  the finest grid starts near its discretisation error.
- Anderson mixing of the last few cycles (``AndersonMixing``) removes the few modes the cycles
  reduce slowly: near the parametric corners that the boundary maps to smooth boundary points
  (the semicylinder's arc), cells are nearly flat for every method and converge last.

Grids: each coarser grid halves an axis's cell count when it is even (nested: every second node)
and takes ceil(n/2) cells when it is odd (nodes interpolated from the finer grid's parametric
coordinates in index space: not nested), down to ``COARSEST_CELLS``; an axis that is already
small stops coarsening while the others go on, and so does, for a while, an axis along which the
cells are much longer than across (see ``hierarchy``). Transfers are tensor products of 1D linear
interpolation in the parametric coordinate: prolongation P coarse to fine, solution restriction I
fine to coarse (injection on nested grids), residual restriction I' = P's transpose with rows
scaled to sum 1 (full weighting on nested grids), so odd sizes need no special case.

Convergence: after each finest-grid cycle, ``update`` is the largest node displacement the cycle
made relative to the geometry's characteristic length (the stopping test, ``tol``);
``residual`` is the largest displacement a point-Jacobi step of the current residual would make,
relative to the same length.
"""

from __future__ import annotations

import time

import numpy as np

from meshgen.methods.anderson import ANDERSON_DEPTH, AndersonMixing
from meshgen.methods.winslow import centre_coefficient, component_array, node_array, stencils, winslow_operator

__all__ = [
    "COARSEST_CELLS",
    "COARSEST_SWEEPS",
    "COMPILED_NODES",
    "DAMPING",
    "DEFAULT_MAX_ITER",
    "DEFAULT_TOL",
    "POST_SMOOTHING",
    "PRE_SMOOTHING",
    "SEMI_COARSENING",
    "Level",
    "along_axes",
    "banded",
    "coarser_coordinates",
    "hierarchy",
    "jacobi_residual",
    "progress_fraction",
    "interpolation_matrix",
    "largest_node_norm",
    "smooth",
    "solve_lines",
    "solve_winslow",
    "stencil_weights",
    "uses_kernels",
    "v_cycle",
]

DEFAULT_TOL = 1e-6  # largest node update per cycle, relative to the characteristic length
DEFAULT_MAX_ITER = 100  # finest-grid cycles; 5-10 are typical
COARSEST_CELLS = 4  # coarsen an axis while it has more cells than this
SEMI_COARSENING = 0.1  # coarsen only axes at least this strongly coupled relative to the strongest
PRE_SMOOTHING, POST_SMOOTHING = 1, 1  # relaxation sweeps before and after the coarse-grid correction
DAMPING = 1.0  # of the line-ADI step; damping (0.85) gave more cycles in every case tried
COMPILED_NODES = 50**3  # grids with at least this many nodes run the compiled kernels (3D; see uses_kernels)
COARSEST_SWEEPS = 40  # relaxation sweeps that solve the coarsest grid (at most 3 interior nodes per axis)


def coarser_coordinates(t: np.ndarray) -> np.ndarray:
    """Parametric node coordinates of the next coarser grid along one axis (see module docstring)."""
    n = len(t) - 1
    if n % 2 == 0:
        return t[::2]
    coarse = (n + 1) // 2
    return np.interp(np.linspace(0.0, n, coarse + 1), np.arange(n + 1), t)


def interpolation_matrix(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Linear interpolation from nodes ``source`` to points ``target`` (both increasing, same
    end points): matrix of shape (len(target), len(source))."""
    cell = np.clip(np.searchsorted(source, target, side="right") - 1, 0, len(source) - 2)
    weight = (target - source[cell]) / (source[cell + 1] - source[cell])
    matrix = np.zeros((len(target), len(source)))
    rows = np.arange(len(target))
    matrix[rows, cell] = 1.0 - weight
    matrix[rows, cell + 1] += weight
    return matrix


def along_axes(matrices, F: np.ndarray) -> np.ndarray:
    """Apply one matrix per spatial axis to a component-first array F (dim, n1, n2[, n3]):
    ``F'[c, i, j, k] = sum M1[i, p] M2[j, q] M3[k, s] F[c, p, q, s]``."""
    for axis, matrix in enumerate(matrices, start=1):
        shape = F.shape
        if axis == F.ndim - 1:
            F = F.reshape(-1, shape[axis]) @ matrix.T
        else:  # a stack of matrix products, no transposed copies
            F = matrix @ F.reshape(int(np.prod(shape[:axis])), shape[axis], -1)
        F = F.reshape(shape[:axis] + (matrix.shape[0],) + shape[axis + 1 :])
    return F


class Level:
    """One grid of the multigrid hierarchy: its stencils and the transfers to the next coarser one.

    ``compiled``: whether this grid's relaxation, residual and transfers run as the numba kernels of
    ``meshgen.methods.winslow_compiled`` (3D only; ``hierarchy`` chooses them for every grid when the finest
    is large, see ``uses_kernels``), else as NumPy array operations; ``weights`` holds the kernels'
    stencil weights and ``bands`` the transfers as (columns, values) of their non-zeros per row.
    """

    def __init__(self, coords, coarse_coords=None, compiled: bool = False):
        self.grid = stencils(coords)
        self.interior = (slice(None),) + (slice(1, -1),) * len(coords)
        self.compiled = bool(compiled) and len(coords) == 3
        if self.compiled:
            self.weights = stencil_weights(self.grid)
        if coarse_coords is not None:
            self.prolong = [interpolation_matrix(tc, t) for t, tc in zip(coords, coarse_coords)]
            self.restrict_solution = [interpolation_matrix(t, tc) for t, tc in zip(coords, coarse_coords)]
            self.restrict_residual = [p.T / p.T.sum(axis=1, keepdims=True) for p in self.prolong]
            if self.compiled:
                self.bands = {
                    name: [banded(m) for m in getattr(self, name)]
                    for name in ("prolong", "restrict_solution", "restrict_residual")
                }

    def transfer(self, name: str, F: np.ndarray) -> np.ndarray:
        """The transfer ``name`` (prolong, restrict_solution, restrict_residual) applied to F (dim, ...)."""
        if not self.compiled:
            return along_axes(getattr(self, name), F)
        from meshgen.methods import winslow_compiled

        for axis, (columns, values) in enumerate(self.bands[name]):
            F = winslow_compiled.transfer(F, columns, values, axis)
        return F

    def defect(self, R: np.ndarray, f) -> np.ndarray:
        """f - N(R) (``f`` None: zero) at the interior nodes, zero on the boundary: shaped as R."""
        if self.compiled:
            from meshgen.methods import winslow_compiled

            return winslow_compiled.defect(R, f, self.weights)
        residual, _ = winslow_operator(R, self.grid)
        full = np.zeros_like(R)
        full[self.interior] = -residual if f is None else f - residual
        return full

    def operator(self, R: np.ndarray):
        """Normalised Winslow residual and axial coefficients of R on this grid (``winslow_operator``)."""
        if not self.compiled:
            return winslow_operator(R, self.grid)
        from meshgen.methods import winslow_compiled

        return winslow_compiled.operator(R, *self.weights)


def uses_kernels(coords) -> bool:
    """Whether the multigrid hierarchy of a grid with these parametric coordinates runs the compiled
    kernels: 3D and at least ``COMPILED_NODES`` nodes. The kernels take a fifth to a quarter of the
    NumPy code's CPU time at every size, but importing numba and loading their cached code costs a
    fresh process about 0.7 s of CPU; a whole solve repays that from about 50^3 nodes (NumPy 0.9 s
    there, 0.5 s at 40^3)."""
    return len(coords) == 3 and int(np.prod([len(t) for t in coords])) >= COMPILED_NODES


def stencil_weights(grid) -> tuple:
    """The six (3, n_a - 1) weight arrays of the compiled kernels: first-derivative (minus, centre,
    plus) per axis, then second-derivative, at each interior index (``meshgen.methods.winslow.Stencils``)."""
    arrays = []
    for kind in (grid.first, grid.second):
        for axis, weights in enumerate(kind):
            inner = len(grid.coords[axis]) - 2
            arrays.append(np.ascontiguousarray(np.stack([np.broadcast_to(np.ravel(w), (inner,)) for w in weights])))
    return tuple(arrays)


def banded(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A transfer matrix (rows, columns) as its non-zeros per row: columns and values, both
    (rows, most non-zeros in a row), rows with fewer padded with value 0."""
    rows, cols = np.nonzero(matrix)  # row-major: each row's non-zeros together, in order
    starts = np.searchsorted(rows, np.arange(matrix.shape[0]))
    slot = np.arange(len(rows)) - starts[rows]
    width = max(int(slot.max()) + 1 if len(rows) else 1, 1)
    columns = np.zeros((matrix.shape[0], width), dtype=np.int64)
    values = np.zeros((matrix.shape[0], width))
    columns[rows, slot] = cols
    values[rows, slot] = matrix[rows, cols]
    return columns, values


def hierarchy(coords, axis_weights=None, compiled: bool | None = None) -> list[Level]:
    """Levels from the given grid (first) to the coarsest (last); ``compiled``: whether they run
    the compiled kernels (3D only; default: ``uses_kernels(coords)``).

    ``axis_weights``: the typical size of A_aa (the weight of r_aa) per axis; the coupling
    strength of axis a on a grid is then A_aa / h_a^2. An axis is coarsened only while it has more
    than ``COARSEST_CELLS`` cells and its strength is at least ``SEMI_COARSENING`` times the
    strongest coarsenable axis's. Cells much longer along one axis than along the other two (the
    ``canal`` tube: 16 cycles instead of 5 at 48^3) couple strongly in two directions, which the
    line relaxation does not resolve; coarsening only those two weakens their coupling by 4 per
    grid until the third axis catches up.
    """
    chain = [tuple(np.asarray(t, dtype=float) for t in coords)]
    weights = np.ones(len(coords)) if axis_weights is None else np.asarray(axis_weights, dtype=float)
    while True:
        cells = np.array([len(t) - 1 for t in chain[-1]])
        strength = weights * cells.astype(float) ** 2
        coarsenable = cells > COARSEST_CELLS
        if not coarsenable.any():
            break
        strongest = strength[coarsenable].max()
        coarsen = coarsenable & (strength >= SEMI_COARSENING * strongest)
        chain.append(tuple(coarser_coordinates(t) if c else t for t, c in zip(chain[-1], coarsen)))
    compiled = uses_kernels(coords) if compiled is None else compiled
    return [Level(c, chain[i + 1] if i + 1 < len(chain) else None, compiled) for i, c in enumerate(chain)]


def largest_node_norm(D: np.ndarray) -> float:
    """Largest Euclidean norm over the nodes of a component-first array (dim, ...)."""
    return float(np.sqrt(np.max(np.einsum("c...,c...->...", D, D)))) if D.size else 0.0


def solve_lines(sub: np.ndarray, sup: np.ndarray, rhs: np.ndarray, axis: int) -> np.ndarray:
    """Solve the tridiagonal systems ``x[i] + sub[i] x[i-1] + sup[i] x[i+1] = rhs[i]`` along every
    grid line parallel to ``axis`` at once (Thomas algorithm, vectorised across the lines).

    ``sub``, ``sup``: scalar fields of the interior nodes, shape (m1, m2[, m3]); ``rhs``: shape
    (dim, m1, m2[, m3]), one system per component with the same matrix. Line ends couple to the
    fixed boundary nodes, whose correction is zero, so those couplings drop out.
    """
    # The loop runs along the lines: make each step's slice contiguous (a copy, cheap next to strided steps).
    sub, sup = (np.ascontiguousarray(np.moveaxis(c, axis, 0)) for c in (sub, sup))
    rhs = np.ascontiguousarray(np.moveaxis(rhs, axis + 1, 0))
    pivot = np.empty_like(sub)
    x = np.empty_like(rhs)
    pivot[0], x[0] = 1.0, rhs[0]
    for i in range(1, len(pivot)):
        factor = sub[i] / pivot[i - 1]
        pivot[i] = 1.0 - factor * sup[i - 1]
        x[i] = rhs[i] - factor * x[i - 1]
    x[-1] /= pivot[-1]
    for i in range(len(pivot) - 2, -1, -1):
        x[i] = (x[i] - sup[i] * x[i + 1]) / pivot[i]
    return np.moveaxis(x, 0, axis + 1)


def smooth(R: np.ndarray, f, level: Level, sweeps: int) -> float:
    """Relaxation sweeps of N(R) = f on the interior nodes of R (in place); ``f`` is None (zero) or
    an interior array (dim, n1-1, ...). Returns the largest Jacobi step (N(R) - f) / D of the
    last sweep's starting state, a cheap measure of the residual.

    Each sweep linearises N with frozen coefficients, J = -D + sum_a C_a (D: the centre
    coefficient, C_a: the couplings to the two neighbours along axis a), and takes the
    approximate-factorisation (ADI) step, times ``DAMPING``,

        delta = (I - D^-1 C_dim)^-1 ... (I - D^-1 C_1)^-1 D^-1 (N(R) - f),

    an approximate factorisation of the Newton step (D - sum_a C_a)^-1 (N(R) - f) that costs one
    residual and one tridiagonal solve per axis. Unlike point Jacobi it solves the strong couplings of
    stretched cells exactly along whichever axis they lie (the semicylinder's cells are about
    twice as long in xi and zeta as in eta, i.e. 4-6 times more strongly coupled in eta), which
    keeps the multigrid rate near 0.3 per cycle instead of 0.7.
    """
    grid = level.grid
    jacobi_step = np.inf
    if level.compiled:
        from meshgen.methods import winslow_compiled

        for sweep in range(sweeps):
            jacobi_step = winslow_compiled.relax(R, f, level.weights, DAMPING, sweep == sweeps - 1)
        return jacobi_step
    for sweep in range(sweeps):
        residual, axial = winslow_operator(R, grid)
        if f is not None:
            residual -= f
        centre = centre_coefficient(axial, grid)
        step = residual / centre
        if sweep == sweeps - 1:
            jacobi_step = largest_node_norm(step)
        for axis, (coupling, (minus, _, plus)) in enumerate(zip(axial, grid.second)):
            scale = coupling / centre
            step = solve_lines(-minus * scale, -plus * scale, step, axis)
        R[level.interior] += DAMPING * step
    return jacobi_step


def v_cycle(levels: list[Level], index: int, R: np.ndarray, f) -> float:
    """One FAS V-cycle for N(R) = f on ``levels[index]`` (R updated in place). Returns the largest
    Jacobi step at the start of the last relaxation sweep (see ``smooth``)."""
    level = levels[index]
    if index == len(levels) - 1:
        return smooth(R, f, level, COARSEST_SWEEPS)
    smooth(R, f, level, PRE_SMOOTHING)
    coarse = levels[index + 1]
    R_coarse_start = level.transfer("restrict_solution", R)
    full_residual = level.defect(R, f)
    coarse_f, _ = coarse.operator(R_coarse_start)
    coarse_f += level.transfer("restrict_residual", full_residual)[coarse.interior]
    R_coarse = R_coarse_start.copy()
    v_cycle(levels, index + 1, R_coarse, coarse_f)
    R += level.transfer("prolong", R_coarse - R_coarse_start)
    return smooth(R, f, level, POST_SMOOTHING)


def progress_fraction(first: float, update: float, tol: float) -> float:
    """How far a solve is, in [0, 1]: the progress of log(update) from the first cycle's towards ``tol``."""
    done = 1.0 if update < tol else np.log(first / update) / np.log(first / tol)
    return float(np.clip(done, 0.0, 1.0))


def jacobi_residual(level: Level, R: np.ndarray, length: float) -> float:
    """The largest Jacobi step of the Winslow equations on ``level`` at the component-first node
    array ``R`` (dim, ...), relative to ``length``: ``solve_winslow``'s ``final_residual``."""
    step, axial = level.operator(R)
    return largest_node_norm(step / centre_coefficient(list(axial), level.grid)) / length


def solve_winslow(
    X0: np.ndarray, coords, tol: float = DEFAULT_TOL, max_iter: int = DEFAULT_MAX_ITER, length: float = 1.0, progress=None
):
    """Solve the discrete Winslow equations for the interior nodes of ``X0``.

    ``X0``: initial node array (n1+1, n2+1[, n3+1], dim), float64; its boundary nodes are kept.
    ``coords``: the parametric node coordinates per axis (1D arrays of n_a + 1 values, >= 3).
    ``tol``: stop when a finest-grid cycle moves no node by more than ``tol * length``.
    ``max_iter``: most finest-grid cycles.
    ``progress``: optional callable ``progress(done, **figures)`` after each cycle, ``done`` in
    [0, 1] the progress of log(update) from the first cycle's towards ``tol``, ``figures`` the
    cycle number, update and residual.
    Returns ``(X, info)``: the node array and a dict with ``iterations`` (finest-grid cycles),
    ``final_update`` and ``final_residual`` (both relative to ``length``), ``converged``,
    ``seconds`` and ``levels`` (the grids' cell counts, finest first).
    """
    start = time.perf_counter()
    starts = [component_array(X0)]
    _, axial = Level(coords, compiled=uses_kernels(coords)).operator(starts[0])
    levels = hierarchy(coords, [np.median(a) for a in axial])
    for level in levels[:-1]:
        starts.append(level.transfer("restrict_solution", starts[-1]))

    # Full-multigrid start: each level begins from its own initial mesh plus the interpolated
    # departure of the coarser solution from the coarser initial mesh, then gets one V-cycle.
    R = starts[-1].copy()
    smooth(R, None, levels[-1], COARSEST_SWEEPS)
    for index in range(len(levels) - 2, -1, -1):
        R = starts[index] + levels[index].transfer("prolong", R - starts[index + 1])
        if index > 0:
            v_cycle(levels, index, R, None)
    del starts  # memory: the finest start alone is as large as the mesh

    acceleration = AndersonMixing(ANDERSON_DEPTH)
    update, first_update, iterations = np.inf, None, 0
    while True:
        before = R.copy()
        residual = v_cycle(levels, 0, R, None) / length
        iterations += 1
        previous_update, update = update, largest_node_norm(R - before) / length
        if not np.isfinite(update):  # diverged: hand back the last finite state
            R = before
            break
        first_update = first_update or update
        if progress is not None:
            progress(progress_fraction(first_update, update, tol), cycle=iterations, update=update, residual=residual)
        if update < tol or iterations >= max_iter:
            break
        if update > previous_update:  # the mixing made things worse: start it afresh
            acceleration.restart()
        R = acceleration.next_iterate(before, R)

    residual = jacobi_residual(levels[0], R, length)
    info = {
        "solver": "nonlinear multigrid (FAS V(1,1) cycles, line-ADI relaxation, full-multigrid start, Anderson mixing)",
        "iterations": iterations,
        "final_update": float(update),
        "final_residual": float(residual),
        "tol": float(tol),
        "converged": bool(update < tol),
        "seconds": time.perf_counter() - start,
        "levels": [[len(t) - 1 for t in level.grid.coords] for level in levels],
    }
    return node_array(R), info

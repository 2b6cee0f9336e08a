"""Newton's method for a small sparse nonlinear system F(x) = 0 over nodes (x: (count, dim)), the
direct solve of the block-set multigrid's coarsest level (``meshgen.methods.multigrid_set``).

The Jacobian is a finite-difference one: the columns (node, component) are grouped by a colouring
of the nodes in which no two nodes of a colour enter a common equation (``colour_nodes``), so one
residual evaluation per colour and component gives every column of that colour. It is factored
once (``scipy.sparse.linalg.splu``) and reused by later solves (the equations change only through
their right-hand side and the state they are linearised at), refreshed where a step shrinks by
less than ``REFRESH_RATIO``: Newton where it matters, defect correction at one residual and one
back-substitution per step elsewhere.
"""

from __future__ import annotations

import numpy as np

__all__ = ["REFRESH_RATIO", "LaggedNewton", "colour_nodes"]

REFRESH_RATIO = 0.5  # a step longer than this times the previous one refactors the Jacobian
FD_STEP = 1e-7  # finite-difference step, relative to the characteristic length


def colour_nodes(pattern, start: np.ndarray | None = None, seed: int = 0) -> np.ndarray:
    """(count,) a colour per node such that no equation (row of the boolean ``pattern``
    (count, count): equation i reads node j) reads two nodes of one colour. ``start``: colours to
    keep where they are already valid (a structured grid's index modulo 3 per axis). The nodes in
    conflict are recoloured by Jones-Plassmann: in each round those heavier (random weights)
    than all their uncoloured conflicting nodes take the smallest colour none of their coloured
    conflicts has."""
    import scipy.sparse as sp  # scipy on first use: `meshgen mesh --help` imports this module

    pattern = sp.csr_matrix(pattern, dtype=float)
    conflict = (pattern.T @ pattern).tocsr()
    conflict.setdiag(0.0)
    conflict.eliminate_zeros()
    conflict.data[:] = 1.0
    count = conflict.shape[0]
    colours = np.full(count, -1) if start is None else np.asarray(start).copy()
    if start is not None:  # uncolour one node of every pair in conflict: the later one
        upper = sp.triu(conflict).tocoo()
        clash = colours[upper.row] == colours[upper.col]
        colours[upper.col[clash]] = -1
    weight = np.random.default_rng(seed).permutation(count) + 1.0
    while (colours < 0).any():
        todo = np.flatnonzero(colours < 0)
        among = conflict[todo][:, todo].tocsr()  # the uncoloured ones' conflicts among themselves
        weighed = among.multiply(weight[todo][None, :]).tocsr()
        heaviest = np.zeros(len(todo))
        rows = np.diff(weighed.indptr) > 0
        heaviest[rows] = np.maximum.reduceat(weighed.data, weighed.indptr[:-1][rows]) if weighed.nnz else 0.0
        pick = todo[weight[todo] > heaviest]
        done = np.flatnonzero(colours >= 0)
        used = np.zeros((count, colours.max() + 2))
        used[done, colours[done]] = 1.0
        colours[pick] = np.argmin(conflict[pick] @ used > 0, axis=1)
    return colours


class LaggedNewton:
    """Newton iterations for F(x) = 0 with a finite-difference Jacobian over the sparsity
    ``pattern`` (count, count) (equation i reads node j), kept between solves.
    ``length``: the characteristic length, the unit of the steps and of ``solve``'s ``tol``;
    ``colours``: a first guess at ``colour_nodes``'."""

    def __init__(self, pattern, length: float, colours: np.ndarray | None = None):
        import scipy.sparse as sp

        self.pattern = sp.coo_matrix(pattern)
        self.colours = colour_nodes(pattern, colours)
        self.length = length
        self.factor = None
        self.factorisations = 0

    def refactor(self, residual, values: np.ndarray, base: np.ndarray) -> None:
        """The Jacobian of ``residual`` at ``values`` (its residual ``base``), factored."""
        count, dim = values.shape
        h = FD_STEP * self.length
        colours = self.colours.max() + 1
        columns = np.empty((colours, dim, count, dim))  # per colour and component: dF / dx
        for colour in range(colours):  # a loop over colours, not nodes
            nodes = self.colours == colour
            for component in range(dim):
                moved = values.copy()
                moved[nodes, component] += h
                columns[colour, component] = (residual(moved) - base) / h
        row, col = self.pattern.row, self.pattern.col
        pairs = [(a, b) for a in range(dim) for b in range(dim)]
        data = np.concatenate([columns[self.colours[col], b, row, a] for a, b in pairs])
        rows = np.concatenate([row * dim + a for a, _ in pairs])
        cols = np.concatenate([col * dim + b for _, b in pairs])
        import scipy.sparse as sp
        import scipy.sparse.linalg as spla

        jacobian = sp.csc_matrix((data, (rows, cols)), shape=(count * dim, count * dim))
        self.factor = spla.splu(jacobian)
        self.factorisations += 1

    def solve(self, residual, values: np.ndarray, tol: float, reduction: float, iterations: int) -> np.ndarray | None:
        """x from ``values`` (count, dim) until a step moves no coordinate by more than ``tol``
        times the length or ``reduction`` times the first step, or ``iterations`` steps;
        ``residual``: x (count, dim) -> F(x) (count, dim). None where a step is not finite (a
        folded start: the caller relaxes instead)."""
        values = values.copy()
        previous, first = np.inf, None
        for _ in range(iterations):
            base = residual(values)
            if self.factor is None:
                self.refactor(residual, values, base)
            step = self.factor.solve(base.reshape(-1)).reshape(values.shape)
            values -= step
            size = float(np.abs(step).max())
            if not np.isfinite(size):
                self.factor = None
                return None
            first = size if first is None else first
            if size < max(tol * self.length, reduction * first):
                break
            if size > REFRESH_RATIO * previous:
                self.factor = None
            previous = size
        return values

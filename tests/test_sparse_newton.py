"""The 2D block-set multigrid coarsest level's direct solve (meshgen.methods.sparse_newton, used by
meshgen.methods.multigrid_set): the colouring against the definition (no equation reads two nodes
of a colour), the finite-difference Jacobian against the analytic one of a closed-form system,
Newton against its known root; on the DFG channel (sliding walls on and off) the same discrete solution as the hierarchy relaxed
down to its coarsest grid (DIRECT_NODES 0), in fewer cycles
(with sliding walls)."""

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from meshgen.methods import multigrid_set
from meshgen.methods.sparse_newton import LaggedNewton, colour_nodes


def _grid_pattern(n):
    """A 9-point stencil pattern on an n x n grid plus a few random long-range reads."""
    index = np.arange(n * n).reshape(n, n)
    rows, cols = [], []
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            a = index[max(0, -di) : n - max(0, di), max(0, -dj) : n - max(0, dj)]
            b = index[max(0, di) : n - max(0, -di), max(0, dj) : n - max(0, -dj)]
            rows.append(a.reshape(-1))
            cols.append(b.reshape(-1))
    rng = np.random.default_rng(1)
    rows.append(rng.integers(0, n * n, 20))
    cols.append(rng.integers(0, n * n, 20))
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    return sp.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(n * n, n * n)), index


@pytest.mark.parametrize("structured", [False, True])
def test_no_equation_reads_two_nodes_of_one_colour(structured):
    pattern, index = _grid_pattern(12)
    start = None
    if structured:
        i, j = np.unravel_index(np.arange(index.size), index.shape)
        start = (i % 3) * 3 + j % 3
    colours = colour_nodes(pattern, start)
    coo = pattern.tocoo()
    reads = np.unique(np.stack([coo.row, coo.col], axis=1), axis=0)  # (equation, node) read, once each
    read_colours = np.unique(np.stack([reads[:, 0], colours[reads[:, 1]]], axis=1), axis=0)
    assert len(read_colours) == len(reads)  # as many colours as nodes in every equation
    conflicts = (pattern.T @ pattern).tocsr()
    assert colours.max() + 1 <= np.diff(conflicts.indptr).max()  # at most the largest conflict count (+1, less the node)
    if structured:
        assert colours.max() + 1 < 20  # the 9 grid colours kept but where a random read clashes


def test_newton_finds_the_root_and_its_jacobian_is_the_analytic_one():
    n, dim = 10, 2
    pattern, _ = _grid_pattern(n)
    rng = np.random.default_rng(2)
    A = sp.csr_matrix(pattern.multiply(rng.uniform(-0.1, 0.1, pattern.shape))) + 3.0 * sp.eye(n * n)
    root = rng.normal(size=(n * n, dim))

    def operator(x):  # F_c(x) = A x_c + 0.1 x_c |x|^2, coupled through |x|^2
        return A @ x + 0.1 * x * np.sum(x**2, axis=1, keepdims=True)

    rhs = operator(root)
    solver = LaggedNewton(pattern, length=1.0)
    x = root + 0.3 * rng.normal(size=root.shape)
    solver.refactor(lambda y: operator(y) - rhs, x, operator(x) - rhs)
    # the analytic Jacobian, (node, component) interleaved as the solver orders its unknowns
    rows, cols, data = [], [], []
    Acoo = A.tocoo()
    for c in range(dim):
        rows.append(Acoo.row * dim + c)
        cols.append(Acoo.col * dim + c)
        data.append(Acoo.data)
        for d in range(dim):
            node = np.arange(n * n)
            rows.append(node * dim + c)
            cols.append(node * dim + d)
            data.append(0.1 * ((c == d) * np.sum(x**2, axis=1) + 2.0 * x[:, c] * x[:, d]))
    J = sp.csc_matrix((np.concatenate(data), (np.concatenate(rows), np.concatenate(cols))), shape=(n * n * dim,) * 2)
    v = rng.normal(size=n * n * dim)
    np.testing.assert_allclose(solver.factor.solve(v), spla.spsolve(J, v), rtol=1e-5, atol=1e-5)
    got = solver.solve(lambda y: operator(y) - rhs, x, tol=1e-14, reduction=0.0, iterations=30)
    assert np.abs(got - root).max() < 1e-12
    # a residual that is not finite (a folded cell): None, for the caller to relax instead
    assert solver.solve(lambda y: np.full_like(y, np.nan), x, tol=1e-14, reduction=0.0, iterations=30) is None


@pytest.mark.parametrize("slide", [True, False])
def test_the_direct_coarsest_solve_keeps_the_discrete_solution(slide, monkeypatch):
    from meshgen.geometry.blocks import load_block_set
    from meshgen.methods.elliptic import elliptic_blocks

    block_set = load_block_set("dfg-cylinder", None, (34, 20))
    Xs, info = elliptic_blocks(block_set, tol=1e-11, max_iter=400, slide=slide)
    monkeypatch.setattr(multigrid_set, "DIRECT_NODES", 0)  # relaxed down to the coarsest grid instead
    relaxed, relaxed_info = elliptic_blocks(block_set, tol=1e-11, max_iter=400, slide=slide)
    assert info["converged"] and relaxed_info["converged"]
    # sliding walls: the stacked blocks' weak-axis modes that the coarse levels' sweeps left
    assert info["iterations"] < relaxed_info["iterations"] if slide else info["iterations"] <= relaxed_info["iterations"]
    for X, Y in zip(Xs, relaxed):  # to 1e-9 of the block's shortest grid edge
        shortest = min(np.linalg.norm(np.diff(X, axis=axis), axis=-1).min() for axis in range(2))
        assert np.max(np.linalg.norm(X - Y, axis=-1)) < 1e-9 * shortest

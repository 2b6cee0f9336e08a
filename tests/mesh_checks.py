"""Independent checks of node arrays for the tests (not meshgen.quality: a second computation)."""

import itertools

import numpy as np


def corner_jacobians(X):
    """Jacobian determinant at every corner of every cell of node array X (2D or 3D):
    det of the cell's edge vectors leaving that corner along +i, +j(, +k), each edge
    pointing away from the corner. Shape (2**dim, n1, n2[, n3])."""
    dim = X.shape[-1]
    cells = [n - 1 for n in X.shape[:-1]]
    dets = []
    for corner in itertools.product((0, 1), repeat=dim):
        at = tuple(slice(c, c + n) for c, n in zip(corner, cells))
        edges = []
        for axis in range(dim):
            neighbour = list(at)
            other = 1 - corner[axis]
            neighbour[axis] = slice(other, other + cells[axis])
            edge = X[tuple(neighbour)] - X[at]
            edges.append(edge if corner[axis] == 0 else -edge)
        dets.append(np.linalg.det(np.stack(edges, axis=-1)))
    return np.stack(dets)

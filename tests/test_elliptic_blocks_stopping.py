"""The multi-block elliptic solver's stopping rule measures node updates against each node's local
cell size (meshgen.methods.sliding.local_cell_sizes): the sizes checked against the edges of the
merged unstructured mesh, an independent path (cells' corner lists, not the block arrays)."""

import numpy as np
import pytest

from meshgen.geometry.block_nodes import global_numbering, merged_mesh
from meshgen.geometry.blocks import load_block_set, tfi_blocks
from meshgen.methods.sliding import local_cell_sizes

# Corner pairs of the edges of a quadrilateral and of a hexahedron (VTK corner order).
QUAD_EDGES = [(0, 1), (1, 2), (2, 3), (3, 0)]
HEX_EDGES = QUAD_EDGES + [(4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7)]


@pytest.mark.parametrize("spec, dims", [("pipe", (3, 2, 3)), ("dfg-cylinder", (4, 3))])
def test_local_cell_sizes_are_the_shortest_edge_at_each_node(spec, dims):
    block_set = load_block_set(spec, None, dims)
    Xs = tfi_blocks(block_set)
    numbering, count = global_numbering(block_set)
    sizes = local_cell_sizes(block_set, Xs, numbering, count)
    points, cells, _ = merged_mesh(block_set, Xs)
    expected = np.full(len(points), np.inf)
    for a, b in HEX_EDGES if block_set.dim == 3 else QUAD_EDGES:
        length = np.linalg.norm(points[cells[:, a]] - points[cells[:, b]], axis=1)
        np.minimum.at(expected, cells[:, a], length)
        np.minimum.at(expected, cells[:, b], length)
    # The merged mesh's node order is not the global numbering's: compare node by node by position.
    values = np.empty((count, block_set.dim))
    for X, ids in zip(Xs, numbering):
        values[ids.reshape(-1)] = X.reshape(-1, block_set.dim)
    order = np.lexsort(values.T[::-1].round(12))
    merged_order = np.lexsort(points[:, : block_set.dim].T[::-1].round(12))
    assert np.allclose(values[order], points[merged_order, : block_set.dim], atol=1e-12)
    assert np.allclose(sizes[order], expected[merged_order], rtol=1e-12)

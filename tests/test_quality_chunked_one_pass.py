"""The block-wise report reads each block once (design notes §21, "One pass over a file's blocks").

A block is evaluated with its own degenerate-edge tolerance and orientation, and evaluated again
with the mesh's only when an edge or its orientation says they could differ. Each report is checked
against the whole mesh evaluated in memory by the compiled kernels with the mesh's own tolerance
and orientation: counts, extremes and percentiles (from the sketch of all kept values: merging
sketches is exact) equal, means to rounding. Meshes are built so that the case under test happens,
and the tests check that it did (the phases ``progress`` heard).
"""

import math

import numpy as np
import pytest

from meshgen.formats import write_mesh
from meshgen.quality import METRICS
from meshgen.quality import sketch as sketches
from meshgen.quality.chunked import SECOND_PASS, chunked_report
from meshgen.quality.edges_compiled import shortest_edge_above
from meshgen.quality.structured import structured_metrics

pytest.importorskip("dask")


def expected_report(X):
    """Counts and per-metric figures of ``X`` evaluated whole, in memory, by the compiled kernels."""
    values, degenerate, _ = structured_metrics(X, kernels="compiled")
    inverted = degenerate | ~(values["scaled_jacobian"] > 0.0)
    figures = {"cells": degenerate.size, "degenerate": int(degenerate.sum()), "inverted": int(inverted.sum()), "metrics": {}}
    for name in METRICS:
        kept = values[name][~degenerate]
        low, high = float(kept.min()), float(kept.max())
        sketch = sketches.sketch_of(kept)
        figures["metrics"][name] = {
            "min": low,
            "max": high,
            "p01": sketches.quantile(sketch, 0.01, low, high),
            "p99": sketches.quantile(sketch, 0.99, low, high),
            "mean": float(kept.mean()),
        }
    return figures


def blockwise(source, block_nodes):
    """(report, phases heard) of ``chunked_report``."""
    heard = set()
    report = chunked_report(source, block_nodes=block_nodes, progress=lambda done, total, phase: heard.add(phase))
    return report, heard


def assert_same(report, expected):
    assert report["cells"] == expected["cells"]
    assert report["inverted"]["count"] == expected["inverted"]
    assert report["inverted"]["degenerate"] == expected["degenerate"]
    for name in METRICS:
        mine, theirs = report["metrics"][name], expected["metrics"][name]
        assert [mine[k] for k in ("min", "max", "p01", "p99")] == [theirs[k] for k in ("min", "max", "p01", "p99")], name
        assert mine["mean"] == pytest.approx(theirs["mean"], rel=1e-12, abs=1e-14), name


def box_grid(shape, far=None):
    """A distorted box grid of node ``shape`` (3D), its last k plane moved to z = ``far`` if given:
    the bounding box grows in the last block only."""
    rng = np.random.default_rng(7)
    axes = [np.arange(n, dtype=float) for n in shape]
    X = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    X = X + rng.uniform(-0.1, 0.1, X.shape)
    if far is not None:
        X[:, :, -1, 2] = far
    return X


def sources(tmp_path, X, name):
    """The node array and, in 3D, the same mesh as a .cgns file (read by component)."""
    yield X
    if X.shape[-1] == 3:
        path = tmp_path / f"{name}.cgns"
        write_mesh(path, X)
        yield str(path)


# (edge length in the first block, second pass expected): the far plane at z = 1e4 makes the mesh's
# tolerance about 1e-8, a first block's own about 1e-11
SHORT_EDGES = [
    (None, False),  # no short edge: one pass
    (1e-10, True),  # degenerate under the mesh's tolerance only
    (1e-13, False),  # degenerate under the block's tolerance already
    (0.0, False),  # a collapsed edge: degenerate under both
    (1e-6, False),  # above both
]


@pytest.mark.parametrize("length, second_pass", SHORT_EDGES)
def test_edges_degenerate_only_under_the_whole_meshs_tolerance(tmp_path, length, second_pass):
    X = box_grid((6, 5, 12), far=1e4)
    if length is not None:
        X[2, 2, 1] = X[1, 2, 1] + np.array([length, 0.0, 0.0])
    expected = expected_report(X)
    if second_pass:  # the cells on that edge: degenerate in the whole mesh, not under a block's tolerance
        assert expected["degenerate"] == 4 and not structured_metrics(X[:, :, :4], kernels="compiled")[1].any()
    for source in sources(tmp_path, X, "late"):
        for block_nodes in (60, 300, None):
            report, heard = blockwise(source, block_nodes)
            assert_same(report, expected)
            one_block = block_nodes is None  # the whole mesh in one block: its own tolerance is the mesh's
            assert heard == ({"quality", SECOND_PASS} if second_pass and not one_block else {"quality"}), (block_nodes, heard)


def test_a_bounding_box_that_grows_late_needs_no_second_pass_without_short_edges(tmp_path):
    """Each block's tolerance is far below the mesh's (the far planes come last, in the last
    blocks), yet with no edge between the two every block's first values stand."""
    X = box_grid((5, 4, 30))
    X[:, :, 20:, 2] *= np.geomspace(1.0, 1e6, 10)  # each block's box larger than the one before
    expected = expected_report(X)
    for source in sources(tmp_path, X, "growing"):
        report, heard = blockwise(source, 60)
        assert_same(report, expected)
        assert heard == {"quality"}


def grid_2d(nx, ny):
    x, y = np.meshgrid(np.linspace(0.0, 1.0, nx), np.linspace(0.0, 2.0, ny), indexing="ij")
    X = np.stack([x + 0.2 * y * x, y + 0.05 * np.sin(3 * x)], axis=-1)
    return X


def test_2d_meshes_of_either_orientation_in_one_pass():
    for X in (grid_2d(9, 14), grid_2d(9, 14)[::-1]):  # counter-clockwise, clockwise
        expected = expected_report(X)
        report, heard = blockwise(X, 30)
        assert_same(report, expected)
        assert heard == {"quality"}
        assert expected["inverted"] == 0  # each takes the mesh's orientation: no cell inverted


def test_a_2d_block_folded_against_the_mesh_is_evaluated_again_with_the_meshs_orientation():
    X = grid_2d(9, 14)
    X[:, :2, 0] = 1.0 - X[:, :2, 0]  # the first two rows of nodes mirrored: the first cells fold over
    expected = expected_report(X)
    assert 0 < expected["inverted"] < expected["cells"] // 2
    report, heard = blockwise(X, 30)  # the first block: the first rows of cells, their area negative
    assert_same(report, expected)
    assert heard == {"quality", SECOND_PASS}


def test_a_file_with_non_finite_and_collapsed_nodes_in_one_pass(tmp_path):
    X = box_grid((6, 5, 12))
    X[3, 3, 5] = np.nan
    X[0, 0, 9] = X[1, 0, 9]  # a zero-length edge
    X[4, 1, 2, 1] = np.inf
    expected = expected_report(X)
    assert expected["degenerate"] > 0
    for source in sources(tmp_path, X, "holes"):
        report, heard = blockwise(source, 60)
        assert_same(report, expected)
        assert "2 nodes have non-finite coordinates; their cells count as degenerate" in report["warnings"]
        assert heard == {"quality"}


def numpy_lengths(F):
    """Every edge length of nodes by component ``F`` (dim, nk, nj, ni): the norms of the node
    differences along each grid axis."""
    return np.concatenate([np.linalg.norm(np.diff(F, axis=axis), axis=0).ravel() for axis in (1, 2, 3)])


@pytest.mark.parametrize("dim", [2, 3])
def test_the_shortest_edge_above_a_floor_against_numpy(dim):
    rng = np.random.default_rng(11)
    shape = (dim, 1 if dim == 2 else 6, 7, 9)
    F = rng.uniform(-1.0, 1.0, shape)
    F[:, 0, 3, 4] = F[:, 0, 3, 5]  # a zero edge
    F[:, 0, 4, 4] = F[:, 0, 4, 5] + 1e-9  # a tiny one
    F[0, 0, 1, 1] = np.nan
    F[1, 0, 5, 2] = -np.inf
    for lo, box in (((0, 0, 0), shape[:0:-1]), ((2, 1, 0), (8, 6, shape[1]))):
        nodes = F[:, lo[2] : box[2], lo[1] : box[1], lo[0] : box[0]]
        every = numpy_lengths(nodes)
        with np.errstate(invalid="ignore"):
            finite = every[np.isfinite(every)]
        for floor in (0.0, 1e-9, 1e-3, 0.5):
            above = finite[finite > floor]
            assert shortest_edge_above(F, lo, box, floor) == (above.min() if above.size else np.inf), (lo, floor)
    assert shortest_edge_above(F, (0, 0, 0), shape[:0:-1], 100.0) == np.inf


@pytest.mark.parametrize("dim", [2, 3])
def test_the_shortest_edge_is_the_length_the_kernels_compare_with_the_tolerance(dim):
    """The kernels call a cell degenerate when an edge is at most the tolerance: with the
    tolerance at the shortest edge the cells on it are degenerate, one ulp below it none is; the
    shortest edge above that one (the floored search) is the next length the kernels tell apart."""
    rng = np.random.default_rng(5)
    shape = (7, 6, 5)[:dim]
    X = np.stack(np.meshgrid(*[np.arange(n, dtype=float) for n in shape], indexing="ij"), axis=-1)
    X = X + rng.uniform(-0.2, 0.2, X.shape)
    X[(2,) * dim] = X[(1,) + (2,) * (dim - 1)] + rng.uniform(1e-7, 2e-7, dim)  # one short edge
    X[(4,) + (3,) * (dim - 1)] = X[(3,) * dim] + rng.uniform(5e-7, 6e-7, dim)  # a longer one, other cells
    F = X.transpose((dim,) + tuple(range(dim - 1, -1, -1)))
    F = F if dim == 3 else F[:, None]
    box = (shape + (1,))[:3]
    shortest = shortest_edge_above(F, (0, 0, 0), box)
    assert 1e-7 < shortest < 4e-7
    cells_per_edge = 2 ** (dim - 1)
    for length, degenerate in (
        (shortest, cells_per_edge),
        (shortest_edge_above(F, (0, 0, 0), box, shortest), 2 * cells_per_edge),
    ):
        at = structured_metrics(X, tolerance=length, kernels="compiled")[1]
        below = structured_metrics(X, tolerance=math.nextafter(length, 0.0), kernels="compiled")[1]
        assert at.sum() == degenerate and below.sum() == degenerate - cells_per_edge, length


def test_block_reads_follow_a_file_rewritten_at_the_same_path(tmp_path):
    """The zone's coordinate datasets are found once per version of the file: a mesh written
    anew at the same path (another shape, other nodes) is what the next block read returns, and a
    block beyond the zone is refused in one line."""
    from meshgen.errors import FormatError
    from meshgen.formats import read_node_block, read_node_components

    path = tmp_path / "m.cgns"
    first, second = box_grid((4, 5, 6)), box_grid((7, 3, 5)) + 10.0
    write_mesh(path, first)
    block = (slice(1, 3), slice(0, 3), slice(2, 5))
    assert np.array_equal(read_node_block(path, block), first[block])
    write_mesh(path, second)
    assert np.array_equal(read_node_block(path, block), second[block])
    assert np.array_equal(read_node_components(path, block), second[block].transpose(3, 2, 1, 0))
    whole = (slice(0, 7), slice(0, 3), slice(0, 5))  # beyond the first mesh, all of the second
    assert np.array_equal(read_node_components(path, whole), second.transpose(3, 2, 1, 0))
    with pytest.raises(FormatError, match="is not in the zone's"):  # in the first mesh, beyond the second
        read_node_components(path, (slice(0, 4), slice(0, 4), slice(0, 5)))

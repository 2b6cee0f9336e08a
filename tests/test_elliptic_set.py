"""The elliptic solver on block sets (meshgen.methods.elliptic.elliptic_blocks, the multigrid of
meshgen.methods.multigrid_set): a set of one block is the one-block solve; a block split in two
gives the mesh of the whole block, its interface nodes satisfying the whole block's discrete
Winslow equations (residual computed independently by meshgen.methods.winslow on the stitched
array); the 2D kernels against the NumPy operator and line-ADI sweep."""

import numpy as np
import pytest

from meshgen.geometry import cube
from meshgen.geometry.blocks import BlockSet, Interface
from meshgen.methods.elliptic import elliptic_blocks
from meshgen.methods.multigrid import Level, smooth, solve_winslow
from meshgen.methods.multigrid_set import solve_set
from meshgen.methods.winslow import component_array, winslow_operator, winslow_residual


def _curved(shape):
    """A curved structured block, mirror-symmetric about the plane xi = 1/2 (so its halves have
    equal mean lengths across the split): node array shape + (dim,)."""
    t = np.meshgrid(*[np.linspace(0.0, 1.0, n) for n in shape], indexing="ij")
    xi, eta = t[0], t[1]
    x = (xi - 0.5) * (1.0 + 0.6 * eta)
    y = eta + 0.25 * np.sin(np.pi * xi) * (1.0 - 0.5 * eta)
    if len(shape) == 2:
        return np.stack([x, y], axis=-1)
    zeta = t[2]
    return np.stack([x, y, zeta * (1.0 + 0.3 * eta) + 0.1 * np.cos(np.pi * xi)], axis=-1)


def _block_set(shapes, interfaces=()):
    dim = len(shapes[0])
    taken = {(i.a, i.face_a.name) for i in interfaces} | {(i.b, i.face_b.name) for i in interfaces}
    patches = {
        (b, face.name): ("wall", "wall") for b in range(len(shapes)) for face in cube.faces(dim) if (b, face.name) not in taken
    }
    return BlockSet(
        name="split",
        dim=dim,
        description="",
        values={},
        names=tuple(f"b{b}" for b in range(len(shapes))),
        geometries=(None,) * len(shapes),
        coords=tuple(tuple(np.linspace(0.0, 1.0, n) for n in shape) for shape in shapes),
        interfaces=tuple(interfaces),
        patches=patches,
        length=2.0,
    )


def _split(shape):
    """The whole block's start, and the set of its two halves along xi (a's xi1 is b's xi0)."""
    X = _curved(shape)
    middle = (shape[0] - 1) // 2
    dim = len(shape)
    interface = Interface(0, cube.Face(dim, 0, 1), 1, cube.Face(dim, 0, 0), tuple(range(1, dim + 1)))
    halves = [X[: middle + 1], X[middle:]]
    return X, halves, _block_set([h.shape[:-1] for h in halves], [interface])


@pytest.mark.parametrize("shape", [(17, 11), (13, 9, 7)])
def test_a_block_split_in_two_gives_the_whole_blocks_mesh(shape):
    X, halves, block_set = _split(shape)
    coords = [np.linspace(0.0, 1.0, n) for n in shape]
    whole, info = solve_winslow(X, coords, tol=1e-12, max_iter=200, length=2.0)
    assert info["converged"]
    Xs, set_info = elliptic_blocks(block_set, tol=1e-11, slide=False, initial=halves, orthogonality=False)
    assert set_info["converged"] and set_info["sweeps"] < 60
    middle = (shape[0] - 1) // 2
    stitched = np.concatenate([Xs[0], Xs[1][1:]], axis=0)
    np.testing.assert_array_equal(Xs[0][-1], Xs[1][0])  # the interface nodes, one value in both blocks
    spacing = 1.0 / (shape[0] - 1)
    assert np.abs(stitched - whole).max() < 1e-8 * spacing
    # independently: the whole block's Winslow residual at the interface nodes, against the start's
    residual = winslow_residual(stitched, coords)[middle - 1]
    start = winslow_residual(X, coords)[middle - 1]
    assert np.abs(start).max() > 1e-2
    assert np.abs(residual).max() < 1e-7 * np.abs(start).max()


def test_a_set_of_one_block_is_the_one_block_solve():
    X = _curved((17, 11))
    block_set = _block_set([X.shape[:-1]])
    coords = block_set.coords[0]
    expected, info = solve_winslow(X, coords, length=block_set.length)
    (got,), set_info = elliptic_blocks(block_set, slide=False, initial=[X], orthogonality=False)
    np.testing.assert_array_equal(got, expected)  # the same code: the same mesh, to the bit
    assert set_info["sweeps"] == info["iterations"]
    # the block-set multigrid (halo, frozen boundary, shared levels) converges to the same discrete solution
    values, cycles, update, _ = solve_set(block_set, [X], 1e-11, 100, slide=False)
    assert update < 1e-11 and cycles < 40
    tight, _ = solve_winslow(X, coords, tol=1e-13, max_iter=200, length=block_set.length)
    assert np.abs(values.reshape(X.shape) - tight).max() < 1e-9


def test_the_2d_kernels_match_the_numpy_operator_and_sweep():
    from meshgen.methods import winslow_compiled_2d
    from meshgen.methods.multigrid import stencil_weights

    rng = np.random.default_rng(3)
    coords = [np.linspace(0.0, 1.0, 12), np.cumsum(np.r_[0.0, rng.uniform(0.5, 1.5, 9)])]
    coords[1] /= coords[1][-1]
    X = _curved((12, 10)) + 0.01 * rng.standard_normal((12, 10, 2))
    R = component_array(X)
    level = Level(coords)
    weights = stencil_weights(level.grid)
    residual, axial = winslow_operator(R, level.grid)
    got_residual, got_axial = winslow_compiled_2d.operator(R, weights)
    scale = np.abs(residual).max()
    assert np.abs(got_residual - residual).max() < 1e-12 * scale
    assert np.abs(got_axial - np.stack(axial)).max() < 1e-12
    f = 0.1 * scale * rng.standard_normal(residual.shape)
    defect = winslow_compiled_2d.defect(R, f, weights)
    assert np.abs(defect[level.interior] - (f - residual)).max() < 1e-12 * scale
    assert not defect[:, 0].any() and not defect[:, :, -1].any()
    expected = R.copy()
    smooth(expected, f, level, 1)
    swept = R.copy()
    winslow_compiled_2d.relax(swept, f, weights, 1.0)
    assert np.abs(swept - expected).max() < 1e-12 * np.abs(expected - R).max()
    # frozen nodes stay; the others still move
    frozen = np.zeros(residual.shape[1:], dtype=bool)
    frozen[3, :] = True
    kept = R.copy()
    winslow_compiled_2d.relax(kept, f, weights, 1.0, frozen)
    np.testing.assert_array_equal(kept[:, 4], R[:, 4])
    assert np.abs(kept[:, 6] - R[:, 6]).max() > 0


def test_a_split_with_turned_block_gives_the_same_mesh():
    """The second half stored with its axes swapped and one reversed: the halo is filled through the
    interface's Transform, and the mesh is the one of the halves in the same frame."""
    X, halves, block_set = _split((17, 11))
    turned = np.ascontiguousarray(np.flip(np.transpose(halves[1], (1, 0, 2)), axis=0))  # b's (j, i) with j reversed
    # a's xi (axis 0) is b's eta (axis 1, +); a's eta (axis 1) is b's xi (axis 0, reversed)
    interface = Interface(0, cube.Face(2, 0, 1), 1, cube.Face(2, 1, 0), (2, -1))
    other = _block_set([halves[0].shape[:-1], turned.shape[:-1]], [interface])
    straight, _ = elliptic_blocks(block_set, tol=1e-11, slide=False, initial=halves, orthogonality=False)
    Xs, info = elliptic_blocks(other, tol=1e-11, slide=False, initial=[halves[0], turned], orthogonality=False)
    assert info["converged"]
    np.testing.assert_allclose(Xs[0], straight[0], rtol=0, atol=1e-10)
    back = np.transpose(np.flip(Xs[1], axis=0), (1, 0, 2))
    np.testing.assert_allclose(back, straight[1], rtol=0, atol=1e-10)


@pytest.mark.parametrize("name, dims", [("dfg-cylinder", (12, 8)), ("pipe", (8, 4, 6))])
def test_the_layout_moves_values_as_the_halo_does(name, dims):
    """The flat buffer of a level's padded blocks (interfaces.Layout) against the Halo's own
    gather and scatter: loaded, every block's view is the Halo's padded array; after arbitrary
    values are written into the blocks' own nodes, ``unique`` is the Halo's ``unique`` of them
    and ``exchange`` refills every halo, ghost and shared copy from the node's owner."""
    from meshgen.geometry.blocks import load_block_set, tfi_blocks
    from meshgen.methods.interfaces import Layout, gather, mean_length
    from meshgen.methods.multigrid_set import set_levels

    block_set = load_block_set(name, None, dims)
    Xs = tfi_blocks(block_set)
    lengths = [(mean_length(Xs[i.a], i.face_a.axis), mean_length(Xs[i.b], i.face_b.axis)) for i in block_set.interfaces]
    halo = set_levels(block_set, Xs, lengths)[0].halo
    layout = Layout(halo, block_set.dim)
    values = gather(Xs, halo.numbering, halo.count)
    buffer = layout.load(values)
    for view, padded in zip(layout.views(buffer), halo.padded(values)):
        np.testing.assert_array_equal(view, padded)
    rng = np.random.default_rng(1)
    for block, view in enumerate(layout.views(buffer)):  # every copy of a node now disagrees
        view[halo.inside(block)] = rng.normal(size=view[halo.inside(block)].shape)
    expected = halo.unique([view[halo.inside(block)] for block, view in enumerate(layout.views(buffer))])
    np.testing.assert_array_equal(layout.unique(buffer), expected)
    layout.exchange(buffer)
    for view, padded in zip(layout.views(buffer), halo.padded(expected)):
        np.testing.assert_array_equal(view, padded)


def test_sliding_rows_in_the_lines_keep_the_discrete_solution():
    """The DFG channel's sliding walls solved in the normal lines (multigrid_set.wall_rows) and
    the semi-coarsened levels: the same discrete solution as sliding nodes relaxed only by their
    own rule (wall_rows switched off), to far below the stopping tolerance, in fewer cycles."""
    from meshgen.geometry.blocks import load_block_set
    from meshgen.methods import multigrid_set

    block_set = load_block_set("dfg-cylinder", None, (17, 10))
    Xs, info = elliptic_blocks(block_set, tol=1e-11, max_iter=400)
    original = multigrid_set.wall_rows
    try:
        multigrid_set.wall_rows = lambda *args: None
        plain, plain_info = elliptic_blocks(block_set, tol=1e-11, max_iter=400)
    finally:
        multigrid_set.wall_rows = original
    assert info["converged"] and plain_info["converged"]
    assert info["iterations"] < plain_info["iterations"]
    for X, Y in zip(Xs, plain):
        assert np.max(np.abs(X - Y)) < 1e-9 * block_set.length

"""The compiled quality kernels against the plain-NumPy definition
(``meshgen.quality.numpy_kernels``): random, strongly distorted (folded, inverted) and degenerate
meshes, structured and unstructured paths, and a block of a mesh evaluated with the whole mesh's
tolerance."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from meshgen.geometry.grid import cell_connectivity, flat_points
from meshgen.quality import METRICS, cell_metrics_unstructured
from meshgen.quality.numpy_kernels import numpy_cell_metrics as reference_cell_metrics
from meshgen.quality.structured import structured_metrics


def distorted(dims, sigma, seed):
    """A unit box of ``dims`` cells with Gaussian node noise of ``sigma`` cell widths."""
    rng = np.random.default_rng(seed)
    axes = [np.linspace(0.0, 1.0, n + 1) for n in dims]
    X = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    return X + rng.normal(scale=sigma / max(dims), size=X.shape)


def assert_agree(metrics, degenerate, reference, reference_degenerate):
    np.testing.assert_array_equal(degenerate, reference_degenerate)
    for name in METRICS:
        np.testing.assert_allclose(metrics[name], reference[name], rtol=0, atol=1e-12, err_msg=name)


@pytest.mark.parametrize("dims", [(7, 6, 5), (12, 9)])
@pytest.mark.parametrize("sigma", [0.02, 0.3, 0.8])
def test_compiled_kernels_agree_with_the_numpy_reference(dims, sigma):
    X = distorted(dims, sigma, seed=int(sigma * 100) + len(dims))
    metrics, degenerate, _ = structured_metrics(X, kernels="compiled")
    reference, reference_degenerate = reference_cell_metrics(X)
    assert_agree(metrics, degenerate, reference, reference_degenerate)
    if sigma >= 0.3:  # folded faces and inverted cells are covered
        assert np.any(metrics["scaled_jacobian"] <= 0) and np.any(metrics["max_angle"] > 180)
    points, cells = flat_points(X, width=X.shape[-1]), cell_connectivity(X.shape[:-1])
    unstructured = cell_metrics_unstructured(points, cells)
    for name in METRICS:
        np.testing.assert_allclose(unstructured[name], reference[name], rtol=0, atol=1e-12, err_msg=name)


@pytest.mark.parametrize("dims", [(5, 4, 6), (8, 7)])
def test_degenerate_inverted_and_non_finite_cells_agree(dims):
    X = distorted(dims, 0.4, seed=5)
    X[1, 1] = X[1, 2]  # zero-length edges
    X[2, 0] = np.nan  # a non-finite node: its cells, and the faces towards them, have no neighbour centroid
    X[-1, -1] = np.inf
    X[-2, 2] = X[-3, 2] + (X[-3, 2] - X[-2, 2])  # a node mirrored through its neighbour: inverted cells
    with np.errstate(invalid="ignore", over="ignore"):
        metrics, degenerate, info = structured_metrics(X, kernels="compiled")
    reference, reference_degenerate = reference_cell_metrics(X)
    # X[2, 0] and X[-1, -1] are a line of nodes in 3D, one node in 2D
    assert degenerate.any() and info["nonfinite_nodes"] == 2 * (X.shape[2] if len(dims) == 3 else 1)
    assert degenerate.reshape(dims)[-1, -1].all()  # cells with an infinite corner are degenerate
    assert_agree(metrics, degenerate, reference, reference_degenerate)


@pytest.mark.parametrize("dims", [(9, 8, 7), (11, 10)])
def test_a_block_of_cells_gets_its_values_in_the_whole_mesh(dims):
    X = distorted(dims, 0.3, seed=2)
    whole, whole_degenerate, _ = structured_metrics(X, kernels="compiled")
    cell_shape = tuple(dims)
    # cells 2..6 along axis 0 (the others in full) from the nodes of cells 1..7: one neighbour layer
    X_block = X[1:9]
    tolerance = float(np.linalg.norm(np.ptp(X.reshape(-1, X.shape[-1]), axis=0)) * 1e-12)
    cells = (slice(1, 6),) + tuple(slice(0, n) for n in cell_shape[1:])
    part, degenerate, _ = structured_metrics(X_block, tolerance=tolerance, orientation=1.0, cells=cells)
    expected = {name: whole[name].reshape(cell_shape)[2:7].reshape(-1) for name in METRICS}
    for name in METRICS:
        np.testing.assert_array_equal(part[name], expected[name], err_msg=name)
    np.testing.assert_array_equal(degenerate, whole_degenerate.reshape(cell_shape)[2:7].reshape(-1))


def test_small_meshes_take_the_numpy_kernels_without_loading_numba(tmp_path):
    """A fresh process's quality of a small mesh never imports numba, and gives the compiled values."""
    X = distorted((6, 5, 4), 0.3, seed=9)
    np.save(tmp_path / "X.npy", X)
    script = (
        "import sys, numpy as np; from meshgen.quality.structured import structured_metrics; "
        f"m, d, _ = structured_metrics(np.load({str(tmp_path / 'X.npy')!r})); "
        f"np.save({str(tmp_path / 'm.npy')!r}, np.stack([m[k] for k in {list(METRICS)!r}])); "
        "print('numba' in sys.modules)"
    )
    environment = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=environment, check=True)
    assert done.stdout.strip() == "False"
    compiled, _, _ = structured_metrics(X, kernels="compiled")
    np.testing.assert_allclose(np.load(tmp_path / "m.npy"), np.stack([compiled[k] for k in METRICS]), rtol=0, atol=1e-12)


def test_the_file_order_kernel_gives_each_cell_the_c_order_kernels_values(tmp_path):
    """Nodes by component in a CGNS file's order (what ``read_node_components`` returns): every
    cell gets ``structured_hex``'s values to the bit, whole mesh and a block of cells, with
    degenerate, non-finite and inverted cells; only the order of cells differs (i fastest)."""
    from meshgen.formats import read_node_components, write_mesh
    from meshgen.quality import compiled

    dims = (9, 8, 7)
    X = distorted(dims, 0.4, seed=4)
    X[1, 1] = X[1, 2]
    X[2, 0] = np.nan
    X[-2, 2] = X[-3, 2] + (X[-3, 2] - X[-2, 2])
    write_mesh(tmp_path / "m.cgns", X)
    F = read_node_components(tmp_path / "m.cgns", tuple(slice(0, n + 1) for n in dims))
    assert np.array_equal(F, np.moveaxis(X, -1, 0).transpose(0, 3, 2, 1), equal_nan=True)
    for first, last in (((0, 0, 0), dims), ((1, 2, 1), (8, 7, 5))):
        shape = tuple(b - a for a, b in zip(first, last))
        cells = int(np.prod(shape))
        expected, expected_degenerate = np.empty((7, cells)), np.empty(cells, dtype=bool)
        values, degenerate = np.empty((7, cells)), np.empty(cells, dtype=bool)
        with np.errstate(invalid="ignore"):
            compiled.structured_hex(X, first, last, 1e-9, expected, expected_degenerate)
            compiled.structured_hex_file_order(F, first, last, 1e-9, values, degenerate)
        in_c_order = values.reshape((7,) + shape[::-1]).transpose(0, 3, 2, 1).reshape(7, -1)
        assert np.array_equal(in_c_order, expected, equal_nan=True)
        assert np.array_equal(degenerate.reshape(shape[::-1]).T.reshape(-1), expected_degenerate)
        if cells == int(np.prod(dims)):
            assert expected_degenerate.any() and np.isnan(expected).any() and (expected[6] < 0).any()


def test_the_thread_pool_keeps_order_and_runs_nested_calls_in_its_own_thread():
    import threading

    from meshgen.quality.pool import map_in_threads

    def inner(x):
        return [(x * y, threading.current_thread().name) for y in range(3)]

    results = map_in_threads(inner, range(5))
    assert [[v for v, _ in row] for row in results] == [[x * y for y in range(3)] for x in range(5)]
    assert all(len({name for _, name in row}) == 1 for row in results)  # a pool task's calls stay in its thread

"""The compiled grid smoothness figures (``meshgen.quality.smoothness_compiled``) against the NumPy
definition of ``meshgen.quality.smoothness`` (itself held to closed forms in
``tests/test_smoothness.py``): the same per-cell expansion ratio and grid smoothness to round-off,
the same summaries and worst cells, on perturbed, graded, thin, degenerate and non-finite meshes."""

from __future__ import annotations

import numpy as np
import pytest

from meshgen.quality import smoothness
from meshgen.quality.smoothness import expansion_ratio, grid_smoothness, node_smoothness, smoothness_figures
from meshgen.quality.smoothness_compiled import cell_figures


def box(shape, amplitude=0.0, seed=0, grading=(1.0, 1.0, 1.0)):
    """A box grid of ``shape`` nodes, axis a spaced as t^grading[a], nodes moved by N(0, amplitude)."""
    axes = [np.linspace(0.0, 1.0 + 0.3 * a, n) ** g for a, (n, g) in enumerate(zip(shape, grading))]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    return grid + np.random.default_rng(seed).normal(0.0, amplitude, grid.shape)


def degenerate():
    X = box((6, 7, 5), 0.01, seed=4)
    X[2, 3, :] = X[2, 2, :]  # zero-length edges: size ratios of 0 and infinite second differences
    X[4, 4, 4] = X[3, 4, 4]
    return X


def non_finite():
    X = box((6, 5, 7), 0.01, seed=5)
    X[1, 2, 3] = np.nan
    X[4, 1, 1, 0] = np.inf
    return X


MESHES = {
    "perturbed": lambda: box((9, 8, 7), 0.01),
    "graded": lambda: box((7, 9, 8), 0.0, grading=(1.0, 1.7, 0.6)),
    "thin": lambda: box((2, 9, 3), 0.005, seed=2),
    "one node layer deep": lambda: box((5, 2, 2), 0.01, seed=3),
    "degenerate": degenerate,
    "non-finite": non_finite,
}


def close(ours, reference):
    """Equal where NumPy's value is not finite, else to 1e-12 relative."""
    finite = np.isfinite(reference)
    assert np.array_equal(np.isfinite(ours), finite) and np.array_equal(np.isnan(ours), np.isnan(reference))
    assert np.array_equal(ours[~finite & ~np.isnan(reference)], reference[~finite & ~np.isnan(reference)])
    np.testing.assert_allclose(ours[finite], reference[finite], rtol=1e-12, atol=0)


@pytest.mark.parametrize("name", sorted(MESHES))
def test_per_cell_figures_are_the_numpy_definitions(name):
    X = MESHES[name]()
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        ratio, cells, by_axis = cell_figures(X)
        close(ratio, expansion_ratio(X))
        close(cells, grid_smoothness(X))
        for axis in range(3):  # the largest value along each axis's lines, from the nodes
            if X.shape[axis] < 3:
                assert by_axis[axis] == 0.0
            elif not np.isnan(by_axis[axis]):
                assert by_axis[axis] == pytest.approx(np.nanmax(node_smoothness(X, [axis])), rel=1e-12)


@pytest.mark.parametrize("name", sorted(MESHES))
def test_summaries_are_the_numpy_ones(name):
    X = MESHES[name]()
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        ours, reference = smoothness_figures(X, kernels="compiled"), smoothness_figures(X, kernels="numpy")
    for figure in ("expansion_ratio", "grid_smoothness"):
        assert ours[figure]["worst_cell"] == reference[figure]["worst_cell"]
        for key in ("mean", "max", "p99"):
            expected = reference[figure][key]
            assert ours[figure][key] == (
                expected if expected is None or not np.isfinite(expected) else pytest.approx(expected, rel=1e-12)
            )
    assert np.allclose(
        ours["grid_smoothness"]["max_by_axis"], reference["grid_smoothness"]["max_by_axis"], rtol=1e-12, equal_nan=True
    )


def test_auto_takes_the_compiled_kernels_for_large_3d_meshes_only(monkeypatch):
    calls = []
    monkeypatch.setattr(smoothness, "use_compiled", lambda cells, kernels: calls.append(cells) or cells >= 100)
    smoothness_figures(box((6, 6, 6), 0.01))  # 125 cells: compiled
    smoothness_figures(box((4, 4, 4), 0.01))  # 27 cells: NumPy
    smoothness_figures(np.zeros((40, 40, 2)) + np.random.default_rng(0).random((40, 40, 2)))  # 2D: NumPy whatever its size
    assert calls == [125, 27]

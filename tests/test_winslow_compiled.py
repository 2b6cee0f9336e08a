"""The compiled multigrid kernels (meshgen.methods.winslow_compiled) against the NumPy code they replace on
large grids: the Winslow residual and coefficients (meshgen.methods.winslow.winslow_operator), one line-ADI
sweep (meshgen.methods.multigrid.smooth), the multigrid transfers (dense matrices along each axis) and a
whole solve, on small distorted grids with uniform and stretched axes. The kernels' work is split
over threads on every call here (``THREADED_NODES`` 0), as it is on large grids."""

import sys

import numpy as np
import pytest

import meshgen.methods.multigrid  # noqa: F401  (the module that holds the one-grid multigrid)
from meshgen.geometry.plugins import load_geometry
from meshgen.methods import winslow_compiled
from meshgen.methods.winslow import component_array, winslow_operator

elliptic_module = sys.modules["meshgen.methods.multigrid"]
Level, along_axes, smooth, solve_winslow = (
    elliptic_module.Level,
    elliptic_module.along_axes,
    elliptic_module.smooth,
    elliptic_module.solve_winslow,
)


@pytest.fixture(autouse=True)
def threaded(monkeypatch):
    monkeypatch.setattr(winslow_compiled, "THREADED_NODES", 0)


def distorted_grid(coords, seed=0):
    """A smooth, strongly curved map of the parametric grid plus random node jitter: R (3, ...)."""
    t = np.meshgrid(*coords, indexing="ij")
    x = t[0] + 0.3 * np.sin(2.0 * t[1]) * t[2]
    y = (1.0 + t[0]) * np.cos(1.2 * t[1]) + 0.2 * t[2] ** 2
    z = (1.0 + t[0]) * np.sin(1.2 * t[1]) + 1.5 * t[2] + 0.1 * t[0] * t[1]
    R = np.stack([x, y, z])
    R[(slice(None),) + (slice(1, -1),) * 3] += 0.01 * np.random.default_rng(seed).standard_normal(
        (3, *(len(c) - 2 for c in coords))
    )
    return np.ascontiguousarray(R)


GRIDS = {
    "uniform": [np.linspace(0.0, 1.0, n) for n in (7, 6, 9)],
    "stretched": [
        np.linspace(0.0, 1.0, 7),
        np.linspace(0.0, 1.0, 6) ** 1.7,
        np.array([0.0, 0.05, 0.12, 0.2, 0.35, 0.5, 0.7, 0.85, 1.0]),
    ],
}


@pytest.mark.parametrize("name", GRIDS)
def test_residual_and_coefficients_match_numpy(name):
    coords = GRIDS[name]
    R = distorted_grid(coords)
    level = Level(coords, compiled=True)
    expected, expected_axial = winslow_operator(R, level.grid)
    residual, axial = level.operator(R)
    scale = np.abs(expected).max()  # the residual's size: 0.1 to 10 here
    assert scale > 0.1
    np.testing.assert_allclose(residual, expected, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(axial, np.stack(expected_axial), rtol=0, atol=1e-12)
    f = np.random.default_rng(1).standard_normal(expected.shape)
    defect = level.defect(R, f)
    assert np.all(defect[:, 0] == 0) and np.all(defect[:, :, :, -1] == 0)  # boundary nodes
    np.testing.assert_allclose(defect[level.interior], f - expected, rtol=0, atol=1e-12 * scale)


@pytest.mark.parametrize("name", GRIDS)
@pytest.mark.parametrize("with_f", [False, True])
def test_one_relaxation_sweep_matches_numpy(name, with_f):
    coords = GRIDS[name]
    R = distorted_grid(coords, seed=2)
    numpy_level, compiled_level = Level(coords), Level(coords, compiled=True)
    assert not numpy_level.compiled and compiled_level.compiled
    f = 0.1 * np.random.default_rng(3).standard_normal((3, *(len(c) - 2 for c in coords))) if with_f else None
    expected, result = R.copy(), R.copy()
    expected_step = smooth(expected, f, numpy_level, 2)
    step = smooth(result, f, compiled_level, 2)
    assert np.abs(expected - R).max() > 1e-3  # the sweeps moved the nodes
    np.testing.assert_allclose(result, expected, rtol=0, atol=1e-12)
    assert step == pytest.approx(expected_step, rel=1e-12)


def test_transfers_match_the_dense_matrices():
    fine = [
        np.linspace(0.0, 1.0, 9),
        np.linspace(0.0, 1.0, 8),
        np.linspace(0.0, 1.0, 12) ** 1.5,
    ]  # 8, 7 and 11 cells: nested and not
    coarse = [elliptic_module.coarser_coordinates(t) for t in fine]
    level = Level(fine, coarse, compiled=True)
    rng = np.random.default_rng(4)
    for name, source in (("prolong", coarse), ("restrict_solution", fine), ("restrict_residual", fine)):
        F = rng.standard_normal((3, *(len(t) for t in source)))
        np.testing.assert_allclose(level.transfer(name, F), along_axes(getattr(level, name), F), rtol=0, atol=1e-13)


def test_solve_with_kernels_matches_numpy(monkeypatch):
    """A whole multigrid solve with the kernels on every grid gives the NumPy solve's mesh."""
    from meshgen.geometry.layout import relax_faces, with_layout
    from meshgen.methods.tfi import parametric_grid, tfi

    geometry = with_layout(load_geometry("semicylinder"), "smoothed")
    coords = parametric_grid((8, 6, 10))
    X0 = tfi(geometry, None, coords)
    relax_faces(geometry, coords, X0)
    monkeypatch.setattr(elliptic_module, "COMPILED_NODES", 10**9)
    expected, info = solve_winslow(X0, coords, length=geometry.characteristic_length)
    monkeypatch.setattr(elliptic_module, "COMPILED_NODES", 0)
    X, compiled_info = solve_winslow(X0, coords, length=geometry.characteristic_length)
    assert info["converged"] and compiled_info["iterations"] == info["iterations"]
    assert np.abs(X - expected).max() < 1e-10 * geometry.characteristic_length
    assert compiled_info["final_residual"] == pytest.approx(info["final_residual"], rel=1e-6)


def test_kernels_need_3d_grids_of_the_threshold_size():
    assert not elliptic_module.uses_kernels([np.linspace(0, 1, 400)] * 2)
    assert elliptic_module.uses_kernels([np.linspace(0, 1, 41)] * 3) == (41**3 >= elliptic_module.COMPILED_NODES)
    assert not Level([np.linspace(0, 1, 5)] * 2, compiled=True).compiled
    R = component_array(np.zeros((5, 5, 5, 3)))
    assert winslow_compiled.defect(R, None, Level([np.linspace(0, 1, 5)] * 3, compiled=True).weights).shape == R.shape

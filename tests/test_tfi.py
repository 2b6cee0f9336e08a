"""Transfinite interpolation: boundary reproduction, affine exactness, orientation."""

import itertools

import numpy as np
import pytest

from meshgen.geometry.plugins import load_geometry
from meshgen.methods.tfi import parametric_grid, tfi, transfinite


def affine_boundary(points):
    A = np.array([[2.0, 0.3, 0.1], [0.2, 1.5, -0.4], [0.0, 0.5, 3.0]])[: points.shape[1], : points.shape[1]]
    return points @ A.T + 0.7


@pytest.mark.parametrize("dim", [2, 3])
def test_tfi_is_exact_for_an_affine_map(dim):
    rng = np.random.default_rng(0)
    uvw = rng.random((500, dim))
    mapped = transfinite(affine_boundary, list(uvw.T))
    np.testing.assert_allclose(mapped, affine_boundary(uvw), atol=1e-13)


def test_grid_and_scattered_evaluation_agree():
    geometry = load_geometry("semicylinder")
    coords = parametric_grid((4, 5, 6))
    X = tfi(geometry, (4, 5, 6))
    grid = np.stack(np.meshgrid(*coords, indexing="ij"), axis=-1).reshape(-1, 3)
    scattered = transfinite(geometry.boundary, list(grid.T))
    np.testing.assert_allclose(X.reshape(-1, 3), scattered, atol=1e-14)


def test_semicylinder_tfi_reproduces_the_boundary_and_has_positive_jacobians():
    geometry = load_geometry("semicylinder")
    X = tfi(geometry, (30, 30, 30))
    coords = parametric_grid((30, 30, 30))
    grid = np.stack(np.meshgrid(*coords, indexing="ij"), axis=-1)
    for axis, index in itertools.product(range(3), (0, -1)):
        face = np.take(grid, index, axis=axis).reshape(-1, 3)
        np.testing.assert_allclose(np.take(X, index, axis=axis).reshape(-1, 3), geometry.boundary(face), atol=1e-13)
    # Every corner Jacobian of every cell positive: central differences of the trilinear cells.
    e1, e2, e3 = (np.diff(X, axis=a) for a in range(3))
    det = np.einsum("ijkc,ijkc->ijk", e1[:, :-1, :-1], np.cross(e2[:-1, :, :-1], e3[:-1, :-1, :]))
    assert det.min() > 0

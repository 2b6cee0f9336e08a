"""One-block elliptic meshes of extruded shapes (meshgen.methods.elliptic.extruded_solve): the
section's 2D solve, extruded, is the 3D Winslow mesh. Checked against the 3D equations'
residual computed independently (meshgen.methods.winslow on the whole array), against the 3D
multigrid solve of the same start, and refused for shapes that are not extrusions."""

import numpy as np
import pytest

from meshgen.geometry.layout import relax_faces, with_layout
from meshgen.geometry.plugins import load_geometry
from meshgen.methods.clustering import node_coordinates
from meshgen.methods.elliptic import build_elliptic, extruded_solve
from meshgen.methods.multigrid import solve_winslow
from meshgen.methods.tfi import tfi
from meshgen.methods.winslow import winslow_residual


@pytest.mark.parametrize("clusters", [(), ("zeta:both:1.2", "eta:0:1.3")])
def test_the_extruded_mesh_solves_the_3d_equations(clusters):
    geometry = load_geometry("semicylinder")
    coords = node_coordinates((10, 9, 8), list(clusters))
    X, info = build_elliptic(geometry, coords, tol=1e-11)
    assert info["extruded"] and info["converged"]
    residual = winslow_residual(X, coords)  # the 3D discrete equations at the interior nodes
    start = winslow_residual(tfi(with_layout(geometry, "smoothed"), None, coords), coords)
    assert np.abs(residual).max() < 1e-8 * np.abs(start).max()
    # z is linear in zeta, every layer the same section
    zeta = np.asarray(coords[2])
    np.testing.assert_allclose(X[..., 2], X[:, :, :1, 2] + zeta * (X[0, 0, -1, 2] - X[0, 0, 0, 2]), atol=1e-14)
    np.testing.assert_array_equal(X[1:-1, 1:-1, 3, :2], X[1:-1, 1:-1, 5, :2])


def test_the_extruded_mesh_is_the_3d_multigrid_mesh():
    """The 3D solve of the smoothed layout's start (its caps relaxed as their faces' own grids)
    reaches the extruded mesh to the solvers' tolerance."""
    geometry = with_layout(load_geometry("semicylinder"), "smoothed")
    coords = node_coordinates((12, 10, 6), [])
    X, _ = build_elliptic(geometry, coords, tol=1e-11)
    X0 = tfi(geometry, None, coords)
    relax_faces(geometry, coords, X0)
    solid, info = solve_winslow(X0, coords, tol=1e-11, max_iter=100, length=geometry.characteristic_length)
    assert info["converged"]
    assert np.abs(X - solid).max() < 1e-8 * geometry.characteristic_length


@pytest.mark.parametrize("name", ["canal", "flower", "topcurve"])
def test_shapes_that_are_not_extrusions_take_the_3d_solve(name):
    geometry = load_geometry(name)
    coords = node_coordinates((6, 5, 4), [])
    assert extruded_solve(tfi(with_layout(geometry, "smoothed"), None, coords), coords, 1e-6, 50, 1.0) is None
    _, info = build_elliptic(geometry, coords)
    assert "extruded" not in info and info["converged"]


def test_a_sheared_extrusion_is_not_one():
    """Caps moved by a sweep that is not square to them: the 3D operator couples zeta with the
    section, so the shortcut must not apply."""
    geometry = with_layout(load_geometry("semicylinder"), "smoothed")
    coords = node_coordinates((6, 5, 4), [])
    X0 = tfi(geometry, None, coords)
    sheared = X0.copy()
    sheared[..., 0] += 0.3 * sheared[..., 2]
    assert extruded_solve(X0, coords, 1e-6, 50, geometry.characteristic_length) is not None
    assert extruded_solve(sheared, coords, 1e-6, 50, geometry.characteristic_length) is None

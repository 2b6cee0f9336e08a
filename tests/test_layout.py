"""The smoothed boundary layout (meshgen.layout): faces' surface grids by the 2D Winslow equations."""

from __future__ import annotations

import numpy as np
import pytest

from meshgen.cube import face_named
from meshgen.elliptic import elliptic
from meshgen.errors import GeometryError
from meshgen.geometry import check_boundary, load_geometry
from meshgen.layout import RESOLUTION, interpolate_1d, interpolate_2d, layout_of, smoothed, with_layout
from meshgen.quality import quality_report
from meshgen.tfi import tfi


def _face_grid(geometry, name, cells=RESOLUTION):
    """The smoothed layout's surface grid of face ``name`` at the fine nodes: (n, n, 3) points."""
    face = face_named(name, 3)
    U = layout_of(geometry, cells).face_values[(face.axis, face.side)]
    points = np.empty(U.shape[:-1] + (3,))
    points[..., face.axis] = face.side
    a, b = face.tangent_axes
    points[..., a], points[..., b] = U[..., 0], U[..., 1]
    return geometry.boundary(points.reshape(-1, 3)).reshape(U.shape[:-1] + (3,))


def test_flat_face_is_the_2d_elliptic_mesh(semicylinder):
    """The semicylinder's cap is the semidisk: its surface grid must be the 2D Winslow mesh."""
    cells = 32  # a coarser fine grid than the default: the same equations, a quicker test
    cap = _face_grid(semicylinder, "zeta0", cells)
    plane, _ = elliptic(load_geometry("semidisk"), (cells, cells), tol=1e-12, boundary_layout="fixed")
    assert np.abs(cap[..., 2]).max() == 0.0
    assert np.abs(cap[..., :2] - plane).max() < 1e-9
    # and it is not the Coons layout it started from (the test would pass trivially otherwise)
    coons = tfi(load_geometry("semidisk"), (cells, cells))
    assert np.abs(plane - coons).max() > 1e-2


def test_curved_face_solves_the_tangential_winslow_equations(tmp_path):
    """On a curved face the grid's Winslow vector (3 components) must be normal to the surface,
    the normal taken from the geometry's own map (finite differences), not from the grid."""
    path = tmp_path / "dome.py"
    path.write_text(
        "import numpy as np\nname = 'dome'\ndim = 3\ndescription = 'box with a bulged, sheared lid'\nparams = {}\n"
        "def boundary(points):\n"
        "    x, y, z = points[:, 0], points[:, 1], points[:, 2]\n"
        "    x = x + 0.3 * x * y\n"
        "    top = 1 + 0.4 * np.sin(np.pi * points[:, 0]) * np.sin(np.pi * y)\n"
        "    return np.stack([x, y, z * top], axis=1)\n"
    )
    geometry = load_geometry(str(path))
    X = _face_grid(geometry, "zeta1")
    from meshgen.winslow import stencils, winslow_operator

    t = np.linspace(0.0, 1.0, RESOLUTION + 1)
    residual, _ = winslow_operator(np.ascontiguousarray(np.moveaxis(X, -1, 0)), stencils([t, t]))
    residual = np.moveaxis(residual, 0, -1)
    U = layout_of(geometry).face_values[(2, 1)][1:-1, 1:-1].reshape(-1, 2)
    step = 1e-6
    tangents = []
    for d in range(2):
        plus, minus = (np.column_stack([U, np.ones(len(U))]) for _ in range(2))
        plus[:, d] += step
        minus[:, d] -= step
        tangents.append((geometry.boundary(plus) - geometry.boundary(minus)) / (2 * step))
    normal = np.cross(*tangents)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    flat = residual.reshape(-1, 3)
    tangential = flat - (flat * normal).sum(1, keepdims=True) * normal
    assert np.abs(tangential).max() < 1e-6 * np.abs(flat).max()
    assert np.abs(flat).max() > 1e-2  # the normal part (curvature) is really there


def test_edges_are_equally_spaced_along_the_curve(tmp_path):
    """An edge with a non-uniform parametrisation (x = t^2): smoothed nodes are equally spaced."""
    path = tmp_path / "squeezed.py"
    path.write_text(
        "import numpy as np\nname = 'squeezed'\ndim = 3\ndescription = 'box with squeezed x'\nparams = {}\n"
        "def boundary(points):\n"
        "    return np.stack([points[:, 0] ** 2 + 0.5 * points[:, 0], points[:, 1], points[:, 2]], axis=1)\n"
    )
    geometry = load_geometry(str(path))
    X = tfi(smoothed(geometry), (20, 4, 4))
    for edge in (X[:, 0, 0], X[:, -1, -1], X[:, 2, 0]):  # two edges and a line on a face
        spacing = np.diff(edge[:, 0])
        assert np.ptp(spacing) < 1e-3 * spacing.mean()  # to the fine grid's interpolation accuracy
    assert np.ptp(np.diff(tfi(geometry, (20, 4, 4))[:, 0, 0, 0])) > 0.05  # the fixed layout is not


@pytest.mark.parametrize("name", ["semicylinder", "topcurve"])
def test_smoothed_boundary_is_on_the_surface_and_continuous(name):
    geometry = load_geometry(name)
    layout = smoothed(geometry)
    check_boundary(layout)  # continuous across the cube's edges
    X = tfi(layout, (7, 9, 8))
    report = quality_report(X, geometry)  # deviation from the geometry's own surface
    assert report["boundary_deviation"]["max_rel"] < 1e-12


def test_hermite_interpolation_is_exact_for_cubics_and_keeps_edges():
    t = np.linspace(0.0, 1.0, 17)
    p = np.random.default_rng(0).random(200)
    cubic = lambda s: 1 - 2 * s + 3 * s**2 - s**3  # noqa: E731
    assert np.abs(interpolate_1d(cubic(t), p) - cubic(p)).max() < 1e-3  # FD slopes: close, not exact
    values = np.random.default_rng(1).random((17, 17))
    np.testing.assert_array_equal(interpolate_2d(values, p, np.zeros_like(p)), interpolate_1d(values[:, 0], p))
    np.testing.assert_array_equal(interpolate_1d(values[:, 3], t), values[:, 3])  # through the data


def test_semicylinder_elliptic_beats_the_smoothed_gmsh_figure(semicylinder):
    """Issue 16: at 30^3 the smoothed elliptic mesh reaches gmsh's smoothed transfinite 74.42 (to 74.4)."""
    dims = (30, 30, 30)
    X, info = elliptic(semicylinder, dims)
    report = quality_report(X, semicylinder)
    fixed = quality_report(elliptic(semicylinder, dims, boundary_layout="fixed")[0])
    assert info["boundary_layout"] == "smoothed"
    assert report["metrics"]["min_angle"]["mean"] >= 74.4
    assert fixed["metrics"]["min_angle"]["mean"] < 73.5  # today's figure, 73.03
    assert report["inverted"]["count"] == 0
    assert report["boundary_deviation"]["max_rel"] < 1e-12


def test_unknown_layout_is_an_error(semicylinder):
    with pytest.raises(GeometryError, match="unknown boundary layout"):
        with_layout(semicylinder, "wavy")


def test_cli_boundary_layout_option(run_cli, tmp_path, semicylinder):
    """--boundary-layout fixed keeps the TFI boundary nodes; the default moves them within the faces."""
    from meshgen.formats import metadata_of, read_mesh

    dims = (6, 5, 4)
    faces_of = lambda X: np.concatenate([X[0].reshape(-1, 3), X[-1].reshape(-1, 3), X[:, :, 0].reshape(-1, 3)])  # noqa: E731
    expected = tfi(semicylinder, dims)
    for layout in ("fixed", None):
        name = f"{layout}.vtu"
        args = ("mesh", "-m", "elliptic", "-g", "semicylinder", "--dims", *map(str, dims), "-o", name, "-q")
        result = run_cli(*args, *(("--boundary-layout", layout) if layout else ()))
        assert result.returncode == 0, result.stderr
        X = read_mesh(tmp_path / name).points.reshape(*(n + 1 for n in dims), 3)
        assert metadata_of(tmp_path / name)["method_info"]["boundary_layout"] == (layout or "smoothed")
        difference = np.abs(faces_of(X) - faces_of(expected)).max()
        assert difference < 1e-12 if layout == "fixed" else difference > 1e-3


def test_the_layout_cache_gives_back_the_computed_layout_and_ignores_a_damaged_file(semicylinder, monkeypatch, tmp_path):
    from meshgen import layout

    monkeypatch.setenv("MESHGEN_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(layout, "_LAYOUTS", {})
    computed = layout.compute_layout(semicylinder)
    first = layout.layout_of(semicylinder)  # computes and stores
    path = layout.cache_path(semicylinder)
    assert path.is_file() and path.parent.parent == tmp_path / "cache"
    monkeypatch.setattr(layout, "_LAYOUTS", {})
    monkeypatch.setattr(layout, "compute_layout", lambda *args: pytest.fail("the cached layout was not used"))
    cached = layout.layout_of(semicylinder)
    for name in ("edge_values", "face_values"):
        stored, direct = getattr(cached, name), getattr(computed, name)
        assert stored.keys() == direct.keys() and all(np.array_equal(stored[k], direct[k]) for k in direct)
    points = np.random.default_rng(0).random((50, 3))
    points[:, 2] = 1.0  # on the face zeta1
    np.testing.assert_array_equal(cached.apply(points), first.apply(points))
    # Other parameters, another file; a damaged file is recomputed, not trusted.
    assert layout.cache_path(semicylinder.with_params(radius=2.0)) != path
    path.write_bytes(b"not a layout")
    assert layout._read_layout(path) is None

"""Elliptic (Winslow) meshes: the discrete equations, the multigrid solver and the CLI.

The reference implementation below is written independently of meshgen.methods.winslow: node-array
layout, the cofactors as det(g) g^-1 (so it also checks design notes §5's formulas with their
squares), every derivative spelled out on a uniform grid, and a plain point-Jacobi iteration.
"""

import itertools
import json
import warnings

import numpy as np
import pytest
from mesh_checks import corner_jacobians

from meshgen.errors import MeshgenError
from meshgen.formats import metadata_of, read_mesh
from meshgen.geometry.plugins import load_geometry
from meshgen.methods.clustering import node_coordinates
from meshgen.methods.elliptic import ConvergenceWarning, build_elliptic, elliptic
from meshgen.methods.multigrid import along_axes, hierarchy, interpolation_matrix, solve_lines
from meshgen.methods.tfi import parametric_grid, tfi
from meshgen.methods.winslow import winslow_residual

# ---------------------------------------------------------------------------------------------
# independent reference: the discrete Winslow equations on a uniform grid, and point Jacobi


def _at(X, shift):
    """X (n1+1, ..., dim) at the interior nodes shifted by ``shift`` (one offset per axis)."""
    return X[tuple(slice(1 + s, X.shape[a] - 1 + s) for a, s in enumerate(shift))]


def reference_terms(X):
    """At the interior nodes of X on the uniform grid h_a = 1 / n_a: the Winslow residual
    sum_ab A_ab r_ab (not normalised), sum_a A_aa / h_a^2, and trace(A)."""
    dim = X.shape[-1]
    h = [1.0 / (n - 1) for n in X.shape[:-1]]
    unit = np.eye(dim, dtype=int)
    first = [(_at(X, unit[a]) - _at(X, -unit[a])) / (2 * h[a]) for a in range(dim)]
    g = np.stack([np.stack([np.sum(first[a] * first[b], axis=-1) for b in range(dim)], -1) for a in range(dim)], -1)
    adjugate = np.linalg.det(g)[..., None, None] * np.linalg.inv(g)  # the cofactor matrix of a symmetric g
    residual = 0.0
    for a, b in itertools.product(range(dim), repeat=2):
        if a == b:
            second = (_at(X, unit[a]) - 2 * _at(X, 0 * unit[a]) + _at(X, -unit[a])) / h[a] ** 2
        else:
            ea, eb = unit[a], unit[b]
            second = (_at(X, ea + eb) - _at(X, ea - eb) - _at(X, -ea + eb) + _at(X, -ea - eb)) / (4 * h[a] * h[b])
        residual = residual + adjugate[..., a, b][..., None] * second
    diagonal = sum(adjugate[..., a, a] / h[a] ** 2 for a in range(dim))
    return residual, diagonal, np.trace(adjugate, axis1=-2, axis2=-1)


def plain_jacobi(X, sweeps=200000, tol=1e-14):
    """Point Jacobi of the discrete equations: each interior node becomes the value that zeroes its
    own equation with the coefficients and neighbours of the previous sweep,
    x = (neighbour terms) / (2 sum_a A_aa / h_a^2)."""
    X = X.copy()
    interior = tuple(slice(1, -1) for _ in range(X.ndim - 1))
    scale = np.ptp(X.reshape(-1, X.shape[-1]), axis=0).max()
    for _ in range(sweeps):
        residual, diagonal, _ = reference_terms(X)
        step = residual / (2 * diagonal[..., None])
        X[interior] += step
        if np.abs(step).max() < tol * scale:
            return X
    raise AssertionError("plain Jacobi did not converge")


def min_angles(X):
    """Smallest face-corner angle of every cell in degrees (design notes §7): at each corner and
    each pair of index directions, the angle between the two cell edges leaving the corner."""
    dim = X.shape[-1]
    cells = tuple(n - 1 for n in X.shape[:-1])
    angles = []
    for corner in itertools.product((0, 1), repeat=dim):
        base = X[tuple(slice(c, c + n) for c, n in zip(corner, cells))]
        edges = []
        for a in range(dim):
            other = list(corner)
            other[a] = 1 - corner[a]
            edges.append(X[tuple(slice(c, c + n) for c, n in zip(other, cells))] - base)
        for a, b in itertools.combinations(range(dim), 2):
            cosine = np.sum(edges[a] * edges[b], -1) / np.linalg.norm(edges[a], axis=-1) / np.linalg.norm(edges[b], axis=-1)
            angles.append(np.degrees(np.arccos(np.clip(cosine, -1, 1))).reshape(-1))
    return np.min(angles, axis=0)


def affine_geometry(tmp_path, dim):
    """A plugin whose boundary map is affine (a sheared, stretched box): TFI is affine inside."""
    matrix = {2: "[[2.0, 0.5], [0.3, 1.0]]", 3: "[[2.0, 0.5, 0.1], [0.3, 1.0, -0.4], [0.2, 0.1, 3.0]]"}[dim]
    path = tmp_path / f"affine{dim}.py"
    path.write_text(
        "import numpy as np\n"
        f"name = 'affine{dim}'\ndim = {dim}\ndescription = 'affine box'\nparams = {{}}\n"
        f"def boundary(points):\n    return points @ np.array({matrix}).T + 1.5\n"
    )
    return load_geometry(str(path))


# ---------------------------------------------------------------------------------------------
# the discrete equations


@pytest.mark.parametrize("dims", [(7, 5), (4, 5, 3)])
def test_residual_matches_reference_implementation(dims):
    rng = np.random.default_rng(1)
    X = tfi(load_geometry("semidisk" if len(dims) == 2 else "semicylinder"), dims)
    X = X + 0.02 * rng.standard_normal(X.shape)  # any node array, not only smooth ones
    residual, _, trace = reference_terms(X)
    expected = residual / trace[..., None]
    np.testing.assert_allclose(winslow_residual(X), expected, rtol=1e-9, atol=1e-12 * np.abs(expected).max())


# ---------------------------------------------------------------------------------------------
# the solver


@pytest.mark.parametrize(
    "name, dims",
    [
        ("semidisk", (10, 6)),
        ("semidisk", (9, 7)),
        ("semidisk", (24, 20)),
        ("semicylinder", (6, 4, 6)),
        ("semicylinder", (5, 4, 7)),
        ("semicylinder", (10, 9, 8)),
    ],
)
def test_multigrid_converges_to_the_plain_jacobi_solution(name, dims):
    """Odd sizes (9, 7, 5) make non-nested coarse grids; the answer must not depend on them."""
    geometry = load_geometry(name)
    X0 = tfi(geometry, dims)
    X, info = elliptic(geometry, dims, tol=1e-13, boundary_layout="fixed")  # the solver on TFI's boundary
    assert info["converged"] and info["iterations"] < 20
    np.testing.assert_allclose(X, plain_jacobi(X0), rtol=0, atol=1e-10)
    np.testing.assert_array_equal(_boundary(X), _boundary(X0))  # boundary nodes stay exactly put


def _boundary(X):
    mask = np.zeros(X.shape[:-1], dtype=bool)
    for axis in range(X.ndim - 1):
        index = [slice(None)] * (X.ndim - 1)
        for end in (0, -1):
            index[axis] = end
            mask[tuple(index)] = True
    return X[mask]


@pytest.mark.parametrize("dim", [2, 3])
@pytest.mark.parametrize("clustered", [False, True])
def test_affine_map_is_a_fixed_point(tmp_path, dim, clustered):
    geometry = affine_geometry(tmp_path, dim)
    dims = (6, 5, 4)[:dim]
    coords = node_coordinates(dims, ["xi:both:1.3", "eta:0:1.2"] if clustered else [])
    X0 = tfi(geometry, None, coords)
    scale = np.abs(X0).max()
    assert np.abs(winslow_residual(X0, coords)).max() < 1e-12 * scale
    X, info = build_elliptic(geometry, coords)
    assert info["converged"] and info["iterations"] == 1 and info["final_update"] < 1e-12
    np.testing.assert_allclose(X, X0, rtol=0, atol=1e-12 * scale)


@pytest.mark.parametrize("name, dims", [("semidisk", (24, 20)), ("semicylinder", (12, 10, 8))])
def test_converged_residual_is_below_tolerance(name, dims):
    geometry = load_geometry(name)
    tol = 1e-8
    X, info = elliptic(geometry, dims, tol=tol)
    assert info["converged"] and info["final_update"] < tol
    residual, diagonal, _ = reference_terms(X)
    jacobi_step = np.linalg.norm(residual / (2 * diagonal[..., None]), axis=-1).max() / geometry.characteristic_length
    assert jacobi_step < tol
    assert info["final_residual"] == pytest.approx(jacobi_step, rel=1e-6)


def test_stretched_nodes_sample_the_same_map(tmp_path):
    """On stretched parametric nodes the solver discretises the same continuous Winslow map: the
    mesh approaches the fine uniform mesh interpolated at its parametric points at second order.
    (A smooth quarter annulus: the semidisk's flattened corners make its map singular there.)"""
    path = tmp_path / "annulus.py"
    path.write_text(
        "import numpy as np\nname = 'annulus'\ndim = 2\ndescription = 'quarter annulus'\nparams = {}\n"
        "def boundary(points):\n"
        "    radius, angle = 1 + points[:, 1], np.pi / 2 * points[:, 0]\n"
        "    return np.stack([radius * np.cos(angle), radius * np.sin(angle)], axis=1)\n"
    )
    geometry = load_geometry(str(path))
    fine, _ = elliptic(geometry, (256, 256), tol=1e-11)
    t = np.linspace(0.0, 1.0, 257)

    def bilinear(s1, s2):  # the fine mesh at parametric points s1 x s2
        i, j = (np.clip(np.searchsorted(t, s, side="right") - 1, 0, 255) for s in (s1, s2))
        u, v = ((s - t[k]) * 256 for s, k in ((s1, i), (s2, j)))
        u, v = u[:, None, None], v[None, :, None]
        rows, cols = np.meshgrid(i, j, indexing="ij")
        return (
            (1 - u) * (1 - v) * fine[rows, cols]
            + u * (1 - v) * fine[rows + 1, cols]
            + (1 - u) * v * fine[rows, cols + 1]
            + u * v * fine[rows + 1, cols + 1]
        )

    errors = []
    for n in (16, 32):
        s = np.linspace(0.0, 1.0, n + 1)
        coords = [np.expm1(1.5 * s) / np.expm1(1.5), s]  # one smooth stretching for every n
        X, info = elliptic(geometry, coords=coords, tol=1e-11)
        assert info["converged"]
        errors.append(np.abs(X - bilinear(*coords)).max())
    assert errors[1] < 3e-4 and errors[1] < errors[0] / 3, errors


@pytest.mark.parametrize("name, dims", [("semidisk", (32, 32)), ("semidisk", (48, 24)), ("semicylinder", (16, 16, 16))])
def test_no_inverted_cells(name, dims):
    X, info = elliptic(load_geometry(name), dims)
    assert info["converged"]
    jacobians = corner_jacobians(X)
    assert jacobians.min() > 0, f"{np.sum(jacobians.min(axis=0) <= 0)} inverted cells"


def test_elliptic_beats_tfi_on_mean_minimum_angle(semicylinder):
    dims = (16, 16, 16)
    X, _ = elliptic(semicylinder, dims)
    elliptic_angle, tfi_angle = min_angles(X).mean(), min_angles(tfi(semicylinder, dims)).mean()
    assert elliptic_angle > tfi_angle + 1.0, (elliptic_angle, tfi_angle)


def test_not_converging_is_reported():
    geometry = load_geometry("semidisk")
    with pytest.warns(ConvergenceWarning, match="did not converge"):
        X, info = elliptic(geometry, (16, 16), max_iter=1)
    assert not info["converged"] and info["iterations"] == 1 and info["final_update"] > 1e-6
    assert "1e-06" in info["warnings"][0] and f"{info['final_update']:.3g}" in info["warnings"][0]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        elliptic(geometry, (16, 16))  # converged: no warning


def test_progress_reports_each_cycle():
    calls = []
    _, info = elliptic(load_geometry("semidisk"), (16, 16), progress=lambda done, **figures: calls.append((done, figures)))
    assert [figures["cycle"] for _, figures in calls] == list(range(1, info["iterations"] + 1))
    assert calls[-1][0] == 1.0 and all(0.0 <= done <= 1.0 for done, _ in calls)
    assert calls[-1][1]["update"] == info["final_update"]


@pytest.mark.parametrize("options", [{"tol": 0.0}, {"tol": -1e-6}, {"tol": float("nan")}, {"max_iter": 0}])
def test_bad_options_raise(options):
    with pytest.raises(MeshgenError):
        elliptic(load_geometry("semidisk"), (8, 8), **options)


def test_one_cell_across_is_the_tfi_mesh(semicylinder):
    X, info = elliptic(semicylinder, (6, 1, 4), boundary_layout="fixed")
    np.testing.assert_array_equal(X, tfi(semicylinder, (6, 1, 4)))
    assert info["converged"] and info["iterations"] == 0


# ---------------------------------------------------------------------------------------------
# multigrid parts


def test_transfers_on_nested_and_odd_grids():
    fine = np.linspace(0.0, 1.0, 9)
    levels = hierarchy([fine, np.linspace(0.0, 1.0, 8)])  # 8 cells (nested) and 7 cells (not)
    assert [[len(t) - 1 for t in level.grid.coords] for level in levels] == [[8, 7], [4, 4]]
    level = levels[0]
    # solution restriction is injection where nodes coincide
    np.testing.assert_array_equal(level.restrict_solution[0] @ fine, fine[::2])
    # all transfers reproduce linear functions (so affine maps pass through untouched)
    coarse = levels[1].grid.coords
    for axis in range(2):
        t, tc = level.grid.coords[axis], coarse[axis]
        np.testing.assert_allclose(level.prolong[axis] @ (3 * tc - 1), 3 * t - 1, atol=1e-14)
        np.testing.assert_allclose(level.restrict_solution[axis] @ (3 * t - 1), 3 * tc - 1, atol=1e-14)
        np.testing.assert_allclose(level.restrict_residual[axis].sum(axis=1), 1.0)
    # full weighting (1/4, 1/2, 1/4) on the nested axis
    np.testing.assert_allclose(level.restrict_residual[0][2, 3:6], [0.25, 0.5, 0.25])
    F = np.random.default_rng(0).random((2, 9, 8))
    expected = np.einsum("ip,jq,cpq->cij", level.prolong[0].T, level.prolong[1].T, F)
    np.testing.assert_allclose(along_axes([m.T for m in level.prolong], F), expected)


def test_weakly_coupled_axis_waits_to_be_coarsened():
    """Cells 10 times longer along zeta couple 100 times more weakly along it: coarsen xi and eta
    first, until their coupling has dropped to zeta's."""
    coords = parametric_grid((32, 32, 32))
    sizes = [[len(t) - 1 for t in level.grid.coords] for level in hierarchy(coords, [1.0, 1.0, 0.01])]
    assert sizes == [[32, 32, 32], [16, 16, 32], [8, 8, 32], [4, 4, 16], [4, 4, 8], [4, 4, 4]]
    sizes = [[len(t) - 1 for t in level.grid.coords] for level in hierarchy(coords, [1.0, 0.5, 0.2])]
    assert sizes == [[32, 32, 32], [16, 16, 16], [8, 8, 8], [4, 4, 4]]


def test_interpolation_matrix_is_linear_interpolation():
    source, target = np.array([0.0, 0.3, 0.5, 1.0]), np.linspace(0.0, 1.0, 7)
    values = np.sin(source)
    np.testing.assert_allclose(interpolation_matrix(source, target) @ values, np.interp(target, source, values))


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_line_solver_matches_dense_solve(axis):
    rng = np.random.default_rng(axis)
    shape = (5, 6, 4)
    sub, sup = -0.3 * rng.random(shape), -0.3 * rng.random(shape)
    rhs = rng.random((3,) + shape)
    x = solve_lines(sub, sup, rhs, axis)
    m = shape[axis]
    for line in itertools.product(*[range(n) for a, n in enumerate(shape) if a != axis]):
        index = list(line)
        index.insert(axis, slice(None))
        index = tuple(index)
        matrix = np.eye(m) + np.diag(sub[index][1:], -1) + np.diag(sup[index][:-1], 1)
        for c in range(3):
            np.testing.assert_allclose(x[(c,) + index], np.linalg.solve(matrix, rhs[(c,) + index]), atol=1e-13)


# ---------------------------------------------------------------------------------------------
# command line


def test_cli_writes_the_library_mesh(run_cli, tmp_path, semidisk):
    result = run_cli("mesh", "--method", "elliptic", "-g", "semidisk", "--dims", "16", "16", "-o", "x.vtu")
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert lines[0].startswith("elliptic mesh of semidisk") and "(converged)" in lines[1]
    assert "\x1b" not in result.stdout and "\r" not in result.stdout  # no progress bar: not a terminal
    assert result.stderr == ""
    mesh = read_mesh(tmp_path / "x.vtu")
    X, info = elliptic(semidisk, (16, 16))
    np.testing.assert_allclose(mesh.points[:, :2], X.reshape(-1, 2), rtol=0, atol=1e-12)
    recorded = metadata_of(tmp_path / "x.vtu")["method_info"]
    assert recorded["converged"] and recorded["iterations"] == info["iterations"]
    assert recorded["final_residual"] < 1e-6 and "seconds" not in recorded  # timings stay out of mesh files
    report = json.loads((tmp_path / "x.vtu.quality.json").read_text())  # the quality report records them too
    assert report["method_info"]["iterations"] == info["iterations"] and report["inverted"]["count"] == 0
    assert report["method_info"]["seconds"] > 0


def test_cli_warns_when_not_converged(run_cli, tmp_path):
    result = run_cli("mesh", "-m", "elliptic", "-g", "semidisk", "--dims", "16", "16", "-o", "x.vtu", "--max-iter", "1", "-q")
    assert result.returncode == 0, result.stderr
    assert result.stdout == ""  # quiet, and no progress bar when stdout is not a terminal
    assert result.stderr.startswith("Warning: elliptic solver did not converge") and "1 cycle" in result.stderr
    assert not metadata_of(tmp_path / "x.vtu")["method_info"]["converged"]


def test_cli_rejects_a_bad_tolerance(run_cli, tmp_path):
    result = run_cli("mesh", "-m", "elliptic", "-g", "semidisk", "--dims", "8", "8", "-o", "x.vtu", "--tol", "0")
    assert result.returncode == 2 and result.stderr.startswith("Error: --tol must be a positive number")
    assert not (tmp_path / "x.vtu").exists()

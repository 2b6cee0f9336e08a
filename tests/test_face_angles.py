"""checkMesh's face non-orthogonality, its gradient, and the orthogonality polish of block sets
(meshgen.methods.face_angles): against closed forms, quality.merged's independent figures, finite
differences, and the TFI mesh the polish must not fall behind."""

import warnings
from pathlib import Path

import numpy as np
import pytest

from meshgen.geometry.block_nodes import merged_mesh
from meshgen.geometry.blocks import load_block_set, tfi_blocks
from meshgen.geometry.topology import topology_dims
from meshgen.methods import face_angles
from meshgen.methods.elliptic import elliptic_blocks
from meshgen.quality.faces import cell_metrics_unstructured
from meshgen.quality.merged import merged_solver_figures

TOPOLOGIES = Path(__file__).resolve().parents[1] / "examples" / "topologies"


def _grid(n, shear=0.0):
    """An n^3-cell unit-spaced grid, x sheared by ``shear`` per unit y: (points, VTK hexahedra)."""
    i, j, k = np.meshgrid(*[np.arange(n + 1.0)] * 3, indexing="ij")
    points = np.stack([i + shear * j, j, k], axis=-1).reshape(-1, 3)
    ids = np.arange((n + 1) ** 3).reshape((n + 1,) * 3)
    corner = [
        ids[a : a + n, b : b + n, c : c + n]
        for a, b, c in [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
    ]
    return points, np.stack([c.reshape(-1) for c in corner], axis=1)


def _degrees(cos):
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def test_a_sheared_grid_has_the_shear_angle_at_every_internal_face():
    points, cells = _grid(4, shear=0.3)
    internal, boundary = face_angles.face_cosines(points, cells)
    faces = face_angles.faces_of(cells)
    assert len(internal) == 3 * 3 * 16 and len(boundary) == 6 * 16
    normal_to_z = faces.slot >= 4
    # faces across x and across y: the angle is atan(shear); faces across z stay square
    np.testing.assert_allclose(_degrees(internal[~normal_to_z]), np.degrees(np.arctan(0.3)), atol=1e-9)
    np.testing.assert_allclose(_degrees(internal[normal_to_z]), 0.0, atol=1e-6)


def _perturbed_elbow(seed=1, amount=0.003):
    spec = str(TOPOLOGIES / "elbow-pipe-3d.yaml")
    block_set = load_block_set(spec, dims=topology_dims(spec))
    points, cells, block = merged_mesh(block_set, tfi_blocks(block_set))
    return block_set, points + np.random.default_rng(seed).normal(size=points.shape) * amount, cells


def test_the_angles_are_checkmeshs_as_quality_merged_measures_them():
    _, points, cells = _perturbed_elbow()
    internal, boundary = face_angles.largest_angles(points, cells)
    figures = merged_solver_figures(points, cells)[0]
    assert internal == pytest.approx(figures["non_orthogonality_internal"]["max"], abs=1e-9)
    assert boundary == pytest.approx(figures["non_orthogonality_boundary"]["max"], abs=1e-9)
    # a quad mesh, measured extruded as checkMesh sees a 2D case
    spec = str(TOPOLOGIES / "karman-2d.yaml")
    block_set = load_block_set(spec, dims=topology_dims(spec))
    points2, quads, _ = merged_mesh(block_set, tfi_blocks(block_set))
    figures2 = merged_solver_figures(points2, quads)[0]
    assert face_angles.largest_angles(points2, quads)[0] == pytest.approx(figures2["non_orthogonality_internal"]["max"], abs=1e-9)


def test_the_gradient_is_the_derivative():
    _, points, cells = _perturbed_elbow(seed=2)
    faces = face_angles.faces_of(cells)
    X = points[cells]
    orientation = face_angles._orientation(X)
    rng = np.random.default_rng(3)
    weights = rng.normal(size=len(faces.owner) + len(faces.cell))
    gradient = face_angles._cosine_gradient(X, orientation, faces, weights)
    for _ in range(3):
        step = rng.normal(size=X.shape) * 1e-6
        value = [float(weights @ face_angles._cosines(X + sign * step, orientation, faces)[0]) for sign in (1, -1)]
        assert (value[0] - value[1]) / 2 == pytest.approx(float(np.sum(gradient * step)), rel=1e-6)


def test_a_grid_with_shaken_interior_nodes_is_polished_below_the_threshold():
    points, cells = _grid(5)
    interior = np.flatnonzero(np.all((points > 0.5) & (points < 4.5), axis=1))
    shaken = points.copy()
    shaken[interior] += np.random.default_rng(4).uniform(-0.2, 0.2, (len(interior), 3))
    before = face_angles.largest_angles(shaken, cells)
    assert before[0] > 10.0
    moved, info = face_angles.reduce_non_orthogonality(shaken, cells, interior, (5.0, 5.0))
    after = face_angles.largest_angles(moved, cells)
    assert info["after"] == pytest.approx(after)
    assert after[0] < 5.2 and after[1] < 5.2  # the threshold, to the stopping tolerance
    boundary = np.setdiff1d(np.arange(len(points)), interior)
    np.testing.assert_array_equal(moved[boundary], shaken[boundary])
    # no corner's scaled Jacobian fell below the mesh's smallest before
    sj = lambda p: cell_metrics_unstructured(p, cells)["scaled_jacobian"].min()  # noqa: E731
    assert sj(moved) >= sj(shaken) - 1e-12


@pytest.mark.parametrize("name", ["elbow-pipe-3d.yaml", "periodic-channel-2d.yaml"])
def test_an_elliptic_block_set_is_no_less_orthogonal_than_its_tfi(name):
    spec = str(TOPOLOGIES / name)
    block_set = load_block_set(spec, dims=topology_dims(spec))
    start = tfi_blocks(block_set)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        plain, _ = elliptic_blocks(block_set, orthogonality=False)
        polished, info = elliptic_blocks(block_set)

    def figures(Xs):
        found = merged_solver_figures(*merged_mesh(block_set, Xs)[:2])[0]
        return found["non_orthogonality_internal"]["max"], found["non_orthogonality_boundary"]["max"]

    tfi, winslow, result = figures(start), figures(plain), figures(polished)
    assert winslow[0] > tfi[0] or winslow[1] > tfi[1]  # the Winslow mesh alone is less orthogonal here
    assert info["orthogonality"]["kept"]
    assert result[0] < min(winslow[0], tfi[0]) and result[1] <= winslow[1] + 1e-9
    if name.startswith("elbow"):
        assert result[1] < tfi[1]
    # nodes on the boundary stay where the solve put them
    on_boundary = face_angles.boundary_nodes(block_set)
    after, before = merged_mesh(block_set, polished)[0], merged_mesh(block_set, plain)[0]
    np.testing.assert_array_equal(after[on_boundary], before[on_boundary])
    assert np.abs(after - before).max() > 0


def test_the_mesh_command_says_what_the_polish_did(run_cli):
    result = run_cli(
        "mesh", "-g", str(TOPOLOGIES / "periodic-channel-2d.yaml"), "--method", "elliptic", "-o", "c.vtu", "--no-quality"
    )
    assert result.returncode == 0, result.stderr
    line = next(line for line in result.stdout.splitlines() if line.startswith("orthogonality polish:"))
    before, after = (float(v) for v in line.split("non-orthogonality ")[1].split(" deg")[0].split(" -> "))
    assert after < before and "nodes moved" in line and "not kept" not in line

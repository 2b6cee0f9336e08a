"""Quality metrics against closed forms, VTK's vtkMeshQuality (Verdict), and each other; boundary
deviation against exact distances; the report and the mesh command's sidecar."""

import json

import numpy as np
import pytest
from helpers import vtk_quality

from meshgen.geometry.grid import cell_connectivity, flat_points
from meshgen.methods.tfi import tfi
from meshgen.quality import (
    METRICS,
    STATS,
    cell_metrics,
    cell_metrics_unstructured,
    match_faces,
    quality_report,
    summary_lines,
    write_mesh_with_quality,
)
from meshgen.quality.deviation import boundary_deviation, distance_to_boundary, grid_boundary_nodes


def box(dims, lengths=None):
    """Node array of an axis-aligned box of ``dims`` cells with cell sizes ``lengths``."""
    lengths = lengths or [1.0] * len(dims)
    axes = [np.arange(n + 1) * h for n, h in zip(dims, lengths)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)


def perturbed(dims, sigma, seed):
    rng = np.random.default_rng(seed)
    X = box(dims, [1.0 / n for n in dims])
    return X + rng.normal(scale=sigma / max(dims), size=X.shape)


# ---------------------------------------------------------------------------------------------
# known answers


@pytest.mark.parametrize("dims", [(3, 4, 5), (4, 6)])
def test_unit_cells_are_perfect(dims):
    metrics = cell_metrics(box(dims))
    n_cells = int(np.prod(dims))
    expected = {
        "min_angle": 90.0,
        "max_angle": 90.0,
        "equiangle_skewness": 0.0,
        "aspect_ratio": 1.0,
        "centroid_skewness": 0.0,
        "non_orthogonality": 0.0,
        "scaled_jacobian": 1.0,
    }
    assert set(metrics) == set(METRICS)
    for name, value in expected.items():
        assert metrics[name].shape == (n_cells,)
        np.testing.assert_allclose(metrics[name], value, atol=1e-12, err_msg=name)


@pytest.mark.parametrize("shear", [0.3, 1.0, 2.5])
def test_sheared_box_matches_hand_computed_angles(shear):
    # x += shear * y: the edges along i are (1, 0, 0), along j (shear, 1, 0), along k (0, 0, 1).
    X = box((3, 4, 2))
    X[..., 0] += shear * X[..., 1]
    metrics = cell_metrics(X)
    acute = np.degrees(np.arctan2(1.0, shear))  # angle between (1,0,0) and (shear,1,0)
    stretch = np.hypot(1.0, shear)  # |(shear, 1, 0)|
    expected = {
        "min_angle": acute,
        "max_angle": 180.0 - acute,
        "equiangle_skewness": (90.0 - acute) / 90.0,
        "aspect_ratio": stretch,
        # faces normal to i have normal (1, -shear, 0)/stretch; centroid-to-face direction (1, 0, 0)
        "centroid_skewness": 1.0 - 1.0 / stretch,
        # every face: angle between (1, -shear, 0) and (1, 0, 0), or between (0, 1, 0) and (shear, 1, 0)
        "non_orthogonality": np.degrees(np.arctan(shear)),
        "scaled_jacobian": 1.0 / stretch,
    }
    for name, value in expected.items():
        np.testing.assert_allclose(metrics[name], value, rtol=1e-12, atol=1e-12, err_msg=name)


def test_stretched_box_has_the_ratio_of_its_sides():
    metrics = cell_metrics(box((3, 2, 4), [4.0, 1.0, 0.5]))
    np.testing.assert_allclose(metrics["aspect_ratio"], 8.0, rtol=1e-14)
    np.testing.assert_allclose(metrics["min_angle"], 90.0, atol=1e-12)
    np.testing.assert_allclose(metrics["scaled_jacobian"], 1.0, atol=1e-14)
    metrics_2d = cell_metrics(box((3, 2), [0.2, 1.4]))
    np.testing.assert_allclose(metrics_2d["aspect_ratio"], 7.0, rtol=1e-14)


def inside_out(n_cells):
    """A row of unit cubes along x in which the node layer after cell k is pushed past the next
    layer: cell k+1 is turned inside out (its i-edges point backwards), the rest stay valid."""
    X = box((n_cells, 1, 1))
    k = n_cells // 2
    X[k + 1, ..., 0] = k + 2.5
    return X, k + 1


def test_a_cell_turned_inside_out_is_inverted_and_makes_the_mesh_invalid():
    X, bad = inside_out(200)
    metrics = cell_metrics(X)
    np.testing.assert_allclose(metrics["scaled_jacobian"][bad], -1.0, atol=1e-14)
    assert np.all(metrics["scaled_jacobian"][np.arange(200) != bad] > 0)
    # The cell is still a box: angles alone do not see that it is inside out.
    np.testing.assert_allclose(metrics["min_angle"][bad], 90.0, atol=1e-12)
    report = quality_report(X)
    assert report["inverted"] == {"count": 1, "fraction": 1 / 200, "degenerate": 0}
    assert not report["valid"]  # strict: one inverted cell of 200 is one too many
    assert quality_report(box((200, 1, 1)))["valid"]


def test_a_quad_turned_over_is_inverted_against_the_mesh_orientation():
    X = box((6, 5))
    X[6, :, 0] = 4.5  # the last column of quads folds back over its neighbours
    metrics = cell_metrics(X)
    sj = metrics["scaled_jacobian"].reshape(6, 5)
    np.testing.assert_allclose(sj[5], -1.0, atol=1e-14)
    assert np.all(sj[:5] > 0)
    # Mirroring the whole mesh keeps every quad valid: orientation is the mesh's, not +z.
    mirrored = X.copy()
    mirrored[..., 0] *= -1
    np.testing.assert_allclose(cell_metrics(mirrored)["scaled_jacobian"], metrics["scaled_jacobian"], atol=1e-14)


def test_degenerate_and_non_finite_cells_are_inverted_and_never_nan_in_summaries():
    X = box((4, 3, 3))
    X[1, 1, 1] = X[1, 1, 0]  # a zero-length edge: the cells around it collapse
    X[4, 3, 3] = np.nan  # a corner node: its one cell has no shape
    metrics = cell_metrics(X)
    report = quality_report(X)
    degenerate = report["inverted"]["degenerate"]
    assert degenerate == 4 + 1
    assert report["inverted"]["count"] >= degenerate
    for name in METRICS:
        assert not np.any(np.isnan(metrics[name])), name
        for stat in STATS:
            value = report["metrics"][name][stat]
            assert value is not None and np.isfinite(value), (name, stat)
    assert any("non-finite" in w for w in report["warnings"])
    # Degenerate: the four cells around the collapsed edge and the one at the NaN corner. They get
    # the worst values; the summaries describe the other cells.
    shapeless = np.zeros((4, 3, 3), dtype=bool)
    shapeless[:2, :2, 0] = shapeless[3, 2, 2] = True
    shapeless = shapeless.reshape(-1)
    assert np.all(metrics["min_angle"][shapeless] == 0.0) and np.all(metrics["scaled_jacobian"][shapeless] <= 0.0)
    assert report["metrics"]["min_angle"]["min"] == metrics["min_angle"][~shapeless].min()
    assert report["metrics"]["aspect_ratio"]["max"] == metrics["aspect_ratio"][~shapeless].max()


# ---------------------------------------------------------------------------------------------
# VTK's vtkMeshQuality (Verdict)


@pytest.mark.parametrize("sigma", [0.05, 0.2, 0.3])
def test_hexahedra_agree_with_vtk_mesh_quality(sigma):
    X = perturbed((8, 7, 6), sigma, seed=int(sigma * 100))
    points, cells = flat_points(X), cell_connectivity(X.shape[:-1])
    metrics = cell_metrics(X)
    vtk_sj = vtk_quality(points, cells, "SetHexQualityMeasureToScaledJacobian")
    vtk_skew = vtk_quality(points, cells, "SetHexQualityMeasureToEquiangleSkew")
    np.testing.assert_allclose(metrics["scaled_jacobian"], vtk_sj, rtol=0, atol=1e-10)
    np.testing.assert_allclose(metrics["equiangle_skewness"], vtk_skew, rtol=0, atol=1e-10)
    if sigma >= 0.2:  # the strong perturbations do fold cells and faces: those cases are covered
        assert np.any(metrics["scaled_jacobian"] <= 0) and np.any(metrics["max_angle"] > 180)


@pytest.mark.parametrize("sigma", [0.05, 0.25])
def test_quads_agree_with_vtk_mesh_quality(sigma):
    X = perturbed((14, 11), sigma, seed=7)
    points, cells = flat_points(X), cell_connectivity(X.shape[:-1])
    metrics = cell_metrics(X)
    np.testing.assert_allclose(
        metrics["scaled_jacobian"], vtk_quality(points, cells, "SetQuadQualityMeasureToScaledJacobian"), atol=1e-10
    )
    np.testing.assert_allclose(
        metrics["equiangle_skewness"], vtk_quality(points, cells, "SetQuadQualityMeasureToEquiangleSkew"), atol=1e-10
    )


# ---------------------------------------------------------------------------------------------
# structured and unstructured paths


@pytest.mark.parametrize("dims", [(6, 5, 4), (9, 7)])
def test_structured_and_unstructured_paths_agree(dims):
    X = perturbed(dims, 0.25, seed=3)
    metrics = cell_metrics(X)
    points, cells = flat_points(X, width=X.shape[-1]), cell_connectivity(X.shape[:-1])
    # Shuffle nodes and cells: the unstructured path must find the neighbours itself.
    rng = np.random.default_rng(1)
    node_order, cell_order = rng.permutation(len(points)), rng.permutation(len(cells))
    new_id = np.argsort(node_order)
    shuffled = cell_metrics_unstructured(points[node_order], new_id[cells[cell_order]])
    for name in METRICS:
        np.testing.assert_allclose(shuffled[name], metrics[name][cell_order], rtol=1e-13, atol=1e-12, err_msg=name)
    # 2D points may also come as (N, 3) with z = const, as meshio reads them.
    if len(dims) == 2:
        planar = cell_metrics_unstructured(flat_points(X) + [0.0, 0.0, 2.0], cells)
        np.testing.assert_allclose(planar["non_orthogonality"], metrics["non_orthogonality"], atol=1e-12)


def test_face_matching_survives_hash_collisions_and_finds_non_manifold_faces():
    X = perturbed((4, 3, 3), 0.1, seed=0)
    cells = cell_connectivity(X.shape[:-1])
    from meshgen.quality import HEX_FACE_CORNERS

    faces = [cells[:, HEX_FACE_CORNERS[:, j]].reshape(-1) for j in range(4)]
    partner, nonmanifold = match_faces(faces)
    constant, nm = match_faces(faces, hash_rows=lambda columns: np.zeros(len(columns[0]), dtype=np.uint64))
    np.testing.assert_array_equal(partner, constant)
    assert nonmanifold == nm == 0
    interior = 3 * 3 * 3 + 4 * 2 * 3 + 4 * 3 * 2  # faces between two cells
    assert np.count_nonzero(partner >= 0) == 2 * interior
    assert np.all(partner[partner[partner >= 0]] == np.flatnonzero(partner >= 0))
    # A duplicated corner cell: its three interior faces are now used by three cells (non-manifold);
    # its three boundary faces pair with the duplicate.
    doubled = np.vstack([cells, cells[:1]])
    faces = [doubled[:, HEX_FACE_CORNERS[:, j]].reshape(-1) for j in range(4)]
    partner, nonmanifold = match_faces(faces)
    assert nonmanifold == 3 * 3
    assert np.count_nonzero(partner[:6] >= 0) == 3 and np.all(partner[partner[:6][partner[:6] >= 0]] < 6)


# ---------------------------------------------------------------------------------------------
# boundary deviation


def test_tfi_meshes_lie_on_the_true_boundary(semicylinder, semidisk):
    for geometry, dims in ((semicylinder, (12, 10, 8)), (semidisk, (30, 20))):
        X = tfi(geometry, dims)
        points, guesses = grid_boundary_nodes(X)
        for guess in (guesses, None):  # structured seeds, and the search unstructured files take
            deviation = boundary_deviation(points, geometry, parametric_guess=guess)
            assert deviation["max_rel"] < 1e-12
            assert deviation["nodes"] == len(points)


def semicylinder_distance(points, radius=1.0, length=2.0):
    """Exact distance to the surface of the half-cylinder for points inside it."""
    x, y, z = points.T
    return np.minimum.reduce([radius - np.hypot(x, y), y, z, length - z])


@pytest.mark.parametrize("shrink", [0.01, 0.05])
def test_a_shrunk_mesh_deviates_by_the_shrink_distance(semicylinder, shrink):
    X = tfi(semicylinder, (16, 14, 10))
    X[..., :2] *= 1.0 - shrink  # pull the section in: arc nodes move shrink off the arc
    points, guesses = grid_boundary_nodes(X)
    exact = semicylinder_distance(points)
    for guess in (guesses, None):
        deviation = boundary_deviation(points, semicylinder, parametric_guess=guess)
        assert deviation["max"] == pytest.approx(shrink, rel=1e-9)
        assert deviation["mean"] == pytest.approx(exact.mean(), rel=1e-9)
        assert deviation["max_rel"] == pytest.approx(shrink / semicylinder.characteristic_length, rel=1e-9)


def test_distance_from_outside_and_inside_in_2d(semidisk):
    X = tfi(semidisk, (24, 16))
    points, _ = grid_boundary_nodes(X)
    for scale in (0.97, 1.03):
        moved = points * scale
        r, y = np.hypot(*moved.T), moved[:, 1]
        # inside: nearest of arc and diameter; outside (y >= 0): radial distance to the arc
        exact = np.minimum(1.0 - r, y) if scale < 1 else np.maximum(r - 1.0, 0.0)
        np.testing.assert_allclose(distance_to_boundary(moved, semidisk), exact, atol=1e-11)


def test_nonfinite_boundary_nodes_make_the_deviation_undefined(semidisk):
    X = tfi(semidisk, (6, 4))
    X[0, 0] = np.inf
    deviation = boundary_deviation(X, semidisk)
    assert deviation["max"] is None and deviation["nonfinite_nodes"] == 1


# ---------------------------------------------------------------------------------------------
# report and the mesh command's output


def test_report_schema_and_summary(semicylinder):
    X = tfi(semicylinder, (8, 6, 5))
    report = quality_report(X, semicylinder)
    for key in ("cells", "dim", "metrics", "inverted", "valid", "boundary_deviation"):
        assert key in report
    assert report["cells"] == 240 and report["dim"] == 3
    assert set(report["metrics"]) == set(METRICS)
    metrics = cell_metrics(X)
    for name in METRICS:
        assert set(report["metrics"][name]) == set(STATS)
        assert report["metrics"][name]["mean"] == pytest.approx(metrics[name].mean())
        assert report["metrics"][name]["p99"] == pytest.approx(np.percentile(metrics[name], 99))
    assert set(report["inverted"]) >= {"count", "fraction"}
    assert set(report["boundary_deviation"]) >= {"max", "mean", "max_rel", "mean_rel", "characteristic_length"}
    json.dumps(report, allow_nan=False)  # JSON-ready
    lines = summary_lines(report)
    assert f"{report['metrics']['min_angle']['mean']:.3g}" in lines[0]
    assert "valid" in "\n".join(lines)


def test_mesh_files_carry_the_metrics_and_a_sidecar(tmp_path, semidisk):
    meshio = pytest.importorskip("meshio")
    X = tfi(semidisk, (10, 7))
    path = tmp_path / "disk.vtu"
    metadata = {"geometry": "semidisk", "params": semidisk.values, "method": "tfi", "dims": [10, 7]}
    report = write_mesh_with_quality(path, X, semidisk, metadata)
    metrics = cell_metrics(X)
    mesh = meshio.read(path)
    for name in METRICS:
        np.testing.assert_allclose(mesh.cell_data[name][0], metrics[name], rtol=1e-15)
    sidecar = json.loads((tmp_path / "disk.vtu.quality.json").read_text())
    assert sidecar["geometry"] == "semidisk" and sidecar["method"] == "tfi"
    assert sidecar["cells"] == 70 and sidecar["metrics"] == json.loads(json.dumps(report["metrics"]))

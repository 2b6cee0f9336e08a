"""The end-of-training quality summary against VTK's vtkMeshQuality (Verdict) and closed forms."""

import numpy as np
import pytest

from meshgen.geometry import load_geometry
from meshgen.grid import cell_connectivity, flat_points
from meshgen.neural.report import boundary_deviation, corner_angles, quality_summary, snap_boundary
from meshgen.tfi import parametric_grid, tfi

vtk = pytest.importorskip("vtk")
from vtk.util.numpy_support import numpy_to_vtk, vtk_to_numpy  # noqa: E402


def vtk_quality(X, measure):
    """Per-cell quality of the node array X by vtkMeshQuality."""
    points = vtk.vtkPoints()
    points.SetData(numpy_to_vtk(flat_points(X), deep=True))
    cells = cell_connectivity(X.shape[:-1])
    grid = vtk.vtkUnstructuredGrid()
    grid.SetPoints(points)
    cell_type = vtk.VTK_HEXAHEDRON if X.shape[-1] == 3 else vtk.VTK_QUAD
    for cell in cells:
        grid.InsertNextCell(cell_type, len(cell), [int(i) for i in cell])
    quality = vtk.vtkMeshQuality()
    quality.SetInputData(grid)
    getattr(quality, f"Set{'Hex' if X.shape[-1] == 3 else 'Quad'}QualityMeasureTo{measure}")()
    quality.Update()
    return vtk_to_numpy(quality.GetOutput().GetCellData().GetArray("Quality"))


def perturbed_semicylinder(cells=6, seed=0):
    geometry = load_geometry("semicylinder")
    X = tfi(geometry, (cells, cells, cells))
    X[1:-1, 1:-1, 1:-1] += np.random.default_rng(seed).normal(scale=0.12, size=X[1:-1, 1:-1, 1:-1].shape)
    return geometry, X


def test_min_angle_of_quads_matches_vtk():
    geometry = load_geometry("semidisk")
    X = tfi(geometry, (12, 9))
    X[1:-1, 1:-1] += np.random.default_rng(1).normal(scale=0.01, size=X[1:-1, 1:-1].shape)
    ours = corner_angles(X).reshape(-1, 4).min(axis=1)
    np.testing.assert_allclose(ours, vtk_quality(X, "MinAngle"), atol=1e-8)
    ours_max = corner_angles(X).reshape(-1, 4).max(axis=1)
    np.testing.assert_allclose(ours_max, vtk_quality(X, "MaxAngle"), atol=1e-8)


def test_inverted_hexahedra_match_vtk_scaled_jacobian():
    geometry, X = perturbed_semicylinder()
    summary = quality_summary(X, geometry, parametric_grid((6, 6, 6)))
    assert summary["inverted"] == int(np.count_nonzero(vtk_quality(X, "ScaledJacobian") <= 0))
    assert 0 < summary["inverted"] < summary["cells"]


def test_boundary_deviation_and_snapping():
    geometry = load_geometry("semicylinder")
    coords = parametric_grid((5, 4, 3))
    X = tfi(geometry, (5, 4, 3))
    assert boundary_deviation(X, geometry, coords).max() < 1e-13
    moved = X.copy()
    moved[0, 2, 1] += np.array([0.0, 0.3, 0.4])  # a boundary node pushed 0.5 off
    moved[2, 2, 1] += 1.0  # an interior node does not count
    deviation = boundary_deviation(moved, geometry, coords)
    assert deviation.max() == pytest.approx(0.5) and np.count_nonzero(deviation > 1e-12) == 1
    assert deviation.size == 6 * 5 * 4 - 4 * 3 * 2  # all nodes minus the interior ones
    np.testing.assert_allclose(snap_boundary(moved, geometry, coords)[0], X[0], atol=1e-14)
    summary = quality_summary(moved, geometry, coords)
    assert summary["boundary_deviation_max"] == pytest.approx(0.5)
    assert summary["boundary_deviation_max_relative"] == pytest.approx(0.5 / geometry.characteristic_length)


def test_a_unit_cube_grid_has_right_angles():
    axes = np.meshgrid(*parametric_grid((3, 4, 2)), indexing="ij")
    X = np.stack(axes, axis=-1)
    angles = corner_angles(X)
    np.testing.assert_allclose(angles, 90.0, atol=1e-12)
    assert angles.shape == (3, 4, 2, 24)

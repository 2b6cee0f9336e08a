""".vts, .su2 and .msh: read back by VTK, meshio and Gmsh itself, with their patches; and
`meshgen evaluate` reads every patch-carrying format."""

import json
import re
import shutil
import subprocess

import numpy as np
import pytest

from meshgen.formats import read_mesh, read_patches, write_mesh
from meshgen.geometry import cube
from meshgen.geometry.patches import geometry_patches
from meshgen.geometry.plugins import load_geometry
from meshgen.methods.tfi import tfi
from meshgen.quality import cell_metrics, quality_report

gmsh = shutil.which("gmsh")


def expected_corners(X):
    """(cells, corners, dim): corner coordinates of each cell in C order, VTK corner order."""
    dim = X.shape[-1]
    offsets = (
        [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
        if dim == 3
        else [(0, 0), (1, 0), (1, 1), (0, 1)]
    )
    cells = tuple(n - 1 for n in X.shape[:-1])
    return np.stack([X[tuple(slice(o, o + c) for o, c in zip(offset, cells))].reshape(-1, dim) for offset in offsets], axis=1)


def face_count(dims, face_name):
    face = cube.face_named(face_name, len(dims))
    return int(np.prod([n for d, n in enumerate(dims) if d != face.axis]))


@pytest.fixture(scope="module", params=[("flower", (3, 4, 5)), ("bump", (5, 3))], ids=["3d", "2d"])
def case(request):
    name, dims = request.param
    geometry = load_geometry(name)
    return geometry, dims, tfi(geometry, dims), geometry_patches(geometry)


# --- .vts ------------------------------------------------------------------------------------


def vtk_read_vts(path):
    vtk = pytest.importorskip("vtk")
    reader = vtk.vtkXMLStructuredGridReader()
    reader.SetFileName(str(path))
    reader.Update()
    return reader.GetOutput()


def test_vtk_reads_the_vts_with_the_same_points_quality_and_patch_ids(tmp_path, case):
    from vtk.util.numpy_support import vtk_to_numpy

    geometry, dims, X, patches = case
    metrics = cell_metrics(X)
    path = write_mesh(tmp_path / "m.vts", X, metrics, {"geometry": geometry.name}, patches=patches)
    grid = vtk_read_vts(path)
    dim = X.shape[-1]
    extent = [0, 0, 0]
    grid.GetDimensions(extent)
    assert extent[:dim] == [n + 1 for n in dims]
    # VTK's structured order runs i fastest: the transpose of meshgen's C order.
    fortran = np.transpose(X, (*range(dim - 1, -1, -1), dim)).reshape(-1, dim)
    points = vtk_to_numpy(grid.GetPoints().GetData())
    np.testing.assert_array_equal(points[:, :dim], fortran)
    stored = vtk_to_numpy(grid.GetCellData().GetArray("scaled_jacobian"))
    expected = np.transpose(metrics["scaled_jacobian"].reshape(dims)).reshape(-1)
    np.testing.assert_allclose(stored, expected, rtol=1e-6)  # Float32
    # Patch ids: every node of the inlet face (x = 0 for the bump, z = 0 for the flower) and no other.
    ids = vtk_to_numpy(grid.GetPointData().GetArray("patch"))
    inlet = [p.name for p in patches].index("inlet")
    axis = 0 if dim == 2 else 2
    on_inlet = np.isclose(points[:, axis], 0.0, atol=1e-12)
    # Nodes on the inlet's rim may belong to a patch listed before it (the first listed wins).
    assert np.all(on_inlet[ids == inlet]) and np.all(np.isin(ids[on_inlet], np.arange(inlet + 1)))
    interior = np.ones(X.shape[:-1], dtype=bool)
    interior[tuple(slice(1, -1) for _ in range(dim))] = False
    assert np.array_equal(ids >= 0, np.transpose(interior).reshape(-1))


def test_vtk_mesh_quality_on_the_vts_agrees_with_meshgen_evaluate(tmp_path, run_cli):
    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import vtk_to_numpy

    geometry = load_geometry("canal")
    X = tfi(geometry, (4, 5, 6))
    path = write_mesh(tmp_path / "m.vts", X, patches=geometry_patches(geometry))
    quality = vtk.vtkMeshQuality()
    quality.SetInputData(vtk_read_vts(path))
    quality.SetHexQualityMeasureToScaledJacobian()
    quality.Update()
    scaled_jacobian = vtk_to_numpy(quality.GetOutput().GetCellData().GetArray("Quality"))
    quality.SetHexQualityMeasureToEquiangleSkew()
    quality.Update()
    skew = vtk_to_numpy(quality.GetOutput().GetCellData().GetArray("Quality"))
    result = run_cli("evaluate", "m.vts", "--json", "-")
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report["cells"] == len(scaled_jacobian) == 120
    for name, values in (("scaled_jacobian", scaled_jacobian), ("equiangle_skewness", skew)):
        for stat, value in (("mean", values.mean()), ("min", values.min()), ("max", values.max())):
            assert report["metrics"][name][stat] == pytest.approx(value, rel=1e-9, abs=1e-12), (name, stat)


def test_vts_is_read_back_by_our_reader(tmp_path, case):
    geometry, dims, X, patches = case
    metrics = cell_metrics(X)
    path = write_mesh(tmp_path / "m.vts", X, metrics, {"geometry": geometry.name, "dims": list(dims)}, patches=patches)
    mesh = read_mesh(path)
    np.testing.assert_array_equal(mesh.points[:, : X.shape[-1]], X.reshape(-1, X.shape[-1]))
    np.testing.assert_array_equal(mesh.points[mesh.cells[0].data][..., : X.shape[-1]], expected_corners(X))
    np.testing.assert_allclose(mesh.cell_data["min_angle"][0], metrics["min_angle"], rtol=1e-6)
    assert read_patches(path) == patches


# --- .su2 and .msh -----------------------------------------------------------------------------


@pytest.mark.parametrize("extension", [".su2", ".msh"])
def test_meshio_reads_su2_and_msh_with_the_same_points_cells_and_boundary_elements(tmp_path, case, extension):
    import meshio

    geometry, dims, X, patches = case
    path = write_mesh(tmp_path / f"m{extension}", X, patches=patches)
    mesh = meshio.read(path)
    dim = X.shape[-1]
    np.testing.assert_array_equal(mesh.points[:, :dim], X.reshape(-1, dim))
    volume = "hexahedron" if dim == 3 else "quad"
    cells = np.concatenate([b.data for b in mesh.cells if b.type == volume])
    np.testing.assert_array_equal(mesh.points[cells][..., :dim], expected_corners(X))
    boundary_type = "quad" if dim == 3 else "line"
    boundary = sum(len(b.data) for b in mesh.cells if b.type == boundary_type)
    assert boundary == sum(face_count(dims, face) for face in cube.face_names(dim))
    assert read_patches(path) == patches


def test_su2_markers_hold_each_patchs_faces_with_outward_normals(tmp_path):
    geometry = load_geometry("semicylinder")
    dims = (3, 4, 5)
    X = tfi(geometry, dims)
    path = write_mesh(tmp_path / "m.su2", X, patches=geometry_patches(geometry))
    text = path.read_text()
    points = X.reshape(-1, 3)
    centre = points.mean(axis=0)
    blocks = re.findall(r"MARKER_TAG= (\S+)\nMARKER_ELEMS= (\d+)\n((?:9 .*\n?)*)", text)
    assert [name for name, _, _ in blocks] == ["wall", "symmetry", "inlet", "outlet"]
    for name, count, body in blocks:
        faces = np.array(body.split(), dtype=int).reshape(int(count), 5)[:, 1:]
        expected = sum(face_count(dims, f) for p in geometry_patches(geometry) if p.name == name for f in p.faces)
        assert len(faces) == expected
        quads = points[faces]
        normals = np.cross(quads[:, 2] - quads[:, 0], quads[:, 3] - quads[:, 1])
        outward = quads.mean(axis=1) - centre  # the semicylinder is convex
        assert np.all(np.einsum("ij,ij->i", normals, outward) > 0), name
    assert read_patches(path) == geometry_patches(geometry)


@pytest.mark.skipif(gmsh is None, reason="gmsh not installed (Debian package gmsh)")
def test_gmsh_opens_the_msh_and_sees_the_physical_groups(tmp_path, case):
    """Gmsh reads our MSH 4.1 file and writes it out again as MSH 2.2: its physical names and the
    elements it puts in each group are what it understood."""
    geometry, dims, X, patches = case
    path = write_mesh(tmp_path / "m.msh", X, patches=patches)
    result = subprocess.run(
        [gmsh, str(path), "-0", "-o", str(tmp_path / "out.msh"), "-format", "msh22"], capture_output=True, text=True, timeout=60
    )
    assert result.returncode == 0 and "Error" not in result.stdout + result.stderr, result.stdout + result.stderr
    text = (tmp_path / "out.msh").read_text()
    names = {int(tag): (int(d), name) for d, tag, name in re.findall(r'^(\d) (\d+) "([^"]+)"$', text, re.M)}
    dim = X.shape[-1]
    assert sorted(names.values()) == sorted([(dim, "domain")] + [(dim - 1, p.name) for p in patches])
    elements = text.split("$Elements\n", 1)[1].split("$EndElements", 1)[0].split("\n")[1:-1]
    per_group = {}
    for line in elements:  # number type ntags physical elementary nodes...
        physical = int(line.split()[3])
        per_group[names[physical][1]] = per_group.get(names[physical][1], 0) + 1
    expected = {p.name: sum(face_count(dims, f) for f in p.faces) for p in patches}
    assert per_group == {**expected, "domain": int(np.prod(dims))}


# --- meshgen evaluate and bad input -----------------------------------------------------------------


@pytest.mark.parametrize("target", ["m.vts", "m.su2", "m.msh", "m.cgns"])
def test_evaluate_reads_every_patch_format_meshgen_mesh_writes(run_cli, tmp_path, target):
    result = run_cli("mesh", "--method", "tfi", "-g", "topcurve", "--dims", "3", "4", "5", "-o", target)
    assert result.returncode == 0, result.stderr
    assert "patches: inlet (patch: xi0), outlet (patch: xi1), sides (symmetry: eta0 eta1)" in result.stdout
    evaluated = run_cli("evaluate", target, "--json", "-")
    assert evaluated.returncode == 0 and "Warning" not in evaluated.stderr, evaluated.stderr
    report = json.loads(evaluated.stdout)
    geometry = load_geometry("topcurve")
    expected = quality_report(tfi(geometry, (3, 4, 5)), geometry)
    assert report["cells"] == 60 and "skipped" not in report
    for name in ("min_angle", "non_orthogonality", "scaled_jacobian"):
        assert report["metrics"][name]["mean"] == pytest.approx(expected["metrics"][name]["mean"], rel=1e-12)
    assert report["boundary_deviation"]["max"] < 1e-12  # the geometry came from the file's metadata


@pytest.mark.parametrize(
    "target, patch, message",
    [
        ("m.su2", "zeta0=in(1)", "SU2 marker"),
        ("m.msh", "zeta0=domain", "physical group of the cells"),
        ("m.cgns", "zeta0=" + "p" * 30, "too long for CGNS"),
    ],
)
def test_patch_name_invalid_for_the_format_is_one_line_exit_2(run_cli, tmp_path, target, patch, message):
    result = run_cli("mesh", "--method", "tfi", "--dims", "3", "3", "3", "--patch", patch, "-o", target)
    assert result.returncode == 2 and message in result.stderr and len(result.stderr.strip().splitlines()) == 1
    assert list(tmp_path.iterdir()) == []

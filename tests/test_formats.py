"""Mesh exporters: round trips through our readers, meshio and VTK's readers; cgnscheck; metadata;
orientation; atomic writes; errors."""

import json
import os
import shutil
import subprocess

import numpy as np
import pytest
from vtk.util.numpy_support import vtk_to_numpy

from meshgen.errors import FormatError
from meshgen.formats import extensions, metadata_of, read_mesh, write_mesh
from meshgen.geometry.plugins import load_geometry
from meshgen.methods.tfi import tfi

ALL_EXTENSIONS = [".vtu", ".vtk", ".xdmf", ".cgns", ".xyz", ".fmt"]
WITH_CELL_DATA = [".vtu", ".vtk", ".xdmf", ".cgns"]
METADATA = {
    "method": "tfi",
    "geometry": "semicylinder",
    "params": {"radius": 1.0},
    "dims": [6, 5, 4],
    "note": "quotes \" ' and < & > survive",
    "numpy": np.float64(0.25),
}
# Corner offsets (di, dj, dk) of VTK's hexahedron and quad, written out from VTK's documentation.
HEX_CORNERS = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
QUAD_CORNERS = [(0, 0), (1, 0), (1, 1), (0, 1)]

cgnscheck = shutil.which("cgnscheck")
needs_cgnscheck = pytest.mark.skipif(cgnscheck is None, reason="cgnscheck not installed (Debian package cgns-convert)")


@pytest.fixture(scope="module", params=[3, 2], ids=["3d", "2d"])
def mesh(request):
    """(X, cell_data): the semicylinder by TFI at 6x5x4 cells or the semidisk at 5x4."""
    if request.param == 3:
        X = tfi(load_geometry("semicylinder"), (6, 5, 4))
    else:
        X = tfi(load_geometry("semidisk"), (5, 4))
    cells = int(np.prod([n - 1 for n in X.shape[:-1]]))
    rng = np.random.default_rng(request.param)
    return X, {"scaled_jacobian": rng.random(cells), "index": np.arange(cells, dtype=float)}


def padded_points(X):
    points = X.reshape(-1, X.shape[-1])
    return np.hstack([points, np.zeros((len(points), 3 - points.shape[1]))])


def fortran_points(X):
    """Nodes with i fastest (VTK's structured-grid order), padded to 3 columns."""
    dim = X.shape[-1]
    return padded_points(np.transpose(X, (*range(dim - 1, -1, -1), dim)))


def expected_corners(X):
    """(cells, corners, 3): the corner coordinates of every cell in C order of the cells."""
    dim = X.shape[-1]
    points = np.concatenate([X, np.zeros(X.shape[:-1] + (3 - dim,))], axis=-1)
    cell_shape = tuple(n - 1 for n in X.shape[:-1])
    corners = HEX_CORNERS if dim == 3 else QUAD_CORNERS
    return np.stack(
        [points[tuple(slice(o, o + c) for o, c in zip(offset, cell_shape))].reshape(-1, 3) for offset in corners],
        axis=1,
    )


# --- round trips ---------------------------------------------------------------------------


@pytest.mark.parametrize("extension", ALL_EXTENSIONS)
def test_written_mesh_reads_back_with_the_same_points_cells_cell_data_and_metadata(tmp_path, mesh, extension):
    X, cell_data = mesh
    path = write_mesh(tmp_path / f"mesh{extension}", X, cell_data, METADATA)
    read = read_mesh(path)

    np.testing.assert_array_equal(read.points, padded_points(X))
    assert len(read.cells) == 1 and read.cells[0].type == ("hexahedron" if X.shape[-1] == 3 else "quad")
    np.testing.assert_array_equal(read.points[read.cells[0].data], expected_corners(X))
    if extension in WITH_CELL_DATA:
        assert set(read.cell_data) == set(cell_data)
        for name, values in cell_data.items():
            np.testing.assert_array_equal(read.cell_data[name][0], values)
        assert metadata_of(path) == json.loads(json.dumps(METADATA, default=float))
        assert metadata_of(read) == metadata_of(path)
    else:  # Plot3D has no place for either
        assert read.cell_data == {} and metadata_of(path) == {}


@pytest.mark.parametrize("extension", [".vtu", ".vtk", ".xdmf"])
def test_meshio_reads_the_files_and_their_metadata(tmp_path, mesh, extension):
    import meshio

    X, cell_data = mesh
    path = write_mesh(tmp_path / f"mesh{extension}", X, cell_data, METADATA)
    read = meshio.read(path)
    np.testing.assert_array_equal(read.points, padded_points(X))
    np.testing.assert_array_equal(read.cell_data["index"][0], cell_data["index"])
    if extension != ".xdmf":  # meshio's XDMF reader keeps no free-form information; read_mesh does
        assert metadata_of(read) == metadata_of(path) != {}


def test_metadata_of_a_file_without_metadata_is_empty(tmp_path, mesh):
    X, _ = mesh
    for extension in ALL_EXTENSIONS:
        assert metadata_of(write_mesh(tmp_path / f"plain{extension}", X)) == {}


# --- VTK's readers -------------------------------------------------------------------------


@pytest.mark.parametrize("extension", [".vtu", ".vtk"])
def test_vtk_reads_the_unstructured_files_with_cell_data_and_metadata(tmp_path, mesh, extension):
    vtk = pytest.importorskip("vtk")
    X, cell_data = mesh
    path = write_mesh(tmp_path / f"mesh{extension}", X, cell_data, METADATA)
    reader = vtk.vtkXMLUnstructuredGridReader() if extension == ".vtu" else vtk.vtkUnstructuredGridReader()
    reader.SetFileName(str(path))
    reader.Update()
    grid = reader.GetOutput()
    np.testing.assert_array_equal(vtk_to_numpy(grid.GetPoints().GetData()), padded_points(X))
    assert grid.GetNumberOfCells() == len(cell_data["index"])
    np.testing.assert_array_equal(vtk_to_numpy(grid.GetCellData().GetArray("scaled_jacobian")), cell_data["scaled_jacobian"])
    stored = grid.GetFieldData().GetAbstractArray("meshgen")
    assert stored is not None
    assert json.loads(vtk_to_numpy(stored).tobytes()) == metadata_of(path)


def test_vtk_reads_the_xdmf_file(tmp_path, mesh):
    vtk = pytest.importorskip("vtk")
    if not hasattr(vtk, "vtkXdmfReader"):
        pytest.skip("this VTK build has no XDMF reader")
    X, cell_data = mesh
    path = write_mesh(tmp_path / "mesh.xdmf", X, cell_data, METADATA)
    reader = vtk.vtkXdmfReader()
    reader.SetFileName(str(path))
    reader.Update()
    grid = reader.GetOutputDataObject(0)
    np.testing.assert_array_equal(vtk_to_numpy(grid.GetPoints().GetData()), padded_points(X))
    np.testing.assert_array_equal(vtk_to_numpy(grid.GetCellData().GetArray("index")), cell_data["index"])


def test_vtk_reads_the_cgns_file_with_equal_coordinates_and_cell_data(tmp_path, mesh):
    vtk = pytest.importorskip("vtk")
    X, cell_data = mesh
    path = write_mesh(tmp_path / "mesh.cgns", X, cell_data, METADATA)
    reader = vtk.vtkCGNSReader()
    reader.SetFileName(str(path))
    reader.UpdateInformation()
    reader.EnableAllCellArrays()
    reader.Update()
    blocks = reader.GetOutput().NewIterator()
    blocks.InitTraversal()
    grids = []
    while not blocks.IsDoneWithTraversal():
        grids.append(blocks.GetCurrentDataObject())
        blocks.GoToNextItem()
    assert len(grids) == 1 and grids[0].IsA("vtkStructuredGrid")
    dims = [0, 0, 0]
    grids[0].GetDimensions(dims)
    assert dims == [*X.shape[:-1], 1][:3]
    np.testing.assert_array_equal(vtk_to_numpy(grids[0].GetPoints().GetData()), fortran_points(X))
    # VTK's cells run i fastest; ours in C order (k fastest).
    cell_shape = tuple(n - 1 for n in X.shape[:-1])
    index = vtk_to_numpy(grids[0].GetCellData().GetArray("index"))
    np.testing.assert_array_equal(index, cell_data["index"].reshape(cell_shape).T.reshape(-1))


@pytest.mark.parametrize("extension", [".xyz", ".fmt"])
def test_vtk_plot3d_reader_reads_the_grid_with_the_documented_options(tmp_path, mesh, extension):
    vtk = pytest.importorskip("vtk")
    X, _ = mesh
    path = write_mesh(tmp_path / f"mesh{extension}", X)
    settings = [("explicit", False)] + ([("auto-detect", True)] if extension == ".xyz" else [])
    for _, auto_detect in settings:
        reader = vtk.vtkMultiBlockPLOT3DReader()
        reader.SetXYZFileName(str(path))
        if auto_detect:
            reader.AutoDetectFormatOn()
        else:
            reader.SetBinaryFile(extension == ".xyz")
            reader.SetMultiGrid(1)
            reader.SetHasByteCount(1)
            reader.SetIBlanking(0)
            reader.SetByteOrderToLittleEndian()
            reader.SetDoublePrecision(1)
            reader.SetTwoDimensionalGeometry(X.shape[-1] == 2)
        reader.Update()
        output = reader.GetOutput()
        assert output.GetNumberOfBlocks() == 1
        np.testing.assert_array_equal(vtk_to_numpy(output.GetBlock(0).GetPoints().GetData()), fortran_points(X))


def test_cells_are_positively_oriented_by_vtk_mesh_quality(tmp_path):
    vtk = pytest.importorskip("vtk")
    X = tfi(load_geometry("semicylinder"), (6, 5, 4))

    def smallest_scaled_jacobian(X, name):
        reader = vtk.vtkXMLUnstructuredGridReader()
        reader.SetFileName(str(write_mesh(tmp_path / name, X)))
        quality = vtk.vtkMeshQuality()
        quality.SetInputConnection(reader.GetOutputPort())
        quality.SetHexQualityMeasureToScaledJacobian()
        quality.Update()
        return vtk_to_numpy(quality.GetOutput().GetCellData().GetArray("Quality")).min()

    assert smallest_scaled_jacobian(X, "mesh.vtu") > 0
    # Control: the same mesh mirrored in i (a left-handed map) must read as inverted.
    assert smallest_scaled_jacobian(X[::-1], "mirrored.vtu") < 0


def test_quads_are_counterclockwise(tmp_path):
    X = tfi(load_geometry("semidisk"), (5, 4))
    read = read_mesh(write_mesh(tmp_path / "mesh.vtu", X))
    corners = read.points[read.cells[0].data][..., :2]
    x, y = corners[..., 0], corners[..., 1]
    signed_area = 0.5 * np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y, axis=1)
    assert signed_area.min() > 0


# --- CGNS ----------------------------------------------------------------------------------


def run_cgnscheck(path):
    result = subprocess.run([cgnscheck, str(path)], capture_output=True, text=True, timeout=60)
    return result.returncode, result.stdout + result.stderr


@needs_cgnscheck
def test_cgnscheck_accepts_the_cgns_file(tmp_path, mesh):
    X, cell_data = mesh
    rc, output = run_cgnscheck(write_mesh(tmp_path / "plain.cgns", X, metadata=METADATA))
    assert rc == 0 and "ERROR" not in output and "WARNING" not in output, output
    assert "checking complete" in output
    # Cell data: no errors; the only warning is for names that are not SIDS identifiers.
    rc, output = run_cgnscheck(write_mesh(tmp_path / "data.cgns", X, cell_data, METADATA))
    assert rc == 0 and "ERROR" not in output, output
    warnings = [line for line in output.splitlines() if line.startswith("WARNING")]
    assert warnings == ["WARNING:not a CGNS data-name identifier"] * len(cell_data), output


@needs_cgnscheck
def test_cgnscheck_rejects_a_broken_zone(tmp_path):
    """Control for the test above: cgnscheck does catch a zone whose sizes do not fit its data."""
    import h5py

    path = write_mesh(tmp_path / "mesh.cgns", tfi(load_geometry("semicylinder"), (3, 3, 3)))
    with h5py.File(path, "r+") as root:
        root["Base/Zone/ data"][0, 0] = 9
    rc, output = run_cgnscheck(path)
    assert rc != 0 and "ERROR" in output


@pytest.mark.skipif(shutil.which("plot3d_to_cgns") is None, reason="plot3d_to_cgns not installed (cgns-convert)")
def test_cgns_library_converts_our_plot3d_file_to_our_cgns_coordinates(tmp_path):
    """The CGNS tools' Plot3D reader (multi-block Fortran unformatted, double) reads our .xyz; our
    CGNS reader reads the file the CGNS library wrote."""
    X = tfi(load_geometry("semicylinder"), (6, 5, 4))
    xyz = write_mesh(tmp_path / "mesh.xyz", X)
    converted = tmp_path / "converted.cgns"
    subprocess.run(["plot3d_to_cgns", "-u", "-d", str(xyz), str(converted)], check=True, capture_output=True, timeout=60)
    np.testing.assert_array_equal(read_mesh(converted).points, padded_points(X))


def test_cgns_layout_follows_the_hdf5_mapping(tmp_path):
    import h5py

    X = tfi(load_geometry("semicylinder"), (6, 5, 4))
    path = write_mesh(tmp_path / "mesh.cgns", X, metadata=METADATA)
    with h5py.File(path, "r") as root:
        assert root[" format"][()].tobytes() == b"IEEE_LITTLE_32\0"
        assert root[" hdf5version"].shape == (33,) and root[" hdf5version"][()].tobytes().startswith(b"HDF5 Version ")
        zone = root["Base/Zone"]
        name = h5py.h5a.open(zone.id, b"name")
        assert name.get_type().get_size() == 33 and name.get_type().get_strpad() == h5py.h5t.STR_NULLTERM
        assert zone.attrs["label"] == b"Zone_t" and zone.attrs["type"] == b"I4"
        np.testing.assert_array_equal(zone.attrs["flags"], [1])
        np.testing.assert_array_equal(zone[" data"][()], [[7, 6, 5], [6, 5, 4], [0, 0, 0]])
        assert zone[" data"].dtype == np.int32
        # Fortran order: HDF5 shape (nk, nj, ni), element [k, j, i] = X[i, j, k].
        x = zone["GridCoordinates/CoordinateX/ data"][()]
        assert x.shape == (5, 6, 7) and x.dtype == np.float64
        assert x[3, 2, 1] == X[1, 2, 3, 0]
        assert root["Base"].id.get_create_plist().get_link_creation_order() != 0


def test_cgns_rejects_a_cell_data_name_that_is_not_a_cgns_name(tmp_path):
    X = tfi(load_geometry("semicylinder"), (3, 3, 3))
    path = write_mesh(tmp_path / "mesh.cgns", X)
    before = path.read_bytes()
    with pytest.raises(FormatError, match="not a valid CGNS node name"):
        write_mesh(path, X, {"a/b": np.zeros(27)})
    assert path.read_bytes() == before and sorted(os.listdir(tmp_path)) == ["mesh.cgns"]


# --- Plot3D --------------------------------------------------------------------------------


def test_plot3d_reader_reads_big_endian_single_grid_single_precision_with_iblank(tmp_path):
    """A variant meshgen does not write, built by hand: the reader detects it from record sizes."""
    X = tfi(load_geometry("semicylinder"), (3, 2, 4))
    coordinates = np.moveaxis(X, -1, 0).transpose(0, 3, 2, 1).astype(">f4")
    iblank = np.ones(X.shape[:-1], dtype=">i4")

    def record(data: bytes):
        marker = np.array([len(data)], dtype=">i4").tobytes()
        return marker + data + marker

    path = tmp_path / "single.xyz"
    path.write_bytes(record(np.array(X.shape[:-1], dtype=">i4").tobytes()) + record(coordinates.tobytes() + iblank.tobytes()))
    np.testing.assert_allclose(read_mesh(path).points, padded_points(X), atol=1e-6)


def test_plot3d_binary_layout(tmp_path):
    X = tfi(load_geometry("semidisk"), (5, 4))
    data = write_mesh(tmp_path / "mesh.xyz", X).read_bytes()
    header = np.frombuffer(data[:28], dtype="<i4")
    np.testing.assert_array_equal(header, [4, 1, 4, 8, 6, 5, 8])
    assert np.frombuffer(data[28:32], dtype="<i4")[0] == 2 * 30 * 8 == len(data) - 36
    x = np.frombuffer(data[32 : 32 + 30 * 8], dtype="<f8")
    np.testing.assert_array_equal(x, X[..., 0].T.reshape(-1))


# --- atomic writes and errors --------------------------------------------------------------


@pytest.mark.parametrize(
    ("extension", "target", "failing_call"),
    [
        (".cgns", "meshgen.formats._cgns.fortran", 2),  # after CoordinateX is written
        (".vtu", "meshgen.formats._vtu._write_data_array", 2),  # after the first array
        (".xyz", "meshgen.formats._plot3d._write_record", 2),  # after the first record
    ],
)
def test_a_writer_failing_midway_keeps_the_old_file_and_leaves_no_temporary(
    tmp_path, monkeypatch, extension, target, failing_call
):
    X = tfi(load_geometry("semicylinder"), (3, 3, 3))
    path = write_mesh(tmp_path / f"mesh{extension}", X, metadata={"run": 1})
    before = path.read_bytes()
    calls = []

    def fail_midway(*args, **kwargs):
        calls.append(args)
        if len(calls) == failing_call:
            raise RuntimeError("disk on fire")
        return original(*args, **kwargs)

    module, name = target.rsplit(".", 1)
    original = getattr(__import__(module, fromlist=[name]), name)
    monkeypatch.setattr(target, fail_midway)
    # A library's RuntimeError (how h5py reports a full disk) is one line naming the file.
    with pytest.raises(FormatError, match=f"could not write {path}: disk on fire"):
        write_mesh(path, X * 2, metadata={"run": 2})
    assert len(calls) == failing_call
    assert path.read_bytes() == before
    assert os.listdir(tmp_path) == [path.name]


def test_unknown_extension_lists_the_valid_ones(tmp_path):
    X = tfi(load_geometry("semicylinder"), (3, 3, 3))
    with pytest.raises(FormatError) as error:
        write_mesh(tmp_path / "mesh.stl", X)
    for extension in ALL_EXTENSIONS:
        assert extension in str(error.value)
    # .vts, .su2 and .msh are tested with their patches in test_solver_formats.py, .pvts in test_formats_streamed.py.
    assert sorted(extensions()) == sorted(ALL_EXTENSIONS + [".vts", ".pvts", ".su2", ".msh"])
    assert os.listdir(tmp_path) == []


def test_cell_data_of_the_wrong_size_is_refused_before_writing(tmp_path):
    X = tfi(load_geometry("semicylinder"), (3, 3, 3))
    with pytest.raises(FormatError, match="26 values for 27 cells"):
        write_mesh(tmp_path / "mesh.vtu", X, {"quality": np.zeros(26)})
    assert os.listdir(tmp_path) == []


@pytest.mark.needs_cgnscheck
def test_cli_writes_a_cgns_file_that_passes_cgnscheck(run_cli, tmp_path):
    result = run_cli("mesh", "-m", "tfi", "--dims", 4, 4, 4, "-o", "out.cgns")
    assert result.returncode == 0, result.stderr
    path = tmp_path / "out.cgns"
    read = read_mesh(path)
    assert len(read.points) == 125 and len(read.cells[0].data) == 64
    metadata = metadata_of(path)
    assert metadata["method"] == "tfi" and metadata["dims"] == [4, 4, 4]
    if cgnscheck is None:
        pytest.skip("cgnscheck not installed (Debian package cgns-convert)")
    rc, output = run_cgnscheck(path)
    # The quality arrays have meshgen's names, not CGNS's standard data names: cgnscheck warns
    # about exactly those and about nothing else.
    warnings = [line for line in output.splitlines() if "WARNING" in line]
    assert rc == 0 and "ERROR" not in output, output
    assert warnings == ["WARNING:not a CGNS data-name identifier"] * 7, output


def test_cli_unknown_extension_is_one_line_error(run_cli, tmp_path):
    result = run_cli("mesh", "--dims", 4, 4, 4, "-o", "out.stl")
    assert result.returncode == 2
    assert result.stderr.strip().count("\n") == 0 and ".cgns" in result.stderr and ".xyz" in result.stderr
    assert os.listdir(tmp_path) == []


def test_the_vtk_writers_quote_attributes_as_saxutils_does():
    """``meshgen.formats._xml`` stands in for ``xml.sax.saxutils`` (which imports urllib.request):
    the same strings, so the files keep their bytes."""
    from xml.sax import saxutils

    from meshgen.formats._xml import escape, quoteattr

    cases = ["", "min_angle", 'a"b', "a'b", "a'\"b", "<&>", "x\ny\r\tz", "blocks/b 1.vts", "'\"&<>\n\r\t", "é中"]
    for text in cases:
        assert quoteattr(text) == saxutils.quoteattr(text)
        assert escape(text) == saxutils.escape(text)
        assert escape(text, {'"': "&quot;"}) == saxutils.escape(text, {'"': "&quot;"})

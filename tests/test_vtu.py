""".vtu writer (meshgen.formats._vtu): read back by meshio and by VTK's XML reader, checked against
the node array, meshgen.geometry.grid's connectivity and VTK's own quality of the cells; the compression
layout decoded by hand; atomic writes."""

import base64
import json
import os
import xml.etree.ElementTree as ET
import zlib

import numpy as np
import pytest
from vtk.util.numpy_support import vtk_to_numpy

from meshgen.formats import _vtu, metadata_of, read_mesh, write_mesh
from meshgen.geometry.grid import cell_connectivity, flat_points
from meshgen.geometry.plugins import load_geometry
from meshgen.methods.tfi import tfi

METADATA = {"method": "tfi", "geometry": "semicylinder", "dims": [6, 5, 4], "note": "quotes \" ' and < & > survive"}
VTK_HEXAHEDRON, VTK_QUAD = 12, 9


@pytest.fixture(scope="module", params=[3, 2], ids=["3d", "2d"])
def mesh(request):
    """(X, cell_data): the semicylinder by TFI at 6x5x4 cells or the semidisk at 5x4, with random
    cell data and a name XML must escape."""
    X = tfi(load_geometry("semicylinder"), (6, 5, 4)) if request.param == 3 else tfi(load_geometry("semidisk"), (5, 4))
    cells = int(np.prod([n - 1 for n in X.shape[:-1]]))
    rng = np.random.default_rng(request.param)
    return X, {"scaled_jacobian": rng.random(cells), 'odd <name> & "quotes"': rng.normal(size=cells)}


def read_with_vtk(path):
    vtk = pytest.importorskip("vtk")
    reader = vtk.vtkXMLUnstructuredGridReader()
    reader.SetFileName(str(path))
    reader.Update()
    assert not reader.GetErrorCode()
    return reader.GetOutput()


def vtk_cells(grid) -> tuple[np.ndarray, np.ndarray]:
    """(cell types, connectivity as (cells, corners)) of a vtkUnstructuredGrid."""
    cells = grid.GetCells()
    offsets = vtk_to_numpy(cells.GetOffsetsArray())
    corners = np.diff(offsets)
    assert (corners == corners[0]).all()
    connectivity = vtk_to_numpy(cells.GetConnectivityArray()).reshape(-1, corners[0])
    types = np.array([grid.GetCellType(i) for i in range(grid.GetNumberOfCells())])
    return types, connectivity


def check_meshio_reads(path, X, cell_data, metadata):
    import meshio

    read = meshio.read(path)
    np.testing.assert_array_equal(read.points, flat_points(X))
    assert len(read.cells) == 1 and read.cells[0].type == ("hexahedron" if X.ndim == 4 else "quad")
    np.testing.assert_array_equal(read.cells[0].data, cell_connectivity(X.shape[:-1]))
    assert set(read.cell_data) == set(cell_data)
    for name, values in cell_data.items():
        np.testing.assert_array_equal(read.cell_data[name][0], values)
    assert metadata_of(read) == metadata
    assert metadata_of(path) == metadata  # through meshgen's read_mesh


def check_vtk_reads(path, X, cell_data, metadata):
    grid = read_with_vtk(path)
    np.testing.assert_array_equal(vtk_to_numpy(grid.GetPoints().GetData()), flat_points(X))
    types, connectivity = vtk_cells(grid)
    np.testing.assert_array_equal(types, VTK_HEXAHEDRON if X.ndim == 4 else VTK_QUAD)
    np.testing.assert_array_equal(connectivity, cell_connectivity(X.shape[:-1]))
    assert grid.GetCellData().GetNumberOfArrays() == len(cell_data)
    for name, values in cell_data.items():
        np.testing.assert_array_equal(vtk_to_numpy(grid.GetCellData().GetArray(name)), values)
    stored = grid.GetFieldData().GetAbstractArray("meshgen")
    if metadata:
        assert stored.GetDataTypeAsString() == "unsigned char"
        assert json.loads(vtk_to_numpy(stored).tobytes()) == metadata
    else:
        assert stored is None


def test_meshio_and_vtk_read_back_points_cells_cell_data_and_metadata(tmp_path, mesh):
    X, cell_data = mesh
    path = write_mesh(tmp_path / "mesh.vtu", X, cell_data, METADATA)
    check_meshio_reads(path, X, cell_data, METADATA)
    check_vtk_reads(path, X, cell_data, METADATA)


def test_without_cell_data_or_metadata(tmp_path, mesh):
    X, _ = mesh
    path = write_mesh(tmp_path / "plain.vtu", X)
    check_meshio_reads(path, X, {}, {})
    check_vtk_reads(path, X, {}, {})
    assert b"<FieldData>" not in path.read_bytes() and b"<CellData>" not in path.read_bytes()


def test_2d_mesh_is_quads_in_the_plane_z_0(tmp_path):
    X = tfi(load_geometry("semidisk"), (5, 4))
    grid = read_with_vtk(write_mesh(tmp_path / "mesh.vtu", X))
    points = vtk_to_numpy(grid.GetPoints().GetData())
    assert points.shape == (30, 3)
    np.testing.assert_array_equal(points[:, 2], 0.0)
    np.testing.assert_array_equal(points[:, :2], X.reshape(-1, 2))
    types, connectivity = vtk_cells(grid)
    assert connectivity.shape == (20, 4) and (types == VTK_QUAD).all()


@pytest.mark.parametrize("block_bytes", [1024, 4096, 24])
def test_arrays_of_many_blocks_full_and_partial_read_back(tmp_path, block_bytes):
    """4x4x4 cells: connectivity 4096 bytes (4 full blocks of 1024, or exactly one of 4096),
    points 3000 bytes (a partial last block), cell data 512 bytes (one short block);
    24 bytes: hundreds of blocks of three values each."""
    X = tfi(load_geometry("semicylinder"), (4, 4, 4))
    cell_data = {"index": np.arange(64.0)}
    path = tmp_path / "mesh.vtu"
    _vtu.write(path, X, cell_data, METADATA, block_bytes=block_bytes)
    check_meshio_reads(path, X, cell_data, METADATA)
    check_vtk_reads(path, X, cell_data, METADATA)


def test_data_arrays_follow_vtks_compressed_binary_layout(tmp_path):
    """Decode the file by hand as VTK's format documents it: per DataArray base64(header) then
    base64(zlib blocks); header UInt64 [blocks, block size, last block size or 0, sizes...]."""
    X = tfi(load_geometry("semicylinder"), (4, 4, 4))
    block_bytes = 1024
    path = tmp_path / "mesh.vtu"
    _vtu.write(path, X, {"index": np.arange(64.0)}, METADATA, block_bytes=block_bytes)
    root = ET.parse(path).getroot()
    assert root.attrib == {
        "type": "UnstructuredGrid",
        "version": "1.0",
        "byte_order": "LittleEndian",
        "header_type": "UInt64",
        "compressor": "vtkZLibDataCompressor",
    }
    expected = {
        "meshgen": np.frombuffer(json.dumps(METADATA).encode(), dtype=np.uint8),
        "Points": flat_points(X),
        "connectivity": cell_connectivity(X.shape[:-1]),
        "offsets": 8 * np.arange(1, 65),
        "types": np.full(64, VTK_HEXAHEDRON, dtype=np.uint8),
        "index": np.arange(64.0),
    }
    dtypes = {"UInt8": "u1", "Int64": "<i8", "Float64": "<f8"}
    arrays = root.findall(".//DataArray")
    assert [a.get("Name") for a in arrays] == list(expected)
    for element in arrays:
        assert element.get("format") == "binary"
        text = element.text.strip()
        count = int(np.frombuffer(base64.b64decode(text[:12])[:8], "<u8")[0])
        header_chars = -(-8 * (3 + count) // 3) * 4
        header = np.frombuffer(base64.b64decode(text[:header_chars]), "<u8")
        data = base64.b64decode(text[header_chars:])
        raw = np.ascontiguousarray(expected[element.get("Name")], dtype=dtypes[element.get("type")]).tobytes()
        assert header[0] == -(-len(raw) // block_bytes) and header[1] == block_bytes
        assert header[2] == len(raw) % block_bytes
        assert sum(header[3:]) == len(data)
        ends = np.cumsum(header[3:])
        blocks = [zlib.decompress(data[end - size : end]) for end, size in zip(ends, header[3:])]
        assert all(len(block) == block_bytes for block in blocks[:-1])
        assert b"".join(blocks) == raw


def test_30_cubed_with_quality_arrays_vtk_recomputes_the_stored_scaled_jacobian(tmp_path):
    """The mesh ``meshgen mesh`` writes (seven quality arrays, several blocks per array): VTK's
    Verdict scaled Jacobian of the cells it reads equals the stored per-cell array."""
    vtk = pytest.importorskip("vtk")
    from meshgen.quality import METRICS, write_mesh_with_quality

    X = tfi(load_geometry("semicylinder"), (30, 30, 30))
    path = tmp_path / "mesh.vtu"
    write_mesh_with_quality(path, X, metadata=METADATA)
    mesh = read_mesh(path)
    np.testing.assert_array_equal(mesh.points, flat_points(X))
    np.testing.assert_array_equal(mesh.cells[0].data, cell_connectivity(X.shape[:-1]))
    assert set(mesh.cell_data) == set(METRICS) and metadata_of(mesh) == METADATA

    reader = vtk.vtkXMLUnstructuredGridReader()
    reader.SetFileName(str(path))
    quality = vtk.vtkMeshQuality()
    quality.SetInputConnection(reader.GetOutputPort())
    quality.SetHexQualityMeasureToScaledJacobian()
    quality.Update()
    output = quality.GetOutput()
    verdict = vtk_to_numpy(output.GetCellData().GetArray("Quality"))
    for name in METRICS:
        np.testing.assert_array_equal(vtk_to_numpy(output.GetCellData().GetArray(name)), mesh.cell_data[name][0])
    np.testing.assert_allclose(mesh.cell_data["scaled_jacobian"][0], verdict, rtol=0, atol=1e-10)
    assert json.loads(vtk_to_numpy(output.GetFieldData().GetAbstractArray("meshgen")).tobytes()) == METADATA


def test_blocks_are_zlib_streams_that_stdlib_zlib_inflates():
    """ISA-L's streams are plain zlib streams: the stdlib inflates every kind of block back to its
    bytes (noise-like float64, regular values, a short block, nothing), each level compresses the
    regular data, and level 1 keeps noise-like float64 bytes within 5% of stdlib zlib's level 1."""
    rng = np.random.default_rng(0)
    noisy = rng.standard_normal(40_000).tobytes()
    regular = np.tile(np.linspace(0.0, 1.0, 100), 400).tobytes()
    for level in range(4):
        for data in (noisy, regular, noisy[:1000], b""):
            assert zlib.decompress(_vtu.compress_block(data, level)) == data
        assert len(_vtu.compress_block(regular, level)) < len(regular) / 10
    assert len(_vtu.compress_block(noisy)) < 1.05 * len(zlib.compress(noisy, 1))


def test_connectivity_matches_grid_for_uneven_shapes():
    for node_shape in [(2, 2), (7, 3), (2, 2, 2), (4, 3, 5), (3, 6, 2)]:
        np.testing.assert_array_equal(_vtu._connectivity(node_shape), cell_connectivity(node_shape))


def test_compression_failing_in_a_worker_keeps_the_old_file(tmp_path, monkeypatch):
    X = tfi(load_geometry("semicylinder"), (4, 4, 4))
    path = write_mesh(tmp_path / "mesh.vtu", X, metadata={"run": 1})
    before = path.read_bytes()
    calls = []

    def compress(data, level):
        calls.append(len(data))
        if len(calls) == 3:
            raise MemoryError("out of memory in a worker")
        return original(data, level)

    original = _vtu.zlib.compress  # a small mesh's blocks: zlib (``compress_block``)
    monkeypatch.setattr(_vtu.zlib, "compress", compress)
    with pytest.raises(MemoryError):
        write_mesh(path, X * 2, metadata={"run": 2}, cell_data={"a": np.zeros(64)})
    monkeypatch.undo()
    assert len(calls) >= 3
    assert path.read_bytes() == before and metadata_of(path) == {"run": 1}
    assert os.listdir(tmp_path) == [path.name]


def test_cell_data_computed_while_the_nodes_compress_gives_the_same_bytes(tmp_path, monkeypatch):
    """``write_mesh_with_quality`` hands the writer a callable: the metadata, points and cells are
    submitted for compression before it is called, and the file is byte for byte the one written
    from the finished arrays (``write_mesh`` with the metrics as a mapping)."""
    from meshgen.quality import write_mesh_with_quality
    from meshgen.quality.structured import structured_metrics

    X = tfi(load_geometry("semicylinder"), (9, 8, 7))
    X[3, 4, 2] += 0.05  # cells of every quality, not a regular grid only
    submitted = []
    original = _vtu.compress_blocks

    def compress_blocks(pool, array, *rest):
        submitted.append(array.nbytes)
        return original(pool, array, *rest)

    monkeypatch.setattr(_vtu, "compress_blocks", compress_blocks)
    deferred = tmp_path / "deferred.vtu"
    report = write_mesh_with_quality(deferred, X, metadata=METADATA)
    assert report["cells"] == 9 * 8 * 7 and len(submitted) == 5 + 7  # metadata, points, 3 cell arrays, 7 metrics

    heard = []

    def metrics():
        heard.append(len(submitted))  # arrays already under way when the cell data are asked for
        return structured_metrics(X)[0]

    submitted.clear()
    direct = write_mesh(tmp_path / "direct.vtu", X, cell_data=structured_metrics(X)[0], metadata=METADATA)
    called = write_mesh(tmp_path / "called.vtu", X, cell_data=metrics, metadata=METADATA)
    assert heard == [12 + 5]  # the direct file's 12 arrays, then the called one's first five
    assert deferred.read_bytes() == direct.read_bytes() == called.read_bytes()
    # A format that cannot defer calls it before writing, and gets the same arrays.
    heard.clear()
    submitted.clear()
    cgns = write_mesh(tmp_path / "m.cgns", X, cell_data=metrics, metadata=METADATA)
    assert heard == [0] and set(read_mesh(cgns).cell_data) == set(structured_metrics(X)[0])

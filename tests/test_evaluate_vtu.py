"""``meshgen evaluate`` of a .vtu reads it with meshgen's decoder (``meshgen.formats.read_cells``):
the points, the cells and the cell data ``block`` that meshio reads of the same file, to the bit,
the other arrays left out; files it does not read (other cell kinds, mixed cells) go to meshio;
the reports are those of the file read by meshio."""

import meshio
import numpy as np
import pytest

from meshgen.errors import FormatError
from meshgen.formats import read_cells, write_mesh
from meshgen.quality import files
from meshgen.quality.files import evaluate_file


def as_meshio_reads(path):
    return meshio.read(path, file_format="vtu")


def same_mesh(ours, theirs, cell_arrays=None) -> None:
    assert ours.points.dtype == np.float64 and np.array_equal(ours.points, theirs.points)
    assert [(b.type, b.data.tolist()) for b in ours.cells] == [(b.type, b.data.tolist()) for b in theirs.cells]
    names = set(theirs.cell_data) if cell_arrays is None else set(theirs.cell_data) & set(cell_arrays)
    assert set(ours.cell_data) == names
    for name in names:
        assert np.array_equal(ours.cell_data[name][0], theirs.cell_data[name][0]), name
    assert set(ours.field_data) == set(theirs.field_data)
    for name, values in theirs.field_data.items():
        assert np.array_equal(ours.field_data[name], values), name


@pytest.mark.parametrize(
    ("geometry", "dims"), [("semicylinder", ("12", "10", "8")), ("semidisk", ("14", "9")), ("pipe", ("8", "4", "4"))]
)
def test_read_cells_is_what_meshio_reads(run_cli, tmp_path, geometry, dims):
    """meshgen's own .vtu files: one block (3D, 2D) and a block set (cell data ``block``)."""
    result = run_cli("mesh", "-g", geometry, "--method", "tfi", "--dims", *dims, "-o", "m.vtu", "-q")
    assert result.returncode == 0, result.stderr
    path = tmp_path / "m.vtu"
    same_mesh(read_cells(path), as_meshio_reads(path))
    same_mesh(read_cells(path, cell_arrays=("block",)), as_meshio_reads(path), ("block",))
    assert read_cells(tmp_path / "m.vtu.quality.json") is None  # not a .vtu


def test_a_vtu_meshio_wrote_reads_the_same(tmp_path):
    """Another writer's file (meshio's own binary .vtu, its cell data of two components)."""
    rng = np.random.default_rng(1)
    points = rng.random((27, 3))
    cells = rng.integers(0, 27, size=(5, 8))
    path = tmp_path / "theirs.vtu"
    meshio.write(path, meshio.Mesh(points, [("hexahedron", cells)], cell_data={"v": [rng.random((5, 2))]}))
    same_mesh(read_cells(path), as_meshio_reads(path))


def test_mixed_cells_are_left_to_meshio(tmp_path):
    points = np.random.default_rng(2).random((10, 3))
    mesh = meshio.Mesh(points, [("hexahedron", np.arange(8)[None]), ("quad", np.array([[0, 1, 2, 3]]))])
    path = tmp_path / "mixed.vtu"
    meshio.write(path, mesh)
    assert read_cells(path) is None
    tetra = tmp_path / "tetra.vtu"
    meshio.write(tetra, meshio.Mesh(points, [("tetra", np.array([[0, 1, 2, 3]]))]))
    assert read_cells(tetra) is None


def test_a_truncated_vtu_is_one_error(tmp_path):
    X = np.stack(np.meshgrid(*[np.linspace(0, 1, 5)] * 3, indexing="ij"), axis=-1)
    path = write_mesh(tmp_path / "box.vtu", X)
    data = path.read_bytes()
    start = data.index(b'Name="connectivity"')
    cut = data.index(b"</DataArray>", start)
    path.write_bytes(data[: cut - 200] + data[cut:])
    with pytest.raises(FormatError, match="box.vtu"):
        read_cells(path)


@pytest.mark.parametrize(("geometry", "dims"), [("semicylinder", ("12", "10", "8")), ("pipe", ("8", "4", "4"))])
def test_evaluate_reports_what_the_meshio_read_gives(run_cli, tmp_path, monkeypatch, geometry, dims):
    result = run_cli("mesh", "-g", geometry, "--method", "tfi", "--dims", *dims, "-o", "m.vtu", "-q")
    assert result.returncode == 0, result.stderr
    path = tmp_path / "m.vtu"
    report = evaluate_file(path, per_block=True)
    assert report["boundary_deviation"]["max"] < 1e-9 and report["structured"] == (geometry == "semicylinder")
    monkeypatch.setattr(files, "read_cells", lambda path, cell_arrays=None: None)  # meshio's read
    assert evaluate_file(path, per_block=True) == report

"""Meshes larger than memory in every solver format: the slab-by-slab writers
(``meshgen.formats.streamed``) and the chunked path through them (``meshgen.run.chunked``).

Each streamed file is compared with what the in-memory writer makes of the same node array:
byte for byte (a 2D OpenFOAM case: its extrusion's thickness is a sum in another order, so its
points to rounding). Real readers check the results: checkMesh, VTK's XML reader.
"""

import filecmp
from pathlib import Path

import numpy as np
import pytest
from openfoam_helpers import check_mesh, needs_openfoam

from meshgen.errors import FormatError
from meshgen.formats import check_patches, write_mesh
from meshgen.formats._openfoam import read_list
from meshgen.formats._vts_streamed import byte_blocks
from meshgen.formats.streamed import NodeFile, cells_of_slab, write_streamed
from meshgen.geometry.grid import cell_connectivity
from meshgen.geometry.patches import Patch, geometry_patches
from meshgen.methods.clustering import node_coordinates
from meshgen.run.chunked import tfi_array, write_chunked_mesh

pytest.importorskip("dask")

# (format, file name, options): every format that a chunked mesh can be written in but CGNS.
FORMATS = [
    ("openfoam", "case", {"binary": True}),
    ("openfoam", "case", {"binary": False}),
    ("su2", "mesh.su2", {}),
    ("gmsh", "mesh.msh", {}),
    ("vts", "mesh.vts", {}),
    ("pvts", "mesh.pvts", {}),
    ("plot3d", "mesh.xyz", {}),
    ("plot3d-ascii", "mesh.fmt", {}),
]
IDS = [f"{f}{'-ascii' if o == {'binary': False} else ''}" for f, _, o in FORMATS]


def perturbed_grid(node_shape, mirrored=False, seed=0):
    """A unit-box grid with jittered nodes; ``mirrored``: i runs backwards (a left-handed map)."""
    axes = np.meshgrid(*[np.linspace(0.0, 1.0, n) for n in node_shape], indexing="ij")
    X = np.stack(axes, axis=-1) + 0.02 * np.random.default_rng(seed).standard_normal(tuple(node_shape) + (len(node_shape),))
    return np.ascontiguousarray(X[::-1]) if mirrored else X


def differing(a: Path, b: Path) -> list[str]:
    """Files under ``a`` and ``b`` (or the files themselves, and a .pvts's pieces) whose bytes differ."""
    if a.suffix == ".pvts":
        return differing(a.with_suffix(""), b.with_suffix("")) + ([] if filecmp.cmp(a, b, shallow=False) else [a.name])
    if a.is_file():
        return [] if filecmp.cmp(a, b, shallow=False) else [a.name]
    names = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    assert names == sorted(p.relative_to(b) for p in b.rglob("*") if p.is_file())
    return [str(name) for name in names if not filecmp.cmp(a / name, b / name, shallow=False)]


PATCHES = [
    Patch("inlet", "patch", ("xi0",)),
    Patch("outlet", "patch", ("xi1",)),
    Patch("walls", "wall", ("eta0", "eta1", "zeta0", "zeta1")),
]


@pytest.mark.parametrize("fmt, name, options", FORMATS, ids=IDS)
def test_each_streamed_file_is_the_in_memory_writers_byte_for_byte(tmp_path, fmt, name, options):
    """Several slab sizes (one node plane, uneven slabs, one slab), both orientations of the map."""
    for mirrored in (False, True):
        X = perturbed_grid((7, 6, 8), mirrored)  # 6 x 5 x 7 cells
        nodes_file = tmp_path / f"nodes{mirrored}.cgns"
        write_mesh(nodes_file, X)
        patches = PATCHES if fmt not in ("plot3d", "plot3d-ascii") else check_patches(None, 3)
        write_mesh(_fresh(tmp_path / "memory") / name, X, None, {"run": 1}, patches, fmt, **options)
        for block_nodes in (1, 100):
            target = _fresh(tmp_path / f"streamed{block_nodes}") / name
            nodes = NodeFile(nodes_file, X.shape[:-1], block_nodes)
            write_streamed(target, nodes, fmt, {"run": 1}, check_patches(patches, 3, None, fmt), **options)
            assert differing(tmp_path / "memory" / name, target) == [], (mirrored, block_nodes)


def _fresh(folder: Path) -> Path:
    import shutil

    shutil.rmtree(folder, ignore_errors=True)
    folder.mkdir()
    return folder


@pytest.mark.parametrize("fmt, name, options", FORMATS, ids=IDS)
def test_2d_streamed_files_equal_the_in_memory_writers(tmp_path, fmt, name, options):
    X = perturbed_grid((7, 6), mirrored=True)
    write_mesh(tmp_path / "nodes.cgns", X)
    patches = check_patches(None, 2)
    write_mesh(_fresh(tmp_path / "memory") / name, X, None, {}, patches, fmt, **options)
    write_streamed(
        _fresh(tmp_path / "streamed") / name, NodeFile(tmp_path / "nodes.cgns", (7, 6), 13), fmt, {}, patches, **options
    )
    a, b = tmp_path / "memory" / name, tmp_path / "streamed" / name
    if fmt != "openfoam":
        assert differing(a, b) == []
        return
    # The extrusion's thickness sqrt(area / cells): the area summed slab by slab, in another order.
    assert set(differing(a, b)) <= {"constant/polyMesh/points"}
    points_a, points_b = (read_list(p / "constant/polyMesh/points", "points") for p in (a, b))
    np.testing.assert_allclose(points_b, points_a, rtol=1e-14, atol=0)


def test_slab_cells_and_byte_blocks_cut_the_whole_arrays(tmp_path):
    """Independent of the writers: the cells of i-slabs put together are ``cell_connectivity``;
    blocks cut from consecutive arrays are the blocks of their concatenation."""
    for node_shape in ((5, 4, 6), (6, 3)):
        parts = [cells_of_slab(node_shape, slice(s, min(s + 2, node_shape[0] - 1))) for s in range(0, node_shape[0] - 1, 2)]
        np.testing.assert_array_equal(np.concatenate(parts), cell_connectivity(node_shape))
    arrays = [np.arange(n, dtype=np.uint8) for n in (3, 0, 11, 5, 1, 9)]
    whole = np.concatenate(arrays).tobytes()
    assert [bytes(b) for b in byte_blocks(arrays, 7)] == [whole[i : i + 7] for i in range(0, len(whole), 7)]


def chunked_tfi(semicylinder, cells=(6, 5, 7), block_nodes=120):
    """The TFI mesh of the semicylinder as a dask array of several k-slab blocks."""
    X = tfi_array(semicylinder, node_coordinates(cells), block_nodes=block_nodes)
    assert X.npartitions >= 3
    return X


@pytest.mark.parametrize("fmt, name", [("openfoam", "case"), ("vts", "mesh.vts"), ("pvts", "mesh.pvts"), ("su2", "mesh.su2")])
def test_a_chunked_mesh_is_written_as_the_in_memory_mesh_would_be(tmp_path, semicylinder, fmt, name):
    X = chunked_tfi(semicylinder)
    report, timings = write_chunked_mesh(_fresh(tmp_path / "chunked") / name, X, semicylinder, {"run": 1}, format=fmt)
    write_mesh(_fresh(tmp_path / "memory") / name, X.compute(), None, {"run": 1}, geometry_patches(semicylinder), fmt)
    assert differing(tmp_path / "memory" / name, tmp_path / "chunked" / name) == []
    assert report["cells"] == 6 * 5 * 7 and timings["write_seconds"] > 0
    # The mesh, its sidecar, and nothing else: the scratch node file is gone.
    pieces = ["mesh"] if fmt == "pvts" else []
    assert sorted(p.name for p in (tmp_path / "chunked").iterdir()) == sorted([name, f"{name}.quality.json", *pieces])


@needs_openfoam
def test_checkmesh_passes_a_chunked_openfoam_case(tmp_path, semicylinder):
    X = chunked_tfi(semicylinder, cells=(8, 6, 10), block_nodes=150)
    write_chunked_mesh(tmp_path / "case", X, semicylinder, format="openfoam", evaluate=False)
    report = check_mesh(tmp_path / "case")
    assert report["ok"], report["log"][-2000:]
    assert sum(report["patches"].values()) == 2 * (8 * 6 + 6 * 10 + 8 * 10)


def test_vtk_reads_a_chunked_vts_whole(tmp_path, semicylinder):
    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import vtk_to_numpy

    X = chunked_tfi(semicylinder)
    write_chunked_mesh(tmp_path / "mesh.vts", X, semicylinder, evaluate=False)
    reader = vtk.vtkXMLStructuredGridReader()
    reader.SetFileName(str(tmp_path / "mesh.vts"))
    reader.Update()
    grid = reader.GetOutput()
    assert grid.GetNumberOfPoints() == 7 * 6 * 8 and grid.GetNumberOfCells() == 6 * 5 * 7
    points = vtk_to_numpy(grid.GetPoints().GetData())  # VTK's order: i fastest
    np.testing.assert_array_equal(points, np.transpose(X.compute(), (2, 1, 0, 3)).reshape(-1, 3))


@pytest.mark.parametrize("fmt, name", [("openfoam", "case"), ("gmsh", "mesh.msh"), ("pvts", "mesh.pvts")])
@pytest.mark.parametrize("when", ["meshing", "writing"])
def test_an_interrupted_streamed_write_leaves_nothing(tmp_path, semicylinder, monkeypatch, fmt, name, when):
    X = chunked_tfi(semicylinder)
    progress = None
    if when == "meshing":

        def progress(done, total, phase):
            if done == 2:
                raise KeyboardInterrupt

    else:  # after the scratch file and the quality, while the format's files are written

        def interrupt(*args, **kwargs):
            raise KeyboardInterrupt

        monkeypatch.setattr("meshgen.formats.streamed.bounding_box", interrupt)
        monkeypatch.setattr("meshgen.formats._gmsh.bounding_box", interrupt)
        monkeypatch.setattr("meshgen.formats._foam_streamed.internal_faces", interrupt)
        monkeypatch.setattr("meshgen.formats._pvts.write_piece", interrupt)
    with pytest.raises(KeyboardInterrupt):
        write_chunked_mesh(tmp_path / name, X, semicylinder, progress=progress, format=fmt)
    assert list(tmp_path.iterdir()) == []


def test_pvts_pieces_stream_as_in_memory_and_vtk_reads_them_as_one_grid(tmp_path, semicylinder):
    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import vtk_to_numpy

    from meshgen.formats import _pvts, read_mesh

    X = perturbed_grid((7, 6, 8))
    write_mesh(tmp_path / "nodes.cgns", X)
    patches = check_patches(PATCHES, 3)
    _pvts.write(_fresh(tmp_path / "memory") / "m.pvts", X, {}, {"run": 1}, patches, piece_nodes=100)
    nodes = NodeFile(tmp_path / "nodes.cgns", X.shape[:-1], 13)
    _pvts.write_streamed(_fresh(tmp_path / "streamed") / "m.pvts", nodes, {"run": 1}, patches, piece_nodes=100)
    assert differing(tmp_path / "memory" / "m.pvts", tmp_path / "streamed" / "m.pvts") == []
    assert len(list((tmp_path / "streamed" / "m").iterdir())) == 4  # 7 cell planes in pieces of 2
    reader = vtk.vtkXMLPStructuredGridReader()
    reader.SetFileName(str(tmp_path / "streamed" / "m.pvts"))
    reader.Update()
    grid = reader.GetOutput()
    assert grid.GetNumberOfPoints() == X.size // 3 and grid.GetNumberOfCells() == 6 * 5 * 7
    np.testing.assert_array_equal(vtk_to_numpy(grid.GetPoints().GetData()), np.transpose(X, (2, 1, 0, 3)).reshape(-1, 3))
    np.testing.assert_array_equal(read_mesh(tmp_path / "streamed" / "m.pvts").points, X.reshape(-1, 3))
    # A folder of the user's under the pieces' name is never replaced.
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("keep")
    with pytest.raises(FormatError, match="not the pieces folder"):
        write_mesh(tmp_path / "mine.pvts", X)
    assert (tmp_path / "mine" / "notes.txt").read_text() == "keep"


def test_the_cli_writes_a_chunked_openfoam_case_with_its_options(tmp_path):
    from click.testing import CliRunner

    from meshgen.cli import cli

    args = ["mesh", "-m", "tfi", "--dims", "6", "5", "7", "--chunked", "--no-quality", "--format", "openfoam", "--ascii"]
    result = CliRunner().invoke(cli, [*args, "-o", str(tmp_path / "case")])
    assert result.exit_code == 0, result.output
    owner_file = tmp_path / "case/constant/polyMesh/owner"
    assert b"format      ascii;" in owner_file.read_bytes()
    owner = read_list(owner_file, "labels")
    assert owner.max() == 6 * 5 * 7 - 1 and len(owner) == 3 * 6 * 5 * 7 + (6 * 5 + 5 * 7 + 6 * 7)

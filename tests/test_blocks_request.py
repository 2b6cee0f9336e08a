"""Block sets on the one request path: ``meshgen.mesh()``, ``carry_out(MeshRequest)``, ``meshgen
compare`` and ``Mesh.write`` / ``meshgen.write`` of a multi-block geometry, checked against closed
forms (cell and merged node counts of the pipe's O-grid), the per-block TFI computed directly, and
the written files read back."""

import json

import numpy as np
import pytest

import meshgen
from meshgen.errors import ParameterError
from meshgen.formats.multiblock import read_zones
from meshgen.geometry.block_nodes import merged_mesh
from meshgen.geometry.blocks import load_block_set, tfi_blocks
from meshgen.run.request import MeshRequest, carry_out

N, M, A = 4, 2, 3  # pipe --dims: cells around a quarter, across the wall layer, along the axis


def _pipe_cells(n, m, a):
    return n * n * a + 4 * n * m * a  # the core block and four wall blocks


def _pipe_nodes(n, m, a):
    return ((n + 1) ** 2 + 4 * n * m) * (a + 1)  # interface nodes counted once


def test_mesh_auto_is_elliptic_with_a_note_and_conforming_blocks():
    made = meshgen.mesh("pipe", (N, M, A))
    assert made.method == "elliptic" and made.X is None
    assert any("meshing with elliptic" in line for line in made.notes)
    assert len(made.blocks) == 5
    points, cells, _ = merged_mesh(made.geometry, made.blocks)
    assert len(cells) == _pipe_cells(N, M, A)
    assert len(points) == _pipe_nodes(N, M, A)  # every interface node shared exactly
    report = meshgen.evaluate(made)
    assert report["cells"] == _pipe_cells(N, M, A) and report["inverted"]["count"] == 0
    assert made.quality["min_angle"].shape == (_pipe_cells(N, M, A),)


def test_carry_out_writes_cgns_zones_equal_to_tfi_of_each_block(tmp_path):
    made = carry_out(MeshRequest((N, M, A), "pipe", method="tfi", output=tmp_path / "pipe.cgns"))
    expected = tfi_blocks(load_block_set("pipe", None, (N, M, A)))
    zones = read_zones(tmp_path / "pipe.cgns")
    assert [z["name"] for z in zones] == ["core", "east", "north", "west", "south"]
    for zone, X in zip(zones, expected):
        np.testing.assert_allclose(zone["X"], X, rtol=0, atol=1e-12)
    sidecar = json.loads((tmp_path / "pipe.cgns.quality.json").read_text())
    assert sidecar["cells"] == made.quality_report["cells"] == _pipe_cells(N, M, A)
    assert sidecar["block_set"] == "pipe" and sidecar["block_dims"] == [N, M, A]


def test_mesh_write_and_api_write_of_a_block_set(tmp_path):
    import meshio

    made = meshgen.mesh("dfg-cylinder", (4, 3), "tfi")
    report = meshgen.write(tmp_path / "dfg.vtu", made)
    assert (
        len(meshio.read(tmp_path / "dfg.vtu").cells[0].data)
        == report["cells"]
        == sum((len(x) - 1) * (len(y) - 1) for x, y in made.geometry.coords)
    )
    assert (tmp_path / "dfg.vtu.quality.json").is_file()
    assert meshgen.write(tmp_path / "dfg.vtu", made, quality=False) is None
    assert not (tmp_path / "dfg.vtu.quality.json").exists()  # no sidecar describing another mesh
    made.write(tmp_path / "case", "openfoam")
    assert (tmp_path / "case" / "constant" / "polyMesh" / "owner").is_file()


@pytest.mark.parametrize(
    "options, parameter",
    [
        ({"method": "tfi", "correct": False}, "correct"),
        ({"method": "tfi", "tol": 1e-3}, "tol"),
        ({"boundary_layout": "fixed"}, "boundary_layout"),
        ({"chunked": True}, "chunked"),
    ],
)
def test_block_set_refuses_what_it_cannot_take(tmp_path, options, parameter):
    with pytest.raises(ParameterError) as caught:
        carry_out(MeshRequest((N, M, A), "pipe", output=tmp_path / "x.cgns", **options))
    assert caught.value.parameter == parameter
    assert not list(tmp_path.iterdir())


def test_compare_meshes_a_block_set(run_cli, tmp_path):
    import meshio

    result = run_cli("compare", "-g", "pipe", "--methods", "tfi,elliptic", "--dims", str(N), str(M), str(A), "--out", "out")
    assert result.returncode == 0, result.stderr
    rows = json.loads((tmp_path / "out" / "compare.json").read_text())["rows"]
    assert [row["name"] for row in rows] == ["tfi", "elliptic"]
    for row in rows:
        assert "error" not in row and row["quality"]["cells"] == _pipe_cells(N, M, A)
        written = meshio.read(tmp_path / "out" / f"{row['name']}.vtu")
        assert len(written.cells[0].data) == _pipe_cells(N, M, A) and len(written.points) == _pipe_nodes(N, M, A)


def _first_cells(made, patch):
    """Distances from each node on ``patch`` to its neighbour one layer in, and the node arrays'
    wall-normal lines, measured here from the blocks."""
    heights, lines = [], []
    for (block, face), (name, _) in made.geometry.patches.items():
        if name != patch:
            continue
        axis = {"xi": 0, "eta": 1, "zeta": 2}[face[:-1]]
        X = np.moveaxis(made.blocks[block], axis, 0)
        X = X[::-1] if face.endswith("1") else X  # from the wall inwards
        heights.append(np.linalg.norm(X[1] - X[0], axis=-1).ravel())
        lines.append(np.linalg.norm(np.diff(X, axis=0), axis=-1).reshape(len(X) - 1, -1))
    return np.concatenate(heights), np.concatenate(lines, axis=1)


@pytest.mark.parametrize("geometry, dims, patch", [("pipe", (6, 6, 2), "wall"), ("dfg-cylinder", (6, 5), "cylinder")])
def test_first_cell_height_on_a_wall_patch(geometry, dims, patch):
    height = 0.004 if geometry == "pipe" else 0.001
    spec = f"{height}" if patch == "wall" else f"{patch}={height}"
    made = meshgen.mesh(geometry, dims, "tfi", first_cell=spec)
    heights, widths = _first_cells(made, patch)
    # The wall layer's grid lines are straight in TFI: the mean first cell is the height asked.
    assert heights.mean() == pytest.approx(height, rel=1e-9)
    ratios = widths[1:] / widths[:-1]  # cells grow geometrically away from the wall, one ratio
    np.testing.assert_allclose(ratios, ratios[0, 0], rtol=1e-9)
    assert ratios[0, 0] > 1.0
    points, _, _ = merged_mesh(made.geometry, made.blocks)
    if geometry == "pipe":
        assert len(points) == _pipe_nodes(*dims)  # the graded blocks still share every interface node
    assert made.info["first_cell"][patch]["asked"] == height


def test_first_cell_elliptic_pipe_is_graded_and_valid():
    made = meshgen.mesh("pipe", (6, 6, 2), "elliptic", first_cell="0.004")
    heights, _ = _first_cells(made, "wall")
    uniform = meshgen.mesh("pipe", (6, 6, 2), "elliptic")
    assert heights.mean() < 0.5 * _first_cells(uniform, "wall")[0].mean()
    assert meshgen.evaluate(made)["inverted"]["count"] == 0


@pytest.mark.parametrize(
    "geometry, dims, spec, words",
    [
        ("pipe", (N, M, A), "nowhere=0.01", "has no patch 'nowhere'"),
        ("pipe", (N, M, A), "0.3", "not below the uniform cell"),
        ("pipe", (N, M, A), "-1", "positive length"),
        ("semicylinder", (4, 4, 4), "0.01", "multi-block"),
    ],
)
def test_first_cell_bad_input(geometry, dims, spec, words):
    with pytest.raises(ParameterError, match=words) as caught:
        meshgen.mesh(geometry, dims, "tfi", first_cell=spec)
    assert caught.value.parameter == "first_cell"


def test_first_cell_on_the_command_line(run_cli, tmp_path):
    result = run_cli("mesh", "-g", "pipe", "--dims", "4", "4", "2", "-m", "tfi", "--first-cell", "0.01", "-o", "p.msh")
    assert result.returncode == 0, result.stderr
    assert "first cells on wall: 0.01 mean" in result.stdout
    assert json.loads((tmp_path / "p.msh.quality.json").read_text())["method_info"]["first_cell"]["wall"]["asked"] == 0.01


@pytest.mark.parametrize("method", ["tfi", "elliptic"])
def test_cluster_a_patch_across_blocks(method):
    made = meshgen.mesh("pipe", (4, 5, 2), method, cluster=("wall:1.2",))
    _, widths = _first_cells(made, "wall")
    points, _, _ = merged_mesh(made.geometry, made.blocks)
    assert len(points) == _pipe_nodes(4, 5, 2)
    if method == "tfi":  # straight wall-layer lines: the widths themselves grow by 1.2 inwards
        np.testing.assert_allclose(widths[1:] / widths[:-1], 1.2, rtol=1e-9)
    else:  # the solver relaxes the grading but keeps it: smaller first cells than the ungraded mesh's
        uniform = meshgen.mesh("pipe", (4, 5, 2), method)
        assert widths[0].mean() < 0.8 * _first_cells(uniform, "wall")[1][0].mean()
    assert made.metadata()["cluster"] == ["wall:1.2"]

"""``meshgen evaluate`` of a .vts reads it as its grid (``meshgen.formats.read_grid``: no
connectivity, no stored quality arrays) and measures the node array on threads: the reports must
be those of the file read whole as a ``meshio.Mesh`` and of the serial ``quality_report``, to the
last bit; and the command's output and exit status in a process are the in-process ones."""

import json

import numpy as np
import pytest

from meshgen.formats import read_grid, read_mesh, write_mesh
from meshgen.geometry.grid import cell_connectivity
from meshgen.geometry.plugins import load_geometry
from meshgen.quality import quality_report
from meshgen.quality.files import evaluate_file


@pytest.fixture
def semicylinder_vts(run_cli, tmp_path):
    result = run_cli("mesh", "--method", "tfi", "--dims", "12", "10", "8", "-o", "m.vts", "-q")
    assert result.returncode == 0, result.stderr
    return tmp_path / "m.vts"


def test_read_grid_is_read_mesh_without_its_connectivity(semicylinder_vts):
    mesh = read_mesh(semicylinder_vts)
    grid = read_grid(semicylinder_vts)
    assert grid.node_shape == (13, 11, 9)
    assert np.array_equal(grid.points, mesh.points)
    assert np.array_equal(mesh.cells[0].data, cell_connectivity(grid.node_shape))
    assert set(grid.cell_data) == set(mesh.cell_data) and "min_angle" in grid.cell_data
    for name, values in mesh.cell_data.items():
        assert np.array_equal(grid.cell_data[name][0], values[0])
    assert np.array_equal(grid.point_data["patch"], mesh.point_data["patch"])
    only = read_grid(semicylinder_vts, cell_arrays=("min_angle",), point_arrays=())
    assert list(only.cell_data) == ["min_angle"] and only.point_data == {}
    assert read_grid(semicylinder_vts.with_suffix(".vts.quality.json")) is None  # not a .vts


def test_the_grid_path_reports_what_the_whole_read_and_the_serial_report_give(semicylinder_vts):
    report = evaluate_file(semicylinder_vts)
    assert report["structured"] and report["boundary_deviation"]["max"] < 1e-12
    assert report == evaluate_file(semicylinder_vts, mesh=read_mesh(semicylinder_vts))
    X = read_mesh(semicylinder_vts).points.reshape(13, 11, 9, 3)
    serial = quality_report(X, load_geometry("semicylinder"))
    for key in ("metrics", "inverted", "solver_figures", "cells"):
        assert report[key] == serial[key]
    assert {k: v for k, v in report["boundary_deviation"].items() if k != "source"} == serial["boundary_deviation"]


def sheared_box(dims, shear=0.3):
    axes = [np.linspace(0.0, 1.0, n + 1) for n in dims]
    X = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    X[..., 0] += shear * X[..., 1] ** 2
    return X


@pytest.mark.parametrize("dims", [(6, 5, 4), (7, 5)])
def test_a_vts_without_metadata_takes_the_unstructured_path_as_before(tmp_path, dims):
    path = tmp_path / "foreign.vts"
    X = sheared_box(dims)
    write_mesh(path, X)
    report = evaluate_file(path)
    assert not report["structured"] and report["cells"] == int(np.prod(dims))
    assert report == evaluate_file(path, mesh=read_mesh(path))


def test_a_vts_of_blocks_is_measured_block_by_block_as_before(tmp_path):
    path = tmp_path / "blocks.vts"
    dims = (6, 4, 4)
    blocks = np.repeat([0.0, 1.0], 48)  # cells of block 0 first (C order: i slowest), then block 1
    write_mesh(path, sheared_box(dims), cell_data={"block": blocks})
    report = evaluate_file(path, per_block=True)
    assert [b["file"] for b in report["blocks"]] == [f"{path}:0", f"{path}:1"]
    assert report == evaluate_file(path, mesh=read_mesh(path), per_block=True)


def test_the_command_keeps_the_output_and_the_exit_status(semicylinder_vts, run_cli, run_cli_process):
    in_process = run_cli("evaluate", semicylinder_vts, "--json", "-")
    process = run_cli_process("evaluate", semicylinder_vts, "--json", "-")
    assert process.returncode == 0, process.stderr
    assert json.loads(process.stdout) == json.loads(in_process.stdout)
    tripped = run_cli_process("evaluate", semicylinder_vts, "--fail-if", "cells>10", "-q")
    assert tripped.returncode == 1
    assert "gate cells>10: FAILED" in tripped.stderr and tripped.stdout == ""


def test_the_evaluate_command_imports_no_heavy_library():
    """The command's own start (design notes §21): numba loads in the metrics' worker or thread,
    rich for the table at the end; SciPy, torch, meshio, Dask, h5py and urllib (by
    ``xml.sax.saxutils``) are not needed to read a .vts and measure it."""
    import subprocess
    import sys

    code = "import sys, meshgen.cli.evaluate\nprint(' '.join(sorted(m for m in sys.argv[1:] if m in sys.modules)))\n"
    heavy = ["numba", "scipy", "torch", "meshio", "dask", "h5py", "rich", "urllib.request", "matplotlib", "trimesh"]
    done = subprocess.run([sys.executable, "-c", code, *heavy], capture_output=True, text=True, timeout=120, check=True)
    assert done.stdout.split() == []

"""Meshes larger than memory: block-wise meshing streamed into CGNS, block-wise evaluation, Dask.

Each block-wise result is checked against the in-memory path (or a second algorithm) on meshes
small enough for both, cut into many small blocks.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from neural_helpers import direct_correction

from meshgen.cli import cli
from meshgen.formats._cgns import read_node_block, zone_header
from meshgen.methods.clustering import node_coordinates
from meshgen.methods.tfi import tfi
from meshgen.quality import METRICS, quality_report
from meshgen.quality import sketch as sketches
from meshgen.quality.chunked import chunked_report
from meshgen.run.chunked import neural_array, tfi_array, write_chunked_mesh

pytest.importorskip("dask")


def read_whole(path):
    shape, _ = zone_header(path)
    return read_node_block(path, tuple(slice(0, n) for n in shape))


def assert_reports_agree(exact, blockwise, values):
    """Counts, min and max equal, means to rounding, percentiles within the sketch's bound."""
    assert blockwise["cells"] == exact["cells"]
    assert blockwise["inverted"] == exact["inverted"]
    for name in METRICS:
        a, b = exact["metrics"][name], blockwise["metrics"][name]
        assert b["min"] == a["min"] and b["max"] == a["max"], name
        assert b["mean"] == pytest.approx(a["mean"], rel=1e-12, abs=1e-14), name
        ordered = np.sort(values[name])
        for q, stat in ((0.01, "p01"), (0.99, "p99")):
            position = q * (len(ordered) - 1)
            around = ordered[int(np.floor(position))], ordered[int(np.ceil(position))]
            bound = sketches.RELATIVE_ACCURACY * max(abs(around[0]), abs(around[1])) + sketches.SMALLEST
            assert abs(b[stat] - a[stat]) <= bound * (1 + 1e-9), (name, stat, a[stat], b[stat])
    for key in ("max", "mean"):
        assert blockwise["boundary_deviation"][key] == pytest.approx(exact["boundary_deviation"][key], rel=1e-12, abs=1e-15)


def test_tfi_in_blocks_streamed_to_cgns_equals_the_in_memory_mesh_bit_for_bit(tmp_path, semicylinder):
    coords = node_coordinates((11, 7, 9), ["zeta:both:1.2"])
    X = tfi_array(semicylinder, coords, block_nodes=50)  # slabs of one k plane, split along i as well
    assert X.numblocks[:3] == (2, 1, 10)
    write_chunked_mesh(tmp_path / "m.cgns", X, semicylinder, {"method": "tfi"}, evaluate=False)
    assert np.array_equal(read_whole(tmp_path / "m.cgns"), tfi(semicylinder, None, coords))
    assert [p.name for p in tmp_path.iterdir()] == ["m.cgns"]
    import shutil
    import subprocess

    if shutil.which("cgnscheck"):  # the block-written file is a valid CGNS file too
        result = subprocess.run(["cgnscheck", str(tmp_path / "m.cgns")], capture_output=True, text=True, timeout=60)
        output = result.stdout + result.stderr
        assert result.returncode == 0 and "ERROR" not in output and "WARNING" not in output, output


def test_blockwise_evaluation_equals_the_whole_mesh_path(semicylinder, semidisk):
    rng = np.random.default_rng(3)
    for geometry, dims in ((semicylinder, (9, 8, 7)), (semidisk, (23, 17))):
        X = tfi(geometry, dims)
        X = X + rng.normal(0.0, 0.25 / max(dims), X.shape)  # some inverted cells, a spread of values
        exact = quality_report(X, geometry)
        blockwise = chunked_report(X, geometry, block_nodes=60)
        from meshgen.quality import cell_metrics

        values = cell_metrics(X)
        assert exact["inverted"]["count"] > 0
        assert_reports_agree(exact, blockwise, values)


def test_the_sketch_merges_exactly_and_keeps_its_relative_accuracy():
    rng = np.random.default_rng(0)
    values = np.concatenate([rng.normal(0.3, 1.0, 20000), np.zeros(50), rng.lognormal(0.0, 3.0, 5000)])
    parts = np.array_split(values, 7)
    merged = sketches.sketch_of(parts[0])
    for part in parts[1:]:
        merged = sketches.merge(merged, sketches.sketch_of(part))
    whole = sketches.sketch_of(values)
    for q in (0.0, 0.01, 0.3, 0.5, 0.99, 1.0):
        assert sketches.quantile(merged, q) == sketches.quantile(whole, q)
        exact = np.percentile(values, 100 * q)
        ordered = np.sort(values)
        position = q * (len(values) - 1)
        around = ordered[int(np.floor(position))], ordered[int(np.ceil(position))]
        bound = sketches.RELATIVE_ACCURACY * max(map(abs, around)) + sketches.SMALLEST
        assert abs(sketches.quantile(merged, q) - exact) <= bound * (1 + 1e-9)


def test_a_block_summary_is_numpys_count_sum_extremes_and_sketch():
    from meshgen.quality.summary import block_summaries, metric_summary

    rng = np.random.default_rng(1)
    values = np.concatenate([rng.normal(0.3, 1.0, 20000), np.zeros(50), rng.lognormal(0.0, 3.0, 5000), [1e-13, -1e-13]])
    for part in (values, -values, np.zeros(3), np.array([2.5]), np.abs(values) + 1e-3, rng.uniform(0.5, 179.5, 100000)):
        summary, expected = metric_summary(part), sketches.sketch_of(part)
        assert (summary["count"], summary["sum"], summary["min"], summary["max"]) == (
            part.size,
            np.sum(part),
            np.min(part),
            np.max(part),
        )
        sketch = summary["sketch"]
        assert sketch.zeros == expected.zeros
        for mine, theirs in ((sketch.positive, expected.positive), (sketch.negative, expected.negative)):
            assert mine.offset == theirs.offset and np.array_equal(mine.counts, theirs.counts)
    kept = rng.random(values.size) > 0.3
    summaries = block_summaries({"a": values, "b": values * 2.0, "none": values}, kept)
    assert summaries["b"]["count"] == np.count_nonzero(kept) and summaries["b"]["max"] == 2.0 * values[kept].max()
    assert block_summaries({"a": values}, np.zeros(values.size, dtype=bool)) == {}


def test_a_cgns_file_in_blocks_gives_the_node_arrays_report(tmp_path, semicylinder):
    """The file path (nodes by component in the file's order, buffers reused) against the node
    array's block-wise report: counts, extremes and percentiles equal, means to rounding."""
    from meshgen.formats import write_mesh

    rng = np.random.default_rng(4)
    X = tfi(semicylinder, (9, 8, 7))
    X = X + rng.normal(0.0, 0.3 / 9, X.shape)
    X[1, 1] = X[1, 2]  # degenerate cells
    write_mesh(tmp_path / "m.cgns", X)
    from_array = chunked_report(X, semicylinder, block_nodes=60)
    for block_nodes in (60, None):
        from_file = chunked_report(str(tmp_path / "m.cgns"), semicylinder, block_nodes=block_nodes)
        assert from_file["cells"] == from_array["cells"] and from_file["inverted"] == from_array["inverted"]
        assert from_array["inverted"]["degenerate"] > 0 and from_array["inverted"]["count"] > from_array["inverted"]["degenerate"]
        for name in METRICS:
            a, b = from_array["metrics"][name], from_file["metrics"][name]
            assert [b[k] for k in ("min", "max", "p01", "p99")] == [a[k] for k in ("min", "max", "p01", "p99")], name
            assert b["mean"] == pytest.approx(a["mean"], rel=1e-12, abs=1e-14), name
        for key in ("max", "mean", "nodes"):
            assert from_file["boundary_deviation"][key] == pytest.approx(from_array["boundary_deviation"][key], rel=1e-12)


def soft_model(rng):
    """A random soft-boundary network (no training needed: the correction's arithmetic is tested)."""
    import torch

    sizes = [3, 6, 6, 3]
    state = {}
    for index, (fan_in, fan_out) in enumerate(zip(sizes[:-1], sizes[1:])):
        state[f"layers.{index}.weight"] = torch.tensor(rng.normal(0, 0.5, (fan_out, fan_in)), dtype=torch.float32)
        state[f"layers.{index}.bias"] = torch.tensor(rng.normal(0, 0.1, fan_out), dtype=torch.float32)
    return {
        "dim": 3,
        "widths": sizes[1:-1],
        "state_dict": state,
        "scale": 1.5,
        "center": [0.0, 0.5, 1.0],
        "exact_boundary": False,
        "activation": "tanh",
        "input": "2*xi-1",
    }


def test_neural_blocks_correct_the_boundary_as_the_direct_gordon_hall_form_of_the_error(semicylinder):
    from meshgen.methods.tfi import parametric_grid
    from meshgen.neural.network_map import mesh_from_model

    model = soft_model(np.random.default_rng(1))
    dims = (6, 5, 7)
    coords = parametric_grid(dims)
    X, info = neural_array(model, semicylinder, coords, block_nodes=40)
    X = X.compute()
    M = mesh_from_model(model, coords)  # the network's map, in memory
    # g - M at every node (only the boundary values enter the TFI), looked up by parametric point.
    grid = np.stack(np.meshgrid(*coords, indexing="ij"), axis=-1).reshape(-1, 3)
    on_boundary = np.any((grid == 0.0) | (grid == 1.0), axis=1)
    error = np.zeros_like(M).reshape(-1, 3)
    error[on_boundary] = semicylinder.boundary(grid[on_boundary]) - M.reshape(-1, 3)[on_boundary]
    error = error.reshape(M.shape)

    def error_at(points):
        index = tuple(np.rint(points[:, d] * dims[d]).astype(int) for d in range(3))
        return error[index]

    expected = M + direct_correction(error_at, coords)  # the direct form, a second algorithm
    # the same network bits in both (M in memory); the two forms of the correction differ by float64 round-off
    assert np.allclose(X, expected, rtol=0, atol=1e-12)
    assert info["error_before"]["max"] == pytest.approx(np.linalg.norm(error.reshape(-1, 3), axis=1).max(), rel=1e-5)
    on_faces = X.reshape(-1, 3)[on_boundary]
    assert np.array_equal(on_faces, semicylinder.boundary(grid[on_boundary]))
    assert np.abs(X - M).max() > 0.1  # the correction did move the nodes


def in_memory_and_chunked(which: str, block_nodes: int, dims=(9, 6, 10)):
    """The in-memory mesh of ``which`` ("tfi", "neural" (the bundled exact-boundary model) or
    "soft" (a random soft-boundary network)) on the semicylinder, and the chunked one."""
    from meshgen.geometry import load_geometry
    from meshgen.geometry.layout import trained_layout, with_layout
    from meshgen.methods.correction import correct_boundary
    from meshgen.methods.tfi import parametric_grid
    from meshgen.neural.models import find_model
    from meshgen.neural.network_map import mesh_from_model

    geometry = load_geometry("semicylinder")
    coords = parametric_grid(dims)
    if which == "tfi":
        return tfi(geometry, None, coords), tfi_array(geometry, coords, block_nodes).compute()
    if which == "neural":
        checkpoint = find_model(geometry_name="semicylinder").checkpoint
        model, geometry = checkpoint["model"], with_layout(geometry, trained_layout(checkpoint))
    else:
        model = soft_model(np.random.default_rng(3))
    whole = mesh_from_model(model, coords, geometry)
    correct_boundary(whole, geometry, coords)  # what build_neural does, before the polish (not chunked)
    return whole, neural_array(model, geometry, coords, block_nodes=block_nodes)[0].compute()


@pytest.fixture(params=["compiled", "blas"])
def forward_path(request, monkeypatch):
    """The network's layers compiled (``dense_kernel``) or BLAS products (the whole grid evaluated
    at once, ``small_grid_network``) whatever the grid's size: ``NUMPY_WORK`` at 0 or past any
    grid here."""
    import meshgen.neural.mlp_numpy as mlp_numpy

    monkeypatch.setattr(mlp_numpy, "NUMPY_WORK", 0 if request.param == "compiled" else 10**18)
    return request.param


@pytest.mark.parametrize("which", ["tfi", "neural", "soft"])
@pytest.mark.parametrize("block_nodes", [37, 101, 257, 540])
def test_a_chunked_mesh_is_the_in_memory_mesh_bit_for_bit_at_any_block_size(which, block_nodes, forward_path):
    """Bits, not a tolerance: every node sees the same arithmetic in any block (the network's
    forward pass in a fixed order per node, ``meshgen.neural.mlp_numpy.dense_kernel``, or on small
    grids the whole grid's BLAS values cut to the block; the TFI and correction terms blended node
    by node; the boundary nodes set to g in both).
    Odd block sizes cut the grid into slabs and partial planes. (elliptic has no chunked path: it
    solves for all nodes at once.)"""
    whole, chunked = in_memory_and_chunked(which, block_nodes)
    assert np.array_equal(chunked, whole)


def test_the_compiled_and_blas_forward_passes_give_the_same_mesh_to_float32_round_off():
    """The bundled network's corrected mesh with every layer compiled and with every layer a BLAS
    product (the path is chosen by grid size, so either may make a user's mesh): the same to
    float32 round-off of the network (the two sum in different orders; bits would test one BLAS
    build), and each path's chunked mesh its in-memory mesh to the bit."""
    import meshgen.neural.mlp_numpy as mlp_numpy

    meshes = []
    for work in (0, 10**18):
        with pytest.MonkeyPatch.context() as patch:
            patch.setattr(mlp_numpy, "NUMPY_WORK", work)
            meshes.append(in_memory_and_chunked("neural", 257))
    for compiled, blas in zip(*meshes):
        np.testing.assert_allclose(blas, compiled, rtol=0, atol=1e-5 * np.abs(compiled).max())
    assert all(np.array_equal(whole, chunked) for whole, chunked in meshes)


def test_the_mesh_is_the_same_bits_with_one_or_two_threads(tmp_path):
    """The chunked and in-memory meshes of the bundled network in fresh processes with
    OMP_NUM_THREADS=1 and 2 (the BLAS and Dask thread counts that follow it): with the layers
    compiled, all four the same bits; with BLAS layers (small grids), all four the same bits."""
    script = (
        "import sys, numpy as np; sys.path.insert(0, sys.argv[1]); "
        "import meshgen.neural.mlp_numpy as m; m.NUMPY_WORK = int(sys.argv[3]); "
        "from test_chunked import in_memory_and_chunked; "
        "whole, chunked = in_memory_and_chunked('neural', 101, (7, 5, 8)); "
        "np.save(sys.argv[2] + '-whole.npy', whole); np.save(sys.argv[2] + '-chunked.npy', chunked)"
    )
    runs = [(threads, work) for threads in ("1", "2") for work in ("0", str(10**18))]  # compiled, BLAS
    for threads, work in runs:
        env = dict(os.environ, OMP_NUM_THREADS=threads, OPENBLAS_NUM_THREADS=threads)
        result = subprocess.run(
            [sys.executable, "-c", script, str(Path(__file__).parent), str(tmp_path / f"{threads}-{work}"), work],
            env=env,
            capture_output=True,
            text=True,
        )
        assert result.returncode == 0, result.stderr
    for work in ("0", str(10**18)):
        arrays = [np.load(tmp_path / f"{t}-{work}-{kind}.npy") for t in ("1", "2") for kind in ("whole", "chunked")]
        assert all(np.array_equal(array, arrays[0]) for array in arrays[1:])


@pytest.fixture(scope="module")
def cluster():
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=None) as local:
        yield local


def test_a_dask_distributed_cluster_gives_the_same_mesh_and_report(tmp_path, semicylinder, cluster):
    from distributed import Client

    runner = CliRunner()
    args = ["mesh", "-m", "tfi", "--dims", "10", "9", "8", "-q"]
    result = runner.invoke(cli, args + ["--scheduler", cluster.scheduler_address, "-o", str(tmp_path / "d.cgns")])
    assert result.exit_code == 0, result.output
    local = runner.invoke(cli, args + ["--in-memory", "-o", str(tmp_path / "m.cgns")])
    assert local.exit_code == 0, local.output
    assert np.array_equal(read_whole(tmp_path / "d.cgns"), read_whole(tmp_path / "m.cgns"))
    X = read_whole(tmp_path / "m.cgns")
    with Client(cluster.scheduler_address, set_as_default=False) as client:
        blockwise = chunked_report(str(tmp_path / "d.cgns"), semicylinder, client=client, block_nodes=100)
    from meshgen.quality import cell_metrics

    assert_reports_agree(quality_report(X, semicylinder), blockwise, cell_metrics(X))


def test_evaluate_in_blocks_agrees_with_evaluate_in_memory(tmp_path):
    runner = CliRunner()
    path = str(tmp_path / "e.cgns")
    assert runner.invoke(cli, ["mesh", "-m", "tfi", "--dims", "12", "10", "9", "--chunked", "-q", "-o", path]).exit_code == 0
    sidecar = json.loads(open(path + ".quality.json").read())
    reports = {}
    modes = {
        "--chunked": ["--chunked"],
        "--in-memory": ["--in-memory"],
        "--block-nodes=1024": ["--chunked", "--block-nodes=1024"],
    }
    for mode, options in modes.items():  # the last: 2 blocks of 7 k planes
        result = runner.invoke(cli, ["evaluate", path, *options, "--json", "-"])
        assert result.exit_code == 0, result.output
        reports[mode] = json.loads(result.output)
    from meshgen.quality import cell_metrics

    X = read_whole(path)
    assert_reports_agree(reports["--in-memory"], reports["--chunked"], cell_metrics(X))
    assert_reports_agree(reports["--in-memory"], reports["--block-nodes=1024"], cell_metrics(X))
    too_small = runner.invoke(cli, ["evaluate", path, "--chunked", "--block-nodes", "10"])
    assert too_small.exit_code == 2 and "--block-nodes" in too_small.output
    assert sidecar["metrics"] == reports["--chunked"]["metrics"]  # mesh's report: the block-wise evaluate of its file


@pytest.mark.parametrize(
    "args, expected",
    [
        (
            ["-m", "tfi", "--dims", "4", "4", "4", "--chunked", "-o", "{dir}/x.vtu"],
            "formats that can: .vts, .pvts, .cgns, --format openfoam",
        ),
        (["-m", "tfi", "--dims", "2000", "2000", "2000", "-o", "{dir}/x.vtk"], "cannot be written block by block"),
        (["-m", "tfi", "--dims", "2000", "2000", "2000", "-o", "{dir}/x.xyz"], "overflow a binary record's 32-bit byte count"),
        (["-m", "tfi", "--dims", "1000", "1000", "1000", "--format", "openfoam", "-o", "{dir}/case"], "32-bit OpenFOAM labels"),
        (["-m", "elliptic", "--dims", "4", "4", "4", "--chunked", "-o", "{dir}/x.cgns"], "methods that can: tfi, neural"),
        (["-m", "tfi", "-g", "semidisk", "--dims", "1000000", "1000000", "-o", "{dir}/x.cgns"], "GB free"),
        (["-m", "tfi", "--dims", "100000", "100000", "100000", "-o", "{dir}/x.cgns"], "even block by block"),
        (
            ["-m", "tfi", "--dims", "4", "4", "4", "--scheduler", "tcp://127.0.0.1:9", "-o", "{dir}/x.cgns"],
            "cannot reach the Dask scheduler",
        ),
    ],
)
def test_bad_input_is_one_line_exit_2_and_nothing_written(tmp_path, args, expected):
    import subprocess
    import sys
    import time

    start = time.perf_counter()
    command = [sys.executable, "-m", "meshgen", "mesh", *(a.format(dir=tmp_path) for a in args)]
    result = subprocess.run(command, capture_output=True, text=True, timeout=60)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and expected in lines[0], result.stderr
    assert list(tmp_path.iterdir()) == []
    assert time.perf_counter() - start < 30  # an unreachable scheduler fails fast


def test_an_interrupted_write_leaves_no_file(tmp_path, semicylinder):
    X = tfi_array(semicylinder, node_coordinates((8, 8, 8)), block_nodes=100)

    def interrupt(done, total, phase):
        if done == 3:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        write_chunked_mesh(tmp_path / "i.cgns", X, semicylinder, progress=interrupt)
    assert list(tmp_path.iterdir()) == []


def test_dask_is_not_imported_by_help():
    import subprocess
    import sys

    code = "import sys; from meshgen.cli import cli\ntry:\n    cli.main(['--help'])\nexcept SystemExit: pass\nprint('dask' in sys.modules)"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env={**os.environ})
    assert result.stdout.strip().splitlines()[-1] == "False"


def test_no_quality_writes_the_mesh_alone(tmp_path):
    import meshio

    runner = CliRunner()
    for name, extra in (("a.vtu", []), ("b.cgns", ["--chunked"])):
        result = runner.invoke(
            cli, ["mesh", "-m", "tfi", "--dims", "4", "3", "5", "--no-quality", "-q", *extra, "-o", str(tmp_path / name)]
        )
        assert result.exit_code == 0, result.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.vtu", "b.cgns"]  # no .quality.json
    assert meshio.read(tmp_path / "a.vtu").cell_data == {}
    assert read_whole(tmp_path / "b.cgns").shape == (5, 4, 6, 3)


def test_mesh_block_nodes_sets_the_blocks_and_not_the_mesh(tmp_path):
    """``meshgen mesh --block-nodes``: more, smaller blocks; the same coordinates bit for bit and the
    same report (means to rounding) as the size chosen from the memory."""
    runner = CliRunner()
    paths = {name: str(tmp_path / f"{name}.cgns") for name in ("default", "small")}
    base = ["mesh", "-m", "tfi", "--dims", "12", "10", "9", "--chunked", "-q"]
    assert runner.invoke(cli, [*base, "-o", paths["default"]]).exit_code == 0
    result = runner.invoke(cli, [*base, "--block-nodes", "1024", "-o", paths["small"]])
    assert result.exit_code == 0, result.output
    sidecars = {name: json.loads(open(path + ".quality.json").read()) for name, path in paths.items()}
    assert sidecars["default"]["method_info"]["chunked"]["blocks"] == 1
    assert sidecars["small"]["method_info"]["chunked"]["blocks"] == 2  # 10 k planes of 143 nodes, 7 planes per block
    assert np.array_equal(read_whole(paths["default"]), read_whole(paths["small"]))
    X = read_whole(paths["default"])
    from meshgen.quality import cell_metrics

    assert_reports_agree(sidecars["default"], sidecars["small"], cell_metrics(X))


@pytest.mark.parametrize(
    "options, expected",
    [
        (["--dims", "4", "4", "4", "--block-nodes", "2048"], "--block-nodes sets the blocks of the chunked path; add --chunked"),
        (["--dims", "400", "400", "400", "--chunked", "--block-nodes", str(10**12)], "memory is available; give at most"),
    ],
)
def test_mesh_block_nodes_that_cannot_apply_or_fit_are_refused(tmp_path, options, expected):
    result = CliRunner().invoke(cli, ["mesh", "-m", "tfi", *options, "-o", str(tmp_path / "x.cgns")])
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and expected in lines[0], result.output
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("node_shape", [(301, 301, 301), (1001, 1001, 17), (1001, 1001, 1001), (2001, 2001), (41, 11, 9)])
def test_evaluation_blocks_with_their_halo_stay_near_the_block_size(node_shape):
    """Every node is owned by one block, and a block with the planes read around it holds at most
    the block size (plus one halo row of the first axis where planes are split)."""
    import itertools

    from meshgen.quality.chunked import READ_HALO, evaluation_slices

    block_nodes = 1 << 20
    per_axis = evaluation_slices(node_shape, block_nodes)
    for axis, slices in zip(node_shape, per_axis):
        assert [s.start for s in slices] == [0] + [s.stop for s in slices[:-1]] and slices[-1].stop == axis
    rest = int(np.prod(node_shape[1:-1]))
    for block in itertools.product(*per_axis):
        read = [min(s.stop + 2, n) - max(s.start - 1, 0) for s, n in zip(block, node_shape)]
        allowance = READ_HALO * rest * (1 + READ_HALO) if len(per_axis[0]) > 1 else 0
        assert int(np.prod(read)) <= block_nodes + allowance, (block, read)

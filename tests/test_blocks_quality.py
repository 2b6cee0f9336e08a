"""Quality of block sets as of single blocks: whole-mesh figures that count interfaces as interior
faces (checked against the structured figures of one grid cut into blocks, and against checkMesh),
each block's figures measured with its neighbours, and the boundary deviation from the block set
(checked against the pipe's exact distance to its surface)."""

import json
import re

import numpy as np
import pytest
from openfoam_helpers import needs_openfoam, run_tool

import meshgen
from meshgen.formats.multiblock import patch_faces, write_blocks
from meshgen.geometry.block_nodes import merged_mesh
from meshgen.geometry.blocks import load_block_set, tfi_blocks
from meshgen.geometry.grid import cell_connectivity
from meshgen.geometry.plugins import load_geometry
from meshgen.methods.tfi import tfi
from meshgen.quality.deviation import ON_BOUNDARY
from meshgen.quality.faces_openfoam import non_orthogonality
from meshgen.quality.merged import merged_solver_figures
from meshgen.quality.smoothness import expansion_ratio, grid_smoothness

PIPE = {"radius": 0.5, "length": 4.0}


def _rough(geometry, dims, seed=0):
    X = tfi(load_geometry(geometry), dims)
    return X + 0.02 * np.ptp(X) / max(dims) * np.random.default_rng(seed).standard_normal(X.shape)


def _close(a, b):
    assert a == pytest.approx(b, rel=1e-12, abs=1e-14)


@pytest.mark.parametrize("geometry, dims", [("semicylinder", (7, 5, 6)), ("semidisk", (9, 7))])
def test_one_grid_cut_in_two_blocks_measures_as_the_structured_grid(geometry, dims):
    """A structured grid cut at i = 3 into two blocks: the merged figures (faces matched by their
    nodes) are the structured ones of the whole grid, and each block's are the structured per-cell
    figures of its cells, which see the other block's cells across the cut."""
    X = _rough(geometry, dims)
    cells = cell_connectivity(X.shape[:-1])  # C order: the cells with i < 3 come first
    cell_shape = tuple(n - 1 for n in X.shape[:-1])
    block = (np.unravel_index(np.arange(len(cells)), cell_shape)[0] >= 3).astype(int)
    shapes = [(3, *cell_shape[1:]), (cell_shape[0] - 3, *cell_shape[1:])]
    whole, first, second = merged_solver_figures(X.reshape(-1, X.shape[-1]), cells, block, ("a", "b"), shapes)
    faces = non_orthogonality(X, "numpy")
    for name, per_cell in (("expansion_ratio", expansion_ratio(X)), ("grid_smoothness", grid_smoothness(X))):
        _close(whole[name]["max"], per_cell.max())
        _close(whole[name]["mean"], per_cell.mean())
        _close(first[name]["max"], per_cell[:3].max())
        _close(second[name]["max"], per_cell[3:].max())
        assert whole[name]["max"] == max(first[name]["max"], second[name]["max"])
    for name in ("non_orthogonality_internal", "non_orthogonality_boundary"):
        _close(whole[name]["max"], faces[name]["max"])
        _close(whole[name]["average"], faces[name]["average"])
        assert whole[name]["faces"] == faces[name]["faces"]
    # The cut's faces belong to both blocks: their internal faces add up to the whole's and the cut.
    cut = int(np.prod(cell_shape[1:]))
    assert first["non_orthogonality_internal"]["faces"] + second["non_orthogonality_internal"]["faces"] == (
        faces["non_orthogonality_internal"]["faces"] + cut
    )


@needs_openfoam
def test_whole_mesh_face_non_orthogonality_is_checkmeshs(tmp_path):
    """The pipe's O-grid (interfaces where three blocks meet): the whole mesh's internal-face
    figure is the one checkMesh prints for the case meshgen writes."""
    made = meshgen.mesh("pipe", dims=(8, 4, 6), method="elliptic")
    made.write(tmp_path / "pipe", "openfoam", quality=False)
    log = run_tool("checkMesh", tmp_path / "pipe").stdout
    found = re.search(r"Mesh non-orthogonality Max: (\S+) average: (\S+)", log)
    internal = made.report()["solver_figures"]["non_orthogonality_internal"]
    assert internal["max"] == pytest.approx(float(found[1]), rel=1e-8)
    assert internal["average"] == pytest.approx(float(found[2]), rel=1e-8)
    assert internal["faces"] == int(re.search(r"internal faces:\s+(\d+)", log)[1])


@pytest.mark.parametrize("geometry, dims", [("pipe", ("8", "4", "6")), ("dfg-cylinder", ("8", "6"))])
def test_per_block_figures_never_exceed_the_whole_mesh(run_cli, tmp_path, geometry, dims):
    assert run_cli("mesh", "-g", geometry, "--dims", *dims, "-o", "m.cgns", "-q").returncode == 0
    result = run_cli("evaluate", "m.cgns", "--per-block", "--json", "-")
    assert result.returncode == 0, result.stderr
    whole, *blocks = json.loads(result.stdout)
    assert len(blocks) == len(load_block_set(geometry, None, tuple(map(int, dims))).names)
    for metric, stats in whole["metrics"].items():
        for stat in ("min", "max"):
            pick = max if stat == "max" else min
            assert stats[stat] == pick(b["metrics"][metric][stat] for b in blocks), (metric, stat)
    for name in ("expansion_ratio", "grid_smoothness", "non_orthogonality_internal", "non_orthogonality_boundary"):
        assert whole["solver_figures"][name]["max"] == max(b["solver_figures"][name]["max"] for b in blocks), name
    # The table shows them: no blank whole-mesh column (the Markdown table: rows that do not wrap).
    assert run_cli("evaluate", "m.cgns", "--per-block", "--markdown", "t.md", "-q").returncode == 0
    row = next(line for line in (tmp_path / "t.md").read_text().splitlines() if "| expansion ratio max" in line)
    assert row.split("|")[2].strip().startswith(f"{whole['solver_figures']['expansion_ratio']['max']:.4g} at cell")


def _pipe_distance(points, radius=PIPE["radius"], length=PIPE["length"]):
    """The exact distance of points near the pipe's surface to it (the cylinder's side and its
    end discs), written independently of meshgen's boundary maps."""
    r = np.hypot(points[:, 0], points[:, 1])
    z = points[:, 2]
    side = np.where((z >= 0) & (z <= length), np.abs(r - radius), np.hypot(np.maximum(r - radius, 0), np.maximum(-z, z - length)))
    inside = r <= radius
    ends = np.where(
        inside, np.minimum(np.abs(z), np.abs(z - length)), np.hypot(r - radius, np.minimum(np.abs(z), np.abs(z - length)))
    )
    return np.minimum(side, ends)


def _moved_pipe(dims=(6, 3, 8)):
    """The pipe's TFI mesh with one wall node pushed out by 2e-3 and one inlet node by 5e-4."""
    block_set = load_block_set("pipe", None, dims)
    Xs = tfi_blocks(block_set)
    east = block_set.names.index("east")
    node = Xs[east][-1, 1, 3]
    Xs[east][-1, 1, 3, :2] = node[:2] * (PIPE["radius"] + 2e-3) / np.hypot(*node[:2])
    Xs[east][2, 1, 0, 2] = -5e-4
    return block_set, Xs


def test_block_set_deviation_is_the_distance_to_the_pipe(run_cli, tmp_path):
    block_set, Xs = _moved_pipe()
    points, _, _ = merged_mesh(block_set, Xs)
    boundary = np.unique(np.concatenate([faces.reshape(-1) for _, _, faces in patch_faces(block_set)]))
    expected = _pipe_distance(points[boundary])
    for name in ("m.cgns", "m.vtu"):  # zones with their parametric seeds; merged boundary nodes
        write_blocks(tmp_path / name, block_set, Xs, {"block_set": "pipe", "params": PIPE, "block_dims": [6, 3, 8]})
        result = run_cli("evaluate", name, "-g", "pipe", "--json", "-")
        assert result.returncode == 0, result.stderr
        deviation = json.loads(result.stdout)["boundary_deviation"]
        assert deviation["nodes"] == len(boundary)
        assert deviation["max"] == pytest.approx(expected.max(), rel=1e-9)
        assert deviation["mean"] == pytest.approx(expected.mean(), rel=1e-9)
        assert deviation["source"] == "--geometry"
        # The file records its block set: evaluated without -g, the same figure.
        recorded = json.loads(run_cli("evaluate", name, "--json", "-").stdout)["boundary_deviation"]
        assert recorded["max"] == pytest.approx(expected.max(), rel=1e-9) and recorded["source"] == "recorded in the mesh file"


def test_in_memory_block_set_report_has_deviation_even_where_nodes_slid():
    """The elliptic mesh's inlet and outlet nodes slide in their planes, off the blocks' own maps of
    the end discs: they are still on the pipe's boundary, and measured so."""
    made = meshgen.mesh("pipe", dims=(6, 3, 4), method="elliptic")
    deviation = made.report()["boundary_deviation"]
    points, _, _ = merged_mesh(made.geometry, made.blocks)
    boundary = np.unique(np.concatenate([faces.reshape(-1) for _, _, faces in patch_faces(made.geometry)]))
    assert deviation["nodes"] == len(boundary)
    # The measure stops searching within ON_BOUNDARY of a node's own face (its resolution); the
    # closed-form distance to the pipe is the exact check.
    assert deviation["max"] < ON_BOUNDARY * deviation["characteristic_length"]
    assert _pipe_distance(points[boundary]).max() < 1e-12

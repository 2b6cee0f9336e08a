"""Topology files (``meshgen.geometry.topology_file``, ``meshgen.geometry.topology``): blocks by
their vertices, interfaces from shared faces, counts along chains of parallel edges, curved edges,
and the one-line errors of bad files."""

import json
from pathlib import Path

import numpy as np
import pytest

from meshgen.errors import GeometryError
from meshgen.geometry.block_nodes import global_numbering, interface_gaps, merged_mesh
from meshgen.geometry.blocks import block_spec, load_block_set, tfi_blocks

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "topologies"
HEX = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]


def write(tmp_path, text: str, name: str = "t.yaml") -> str:
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def block_set(path):
    assert block_spec(path) == path  # a topology file is a block set, not a shape file
    return load_block_set(path, None, None if path is None else (1,) * 3)


def load(path, dim):
    return load_block_set(path, None, (1,) * dim)


def test_one_hex_is_the_unit_cube_grid(tmp_path):
    path = write(
        tmp_path, f"vertices: {HEX}\nblocks: [[0, 1, 2, 3, 4, 5, 6, 7]]\ncells: {{counts: [[0, 1, 4], [0, 3, 5], [0, 4, 6]]}}\n"
    )
    blocks = load(path, 3)
    assert blocks.node_shapes == [(5, 6, 7)] and blocks.interfaces == ()
    (X,) = tfi_blocks(blocks)
    expected = np.stack(np.meshgrid(*(np.linspace(0, 1, n) for n in (5, 6, 7)), indexing="ij"), axis=-1)
    np.testing.assert_allclose(X, expected, atol=1e-14)
    # Every face is a patch, the default one here.
    assert sorted(blocks.patches) == [(0, f) for f in ("eta0", "eta1", "xi0", "xi1", "zeta0", "zeta1")]
    assert {v for v in blocks.patches.values()} == {("defaultFaces", "wall")}


def test_two_hexes_sharing_a_turned_face_conform(tmp_path):
    # The second block's vertices start elsewhere on the shared face (x = 1): its axes are turned.
    right = [[2, 0, 0], [2, 1, 0], [2, 1, 1], [2, 0, 1]]
    vertices = HEX + right  # 8..11; the right block's xi runs along y, eta along z, zeta along x
    text = (
        f"vertices: {vertices}\n"
        "blocks: [[0, 1, 2, 3, 4, 5, 6, 7], {name: right, vertices: [1, 2, 6, 5, 8, 9, 10, 11]}]\n"
        "cells: {counts: [[0, 1, 3], [0, 3, 4], [0, 4, 5], [1, 8, 2]]}\n"
    )
    blocks = load(write(tmp_path, text), 3)
    assert len(blocks.interfaces) == 1
    interface = blocks.interfaces[0]
    assert (blocks.names[interface.a], interface.face_a.name, blocks.names[interface.b], interface.face_b.name) == (
        "b0", "xi1", "right", "zeta0",
    )  # fmt: skip
    assert blocks.node_shapes == [(4, 5, 6), (5, 6, 3)]  # the counts follow the chains into the turned block
    assert interface.transform == (3, 1, 2)  # a's xi -> b's zeta, eta -> xi, zeta -> eta
    Xs = tfi_blocks(blocks)
    assert max(interface_gaps(blocks, Xs)) < 1e-14
    numbering, count = global_numbering(blocks)
    assert count == 4 * 5 * 6 + 5 * 6 * 3 - 5 * 6  # the shared face's nodes merged
    points, cells, _ = merged_mesh(blocks, Xs)
    assert len(np.unique(np.round(points, 12), axis=0)) == count  # no two numbers for one point


def test_counts_propagate_along_a_chain_of_three_blocks(tmp_path):
    # Three 2D blocks in a row; the count given on the first one's left edge reaches the third.
    text = (
        "vertices: {a: [0, 0], b: [1, 0], c: [3, 0], d: [3.5, 0], e: [0, 1], f: [1, 1], g: [3, 1], h: [3.5, 1]}\n"
        "blocks: [[a, b, f, e], [b, c, g, f], [c, d, h, g]]\n"
        "cells: {size: 0.25, counts: [[a, e, 7]]}\n"
    )
    blocks = load(write(tmp_path, text), 2)
    assert blocks.node_shapes == [(5, 8), (9, 8), (3, 8)]  # x: ceil(length / 0.25) per block


def test_a_count_given_twice_differently_names_the_chain(tmp_path):
    text = (
        "vertices: {a: [0, 0], b: [1, 0], c: [2, 0], e: [0, 1], f: [1, 1], g: [2, 1]}\n"
        "blocks: [[a, b, f, e], [b, c, g, f]]\n"
        "cells: {size: 0.5, counts: [[a, e, 4], [c, g, 5]]}\n"
    )
    with pytest.raises(GeometryError, match=r"chain of parallel edges a-e, b-f, c-g is given 4 cells \(at a-e\) and 5"):
        load(write(tmp_path, text), 2)


def test_arc_nodes_lie_on_the_circle_evenly(tmp_path):
    # A quarter annulus, radii 1 and 2: the arcs through a point and about a centre.
    s = np.sqrt(0.5)
    text = (
        "vertices: [[1, 0], [2, 0], [0, 2], [0, 1]]\n"
        "blocks: [[0, 1, 2, 3]]\n"
        f"edges: [{{arc: [1, 2], through: [{2 * s}, {2 * s}]}}, {{arc: [3, 0], center: [0, 0]}}]\n"
        "cells: {counts: [[0, 1, 3], [1, 2, 12]]}\n"
    )
    blocks = load(write(tmp_path, text), 2)
    (X,) = tfi_blocks(blocks)
    for index, radius in ((0, 1.0), (-1, 2.0)):
        side = X[index]  # xi = 0 the inner arc, xi = 1 the outer one
        np.testing.assert_allclose(np.hypot(side[:, 0], side[:, 1]), radius, rtol=1e-13)
        np.testing.assert_allclose(np.arctan2(side[:, 1], side[:, 0]), np.linspace(0, np.pi / 2, 13), atol=1e-13)
    inside = np.hypot(X[1:-1, :, 0], X[1:-1, :, 1])
    assert np.all((inside > 1) & (inside < 2))


def test_first_cell_height_and_growth_cap(tmp_path):
    text = (
        "vertices: [[0, 0], [1, 0], [1, 1], [0, 1]]\nblocks: [[0, 1, 2, 3]]\n"
        "cells: {size: 0.25}\ngrading: {first_cell: {floor: 0.01}, growth: 1.3}\n"
        "patches: {floor: {type: wall, faces: [[0, 1]]}}\n"
    )
    blocks = load(write(tmp_path, text), 2)
    eta = blocks.coords[0][1]
    widths = np.diff(eta)
    assert widths[0] == pytest.approx(0.01, rel=1e-9)  # the edge is 1 long: parametric = physical
    assert np.max(widths[1:] / widths[:-1]) <= 1.3 + 1e-9
    assert len(widths) > 4  # 4 cells (size 0.25) cannot reach 0.01 within growth 1.3: more were added


def test_polyline_and_spline_edges_pass_their_points(tmp_path):
    text = (
        "vertices: [[0, 0], [2, 0], [2, 1], [0, 1]]\nblocks: [[0, 1, 2, 3]]\n"
        "edges: [{polyline: [0, 1], points: [[1, -0.5]]}, {spline: [2, 3], points: [[1, 1.5]]}]\n"
        "cells: {counts: [[0, 1, 4], [0, 3, 2]]}\n"
    )
    (X,) = tfi_blocks(load(write(tmp_path, text), 2))
    np.testing.assert_allclose(X[2, 0], [1, -0.5], atol=1e-12)  # half-way in length on the polyline
    np.testing.assert_allclose(X[:, 0, 1], [0, -0.25, -0.5, -0.25, 0], atol=1e-12)
    np.testing.assert_allclose(X[2, -1], [1, 1.5], atol=1e-12)  # the natural spline through its point


GOOD_2D = (
    "vertices: {a: [0, 0], b: [1, 0], c: [2, 0], e: [0, 1], f: [1, 1], g: [2, 1]}\n"
    "blocks: [[a, b, f, e], [b, c, g, f]]\ncells: {size: 0.5}\n"
)


@pytest.mark.parametrize(
    "text, words",
    [
        (
            GOOD_2D + "cels: {size: 1}\n",
            "unknown key 'cels' in the file (keys: name, description, vertices, blocks, joint, pipe, edges, cells, grading, patches, default_patch, surfaces); did you mean 'cells'?",
        ),
        (GOOD_2D.replace("[b, c, g, f]", "[b, c, q, f]"), "block 'b1' names a missing vertex 'q'"),
        (GOOD_2D.replace("[b, c, g, f]", "[b, f, g, c]"), "block 'b1' is left-handed (inverted)"),
        (
            GOOD_2D.replace("cells: {size: 0.5}", "cells: {size: 0.5, counts: [[a, e, 2], [c, g, 3]]}"),
            "is given 2 cells (at a-e) and 3 (at c-g)",
        ),
        (GOOD_2D + "patches: {inlet: {type: patch, faces: [[a, f]]}}\n", "patch 'inlet': (a f) is not a face of any block"),
        (GOOD_2D + "patches: {inlet: {type: patch, faces: [[b, f]]}}\n", "patch 'inlet': the face (b f) is between two blocks"),
        (GOOD_2D + "edges: [{arc: [a, b], throgh: [0.5, 0.2]}]\n", "unknown key 'throgh' in edges[0]"),
        (GOOD_2D + "edges: [{arc: [a, f], through: [0.5, 0.2]}]\n", "edge arc a-f is not an edge of any block"),
        (GOOD_2D + "edges: [{arc: [a, b], through: [0.5, 0]}]\n", "the point it passes through is on the line"),
        ("vertices: !!python/object/apply:os.system ['true']\nblocks: []\n", "is not plain YAML data"),
        ("vertices: [[0, 0]]\nblocks: &x [[0, 0, 0, 0]]\nname: *x\n", "uses a YAML anchor or alias"),
        (GOOD_2D.replace("cells: {size: 0.5}", "cells: {}"), "has no cell count: give cells: size"),
    ],
)
def test_bad_files_are_one_line(tmp_path, text, words):
    with pytest.raises(GeometryError) as raised:
        load(write(tmp_path, text), 2)
    message = str(raised.value)
    assert words in message and "\n" not in message


def test_faces_that_do_not_coincide_say_block_face_and_gap(tmp_path):
    # 3D: the second block's face x = 1 shares 3 of the first's 4 vertices; its fourth is 0.1 off.
    shifted = HEX + [[2, 0, 0], [2, 1, 0], [2, 1, 1], [2, 0, 1], [1, 1.1, 1]]
    text = f"vertices: {shifted}\nblocks: [[0, 1, 2, 3, 4, 5, 6, 7], [1, 8, 9, 2, 5, 11, 10, 12]]\ncells: {{size: 0.5}}\n"
    with pytest.raises(
        GeometryError, match=r"block 'b\d' face xi\d \(.*\) share 3 of their 4 vertices: '6' and '12' are 0.1 apart"
    ):
        load(write(tmp_path, text), 3)
    # 2D: the blocks meet at x = 1, but the second names that side's points b2 and f2.
    text = GOOD_2D.replace("[b, c, g, f]", "[b2, c, g, f2]").replace("g: [2, 1]}", "g: [2, 1], b2: [1, 0], f2: [1, 1]}")
    with pytest.raises(
        GeometryError,
        match=r"face xi\d \(.*\) and block 'b\d' face xi\d \(.*\) coincide but vertices '.*' and '.*' \(gap 0\) are different names",
    ):
        load(write(tmp_path, text), 2)


def test_cli_bad_topology_exits_2_writing_nothing(run_cli, tmp_path):
    write(tmp_path, GOOD_2D.replace("[b, c, g, f]", "[b, c, q, f]"), "bad.yaml")
    result = run_cli("mesh", "-g", "bad.yaml", "--method", "tfi", "-o", "x.cgns")
    assert result.returncode == 2
    assert "missing vertex 'q'" in result.stderr and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert not list(tmp_path.glob("x.*"))


def test_cli_meshes_a_topology_without_dims_and_refines(run_cli, run_cli_process, tmp_path):
    write(tmp_path, GOOD_2D, "two.yaml")
    result = run_cli("mesh", "-g", "two.yaml", "--method", "elliptic", "-o", "two.cgns", "-q")
    assert result.returncode == 0, result.stderr
    refined = run_cli("mesh", "-g", "two.yaml", "--method", "tfi", "--param", "refine=2", "-o", "fine.vtu")
    assert refined.returncode == 0, refined.stderr
    assert "2 blocks, 32 cells" in refined.stdout  # 2 x (2 x 2) cells at size 0.5, refined twice per axis
    missing = run_cli("mesh", "-g", "pipe", "-o", "p.cgns")
    assert missing.returncode == 2 and "--dims" in missing.stderr
    # the mesh records the topology file, not a name no lookup finds: evaluate (a new process, where
    # the file was not given) asks for -g FILE, and with it measures the boundary deviation
    alone = run_cli_process("evaluate", "two.cgns")
    assert alone.returncode == 0 and "recorded block set is the file two.yaml" in alone.stderr, alone.stderr
    given = run_cli("evaluate", "two.cgns", "-g", "two.yaml", "--json", "two.json")
    assert given.returncode == 0, given.stderr
    deviation = json.loads((tmp_path / "two.json").read_text())["boundary_deviation"]
    assert deviation["max"] < 1e-12


@pytest.mark.slow
@pytest.mark.parametrize("name", ["cylinder-2d.yaml", "cylinder-3d.yaml"])  # 3D: its wall projected onto a cylinder
def test_cylinder_example_is_valid_and_passes_checkmesh(run_cli, tmp_path, name):
    from openfoam_helpers import check_mesh, missing_reason

    example = str(EXAMPLES / name)
    result = run_cli("mesh", "-g", example, "--method", "elliptic", "--format", "openfoam", "-o", "case")
    assert result.returncode == 0, result.stderr
    assert "inverted cells: 0 (0.00%)" in result.stdout
    if missing_reason() is not None:
        pytest.skip(missing_reason())
    report = check_mesh(tmp_path / "case")
    assert report["ok"], report["log"][-2000:]


BLOCKMESH_DICT = """FoamFile { version 2.0; format ascii; class dictionary; object blockMeshDict; }
vertices ((1 0 0) (2 0 0) (0 2 0) (0 1 0) (1 0 1) (2 0 1) (0 2 1) (0 1 1) (3 0 0) (3 2 0) (3 0 1) (3 2 1));
blocks (hex (0 1 2 3 4 5 6 7) (3 8 2) simpleGrading (4 1 1) hex (1 8 9 2 5 10 11 6) (5 8 2) simpleGrading (1 1 1));
edges (arc 1 2 (1.41421356237 1.41421356237 0) arc 5 6 (1.41421356237 1.41421356237 1)
       arc 0 3 (0.707106781187 0.707106781187 0) arc 4 7 (0.707106781187 0.707106781187 1));
boundary ();
"""
SAME_TOPOLOGY = """vertices: [[1, 0, 0], [2, 0, 0], [0, 2, 0], [0, 1, 0], [1, 0, 1], [2, 0, 1], [0, 2, 1], [0, 1, 1],
  [3, 0, 0], [3, 2, 0], [3, 0, 1], [3, 2, 1]]
blocks: [[0, 1, 2, 3, 4, 5, 6, 7], [1, 8, 9, 2, 5, 10, 11, 6]]
edges: [{arc: [1, 2], center: [0, 0, 0]}, {arc: [5, 6], center: [0, 0, 1]}, {arc: [0, 3], center: [0, 0, 0]},
  {arc: [4, 7], center: [0, 0, 1]}]
cells: {counts: [[0, 1, 3], [0, 3, 8], [0, 4, 2], [1, 8, 5]]}
grading: {ratios: [[0, 1, 4]]}
"""


@pytest.mark.slow
def test_tfi_of_a_topology_is_blockmeshs_mesh_of_the_same_blocks(tmp_path):
    """blockMesh (an independent implementation: arcs, expansion ratios, its own interpolation)
    meshes the same two blocks to the same points."""
    import re

    from openfoam_helpers import missing_reason, run_tool

    if missing_reason() is not None:
        pytest.skip(missing_reason())
    case = tmp_path / "case"
    (case / "system").mkdir(parents=True)
    (case / "system" / "blockMeshDict").write_text(BLOCKMESH_DICT)
    (case / "system" / "controlDict").write_text(
        "FoamFile { version 2.0; format ascii; class dictionary; object controlDict; }\n"
        "application blockMesh; startFrom startTime; startTime 0; stopAt endTime; endTime 1; deltaT 1;\n"
        "writeControl timeStep; writeInterval 1; writeFormat ascii; writePrecision 15;\n"
    )
    assert run_tool("blockMesh", case).returncode == 0
    text = (case / "constant" / "polyMesh" / "points").read_text()
    theirs = np.array(re.findall(r"^\(([-\d.e+]+) ([-\d.e+]+) ([-\d.e+]+)\)$", text, re.MULTILINE), dtype=float)
    blocks = load(write(tmp_path, SAME_TOPOLOGY), 3)
    points, _, _ = merged_mesh(blocks, tfi_blocks(blocks))
    assert len(points) == len(theirs) == 4 * 9 * 3 + 5 * 9 * 3
    ours = points[np.lexsort(np.round(points, 9).T)]
    theirs = theirs[np.lexsort(np.round(theirs, 9).T)]
    np.testing.assert_allclose(ours, theirs, atol=1e-9)


def test_spline_edge_is_scipys_natural_cubic_spline():
    from scipy.interpolate import CubicSpline

    from meshgen.geometry.topology import curve

    rng = np.random.default_rng(3)
    for inner in (1, 2, 7, 40):
        points = rng.random((inner + 2, 3))
        chord = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
        t = np.linspace(0.0, 1.0, 517)
        expected = CubicSpline(chord / chord[-1], points, axis=0, bc_type="natural")(t)
        found = curve("spline", points[0], points[-1], (None, points[1:-1]))(t)
        np.testing.assert_allclose(found, expected, atol=1e-13)

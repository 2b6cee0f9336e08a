"""Bad shape files through the CLI: one line on stderr saying what is wrong (and where), exit
status 2, nothing written."""

import numpy as np
import pytest
from shape_helpers import DUCT_NAMES, duct_surface, voxel_surface, write_ascii_stl, write_twisted_loft


def refused(run_cli, folder, geometry, *words):
    result = run_cli("mesh", "-g", geometry, "--method", "tfi", "--dims", "2", "2", "2", "-o", "m.vtu")
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.returncode == 2, result.stderr
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    for word in words:
        assert word in lines[0], lines[0]
    assert not (folder / "m.vtu").exists()
    return lines[0]


@pytest.fixture
def duct():
    return duct_surface(n_bend=8, n_width=3, n_height=2)


def test_an_open_surface_says_how_many_edges_and_where(run_cli, tmp_path, duct):
    vertices, triangles, labels = duct
    keep = np.ones(len(triangles), dtype=bool)
    keep[5] = False
    write_ascii_stl(tmp_path / "open.stl", vertices, triangles[keep], labels[keep])
    refused(run_cli, tmp_path, "open.stl", "open: 3 edge(s)", "e.g. the edge at (")


def test_a_non_manifold_surface_says_where(run_cli, tmp_path, duct):
    vertices, triangles, labels = duct
    a, b = triangles[0, :2]
    vertices = np.concatenate([vertices, [vertices[a] + [0.0, 5.0, 0.0]]])
    fin = np.array([[a, b, len(vertices) - 1], [b, a, len(vertices) - 1]])  # a two-sided fin on an edge
    write_ascii_stl(tmp_path / "fin.stl", vertices, np.concatenate([triangles, fin]), np.concatenate([labels, [2, 2]]))
    refused(run_cli, tmp_path, "fin.stl", "not manifold: 1 edge(s)", "e.g. the edge at (")


def test_five_patches_say_what_was_found(run_cli, tmp_path, duct):
    vertices, triangles, labels = duct
    merged = np.where(labels == 5, 4, labels)  # ceiling and floor in one solid: not connected
    merged = np.where(labels == 3, 2, merged)  # outer and inner: neither
    write_ascii_stl(tmp_path / "four.stl", vertices, triangles, merged, names=DUCT_NAMES)
    refused(run_cli, tmp_path, "four.stl", "separate pieces")
    # an L-shaped wall of two neighbouring patches: five patches, corners counted per patch
    merged = np.where(labels == 4, 2, labels)  # floor joins the inner wall
    write_ascii_stl(tmp_path / "five.stl", vertices, triangles, merged, names=DUCT_NAMES)
    line = refused(run_cli, tmp_path, "five.stl", "splits into 5 patch(es) with corners", "six patches of four corners")
    assert "inlet: 3" in line  # the floor-inner corner of the inlet is no corner any more


def _solid_surface(cells, label_of):
    vertices, triangles, normals = voxel_surface(cells)
    centres = vertices[triangles].mean(axis=1)
    return vertices, triangles, np.array([label_of(c, n) for c, n in zip(centres, normals)])


def test_a_patch_with_a_hole_is_refused(run_cli, tmp_path):
    # a 3 x 3 x 1 block with a square hole through it: the top is a face with a hole
    cells = [(i, j, 0) for i in range(3) for j in range(3) if (i, j) != (1, 1)]

    def label(centre, normal):
        x, y, z = centre
        if x in (0.0, 3.0):
            return 0 if x == 0 else 1
        if y in (0.0, 3.0):
            return 2 if y == 0 else 3
        return 4 if z == 1.0 else 5  # the hole's walls join the bottom

    vertices, triangles, labels = _solid_surface(cells, label)
    write_ascii_stl(tmp_path / "holed.stl", vertices, triangles, labels, names=("a", "b", "c", "d", "top", "bottom"))
    refused(run_cli, tmp_path, "holed.stl", "has a hole: 2 boundary loops")


def test_a_patch_with_a_handle_is_refused(run_cli, tmp_path):
    # a 5 x 3 x 1 block with a bridge on top: the top face has a handle
    cells = [(i, j, 0) for i in range(5) for j in range(3)] + [(1, 1, 1), (3, 1, 1), (1, 1, 2), (2, 1, 2), (3, 1, 2)]

    def label(centre, normal):
        x, y, z = centre
        if z < 1.0 and x in (0.0, 5.0):
            return 0 if x == 0 else 1
        if z < 1.0 and y in (0.0, 3.0):
            return 2 if y == 0 else 3
        return 4 if z >= 1.0 else 5

    vertices, triangles, labels = _solid_surface(cells, label)
    write_ascii_stl(tmp_path / "bridge.stl", vertices, triangles, labels, names=("a", "b", "c", "d", "top", "bottom"))
    refused(run_cli, tmp_path, "bridge.stl", "has a handle")


def test_two_solids_in_one_step_file(run_cli, tmp_path):
    pytest.importorskip("gmsh", reason="CAD files need the gmsh Python package (pip install gmsh)")
    write_twisted_loft(tmp_path / "two.step", solids=2)
    refused(run_cli, tmp_path, "two.step", "holds 2 solids")


def test_a_left_handed_assignment_is_refused(run_cli, tmp_path, duct):
    vertices, triangles, labels = duct
    write_ascii_stl(tmp_path / "bend.stl", vertices, triangles, labels)
    (tmp_path / "bend.yaml").write_text(
        "surface: bend.stl\nfaces: {xi0: floor, xi1: ceiling, eta0: outer, eta1: inner, zeta0: outlet, zeta1: inlet}\n"
    )
    refused(run_cli, tmp_path, "bend.yaml", "left-handed")


@pytest.mark.parametrize(
    ("name", "content", "words"),
    [
        ("part.step", b"\x89PNG\r\n\x1a\n" + bytes(range(256)) * 4, ("is not a readable STEP file",)),
        ("duct.stl", b"solid x\n this is not an STL file at all\nendsolid\n", ("is not a",)),
        ("duct.ply", b"ply but not really\n\x00\x01\x02", ("is not a readable PLY surface",)),
        ("duct.obj", b"", ("is empty",)),
        ("duct.stl", b"", ("is empty",)),
        ("duct.yaml", b"surface: [unclosed\n", ("is not valid YAML",)),
    ],
)
def test_a_file_that_is_not_what_its_extension_says_or_is_empty(run_cli, tmp_path, name, content, words):
    if name.endswith(".step"):
        pytest.importorskip("gmsh", reason="CAD files need the gmsh Python package (pip install gmsh)")
    (tmp_path / name).write_bytes(content)
    refused(run_cli, tmp_path, name, *words)


def test_a_missing_or_unreadable_file(run_cli, tmp_path):
    refused(run_cli, tmp_path, "nowhere.stl", "does not exist")
    (tmp_path / "folder.stl").mkdir()
    refused(run_cli, tmp_path, "folder.stl", "is a folder: meshgen reads regular files only")


def test_a_missing_file_named_in_the_yaml(run_cli, tmp_path):
    (tmp_path / "a.yaml").write_text("surface: missing.stl\n")
    refused(run_cli, tmp_path, "a.yaml", "the file missing.stl named for 'surface' does not exist")
    (tmp_path / "b.yaml").write_text("patches:\n  inlet: in.stl\n")
    refused(run_cli, tmp_path, "b.yaml", "the file in.stl named for patch 'inlet' does not exist")

"""Shapes from triangulated surfaces: a bent rectangular duct built by the test, as a multi-solid
ASCII STL, a single-solid STL split at its sharp edges, OBJ and PLY; meshes checked against the
surface itself (trimesh's closest point), the duct's closed-form corners and OpenFOAM's checkMesh."""

import re

import numpy as np
import pytest
from openfoam_helpers import check_mesh, needs_openfoam
from shape_helpers import DUCT_CORNERS, DUCT_NAMES, distance_to_triangles, duct_point, duct_surface, write_ascii_stl

import meshgen
from meshgen.geometry.plugins import load_geometry
from meshgen.quality import quality_report


@pytest.fixture
def duct(tmp_path):
    vertices, triangles, labels = duct_surface(n_bend=16, n_width=6, n_height=4)
    return write_ascii_stl(tmp_path / "duct.stl", vertices, triangles, labels), (vertices, triangles)


def boundary_nodes(X):
    mask = np.zeros(X.shape[:3], dtype=bool)
    mask[[0, -1]], mask[:, [0, -1]], mask[:, :, [0, -1]] = True, True, True
    return X[mask]


def test_solids_become_the_patches_and_the_ends_go_on_zeta(duct):
    geometry = load_geometry(str(duct[0]))
    assert geometry.name == "duct" and geometry.dim == 3 and geometry.values == {}
    named = {face: name for face, (name, _) in geometry.patches.items()}
    assert sorted(named.values()) == sorted(DUCT_NAMES)
    assert {named["zeta0"], named["zeta1"]} == {"inlet", "outlet"}  # the smallest opposite pair
    assert geometry.patches["zeta0"][1] == "patch" and geometry.patches["xi0"][1] == "wall"
    assert len(geometry.boundary_map.face_lines) == 6


@pytest.mark.parametrize("method", ["tfi", "elliptic"])
def test_meshes_of_the_duct_lie_on_its_surface(duct, method):
    path, (vertices, triangles) = duct
    result = meshgen.mesh(str(path), (6, 4, 12), method=method)
    X = result.X
    report = quality_report(X, result.geometry)
    assert report["inverted"]["count"] == 0
    distance = distance_to_triangles(boundary_nodes(X), vertices, triangles)
    length = np.linalg.norm(vertices.max(0) - vertices.min(0))
    assert distance.max() < 1e-9 * length
    corners = X[[0, -1]][:, [0, -1]][:, :, [0, -1]].reshape(-1, 3)
    expected = np.array([duct_point(*c) for c in DUCT_CORNERS])
    gaps = np.linalg.norm(corners[:, None] - expected[None], axis=-1).min(axis=1)
    assert gaps.max() < 1e-12  # each mesh corner is one of the duct's eight corners


def test_a_single_solid_splits_at_its_sharp_edges(tmp_path):
    vertices, triangles, _ = duct_surface(n_bend=12, n_width=4, n_height=3)
    path = write_ascii_stl(tmp_path / "plain.stl", vertices, triangles)
    geometry = load_geometry(str(path))
    assert sorted(name for name, _ in geometry.patches.values()) == [f"patch{k}" for k in range(1, 7)]
    X = meshgen.mesh(geometry, (4, 3, 8), method="tfi").X
    assert quality_report(X, geometry)["inverted"]["count"] == 0


@pytest.mark.parametrize("extension", ["obj", "ply", "stl"])
def test_obj_ply_and_binary_stl_surfaces(tmp_path, extension):
    import trimesh

    vertices, triangles, _ = duct_surface(n_bend=12, n_width=4, n_height=3)
    path = tmp_path / f"duct.{extension}"
    trimesh.Trimesh(vertices, triangles, process=False).export(path)
    geometry = load_geometry(str(path))  # one piece: split at its sharp edges
    X = meshgen.mesh(geometry, (4, 3, 8), method="tfi").X
    assert quality_report(X, geometry)["inverted"]["count"] == 0
    written = trimesh.load(path, process=False)  # the file's own (rounded) coordinates
    distance = distance_to_triangles(boundary_nodes(X), np.asarray(written.vertices), np.asarray(written.faces))
    assert distance.max() < 1e-9 * 4


@needs_openfoam
def test_an_openfoam_case_of_the_duct_passes_check_mesh(run_cli, duct, tmp_path):
    result = run_cli(
        "mesh", "-g", duct[0], "--method", "elliptic", "--dims", "6", "4", "12", "--format", "openfoam", "-o", "case"
    )
    assert result.returncode == 0, result.stderr
    report = check_mesh(tmp_path / "case")
    assert report["ok"], report["log"][-2000:]
    assert set(report["patches"]) == set(DUCT_NAMES)


def test_solids_whose_shared_points_differ_in_the_last_digits_are_welded(tmp_path):
    vertices, triangles, labels = duct_surface(n_bend=8, n_width=3, n_height=2)
    path = write_ascii_stl(tmp_path / "duct.stl", vertices, triangles, labels)
    # rewrite one solid with 12 significant digits: its edge points no longer match bit for bit
    text = path.read_text().split("endsolid inlet\n", 1)
    rounded = re.sub(r"vertex (\S+) (\S+) (\S+)", lambda m: "vertex " + " ".join(f"{float(w):.12g}" for w in m.groups()), text[0])
    path.write_text(rounded + "endsolid inlet\n" + text[1])
    geometry = load_geometry(str(path))
    assert sorted(name for name, _ in geometry.patches.values()) == sorted(DUCT_NAMES)

"""Shapes from CAD files through gmsh (OCC): a twisted loft the test builds and exports; meshes
checked against gmsh's own closest point on the CAD faces, the CAD vertices and OCC's volume."""

import numpy as np
import pytest
from shape_helpers import distance_to_cad, enclosed_volume, write_twisted_loft

import meshgen
from meshgen.geometry.plugins import load_geometry
from meshgen.quality import quality_report

gmsh = pytest.importorskip("gmsh", reason="CAD files need the gmsh Python package (pip install gmsh)")


def boundary_nodes(X):
    mask = np.zeros(X.shape[:3], dtype=bool)
    mask[[0, -1]], mask[:, [0, -1]], mask[:, :, [0, -1]] = True, True, True
    return X[mask]


@pytest.fixture(scope="module")
def loft(tmp_path_factory):
    path = tmp_path_factory.mktemp("cad") / "loft.step"
    return path, write_twisted_loft(path)


@pytest.mark.parametrize("method", ["tfi", "elliptic"])
def test_a_loft_from_step_meshes_on_its_cad_surface(loft, method):
    path, volume = loft
    result = meshgen.mesh(str(path), (6, 6, 12), method=method)
    X = result.X
    assert quality_report(X, result.geometry)["inverted"]["count"] == 0
    distance, vertices = distance_to_cad(boundary_nodes(X), path)
    length = np.linalg.norm(vertices.max(0) - vertices.min(0))
    assert distance.max() < 1e-7 * length
    corners = X[[0, -1]][:, [0, -1]][:, :, [0, -1]].reshape(-1, 3)
    gaps = np.linalg.norm(corners[:, None] - vertices[None], axis=-1).min(axis=1)
    assert gaps.max() < 1e-9 * length and len(vertices) == 8
    # flat-faced cells under curved faces: the volume converges at second order; 6x6x12 gets 1e-2
    assert abs(enclosed_volume(X) - volume) < 1e-2 * volume


@pytest.mark.parametrize("extension", ["brep", "iges"])
def test_brep_and_iges_files(tmp_path, extension):
    path = tmp_path / f"loft.{extension}"
    write_twisted_loft(path)
    geometry = load_geometry(str(path))
    X = meshgen.mesh(geometry, (4, 4, 6), method="tfi").X
    assert quality_report(X, geometry)["inverted"]["count"] == 0
    distance, vertices = distance_to_cad(boundary_nodes(X), path)
    assert distance.max() < 1e-6


def test_the_loft_ends_go_on_zeta_and_faces_are_named(loft):
    geometry = load_geometry(str(loft[0]))
    names = [name for name, _ in geometry.patches.values()]
    assert sorted(names) == [f"face{k}" for k in range(1, 7)]
    # the two flat ends (faces 5 and 6 of the loft) are the smallest opposite pair
    assert {geometry.patches["zeta0"][0], geometry.patches["zeta1"][0]} == {"face5", "face6"}


def test_yaml_corners_of_a_step_solid(loft, tmp_path):
    import itertools
    import math

    def corner(i, j, k):  # the loft's end rectangles (tests/shape_helpers.write_twisted_loft)
        w, h, angle, z = (2.0, 1.0, 0.0, 0.0) if k == 0 else (1.8, 1.0, math.radians(70), 3.0)
        x, y = (i - 0.5) * w, (j - 0.5) * h
        return [math.cos(angle) * x - math.sin(angle) * y, math.sin(angle) * x + math.cos(angle) * y, z]

    corners = [corner(*ijk) for ijk in itertools.product((0, 1), repeat=3)]
    (tmp_path / "part.yaml").write_text(f"surface: {loft[0]}\ncorners: {corners}\n")
    geometry = load_geometry(str(tmp_path / "part.yaml"))
    assert geometry.patches["zeta0"][0] == "face5" and geometry.patches["zeta1"][0] == "face6"
    X = meshgen.mesh(geometry, (3, 3, 4), method="tfi").X
    for i, j, k in itertools.product((0, 1), repeat=3):
        assert np.allclose(X[(0, -1)[i], (0, -1)[j], (0, -1)[k]], corner(i, j, k), atol=1e-12)

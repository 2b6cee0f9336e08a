"""Geometry files (YAML), the faces view (``geometries show FILE -o faces.vtu``), the layout cache
keyed by a shape file's content, ``meshgen.load_geometry`` on shape files, and OpenFOAM cases of a
STEP solid with the patch names a YAML file gives."""

import shutil

import numpy as np
import pytest
from openfoam_helpers import check_mesh, needs_openfoam
from shape_helpers import DUCT_NAMES, duct_point, duct_surface, write_ascii_stl, write_twisted_loft

import meshgen
from meshgen.geometry.layout import cache_path
from meshgen.geometry.plugins import Geometry, load_geometry
from meshgen.quality import quality_report


@pytest.fixture
def duct(tmp_path):
    vertices, triangles, labels = duct_surface(n_bend=12, n_width=4, n_height=3)
    return tmp_path, (vertices, triangles, labels)


def test_yaml_assigns_faces_renames_and_types(duct):
    folder, (vertices, triangles, labels) = duct
    write_ascii_stl(folder / "bend.stl", vertices, triangles, labels)
    (folder / "bend.yaml").write_text(
        "surface: bend.stl\n"
        "faces: {xi0: floor, xi1: ceiling, eta0: inner, eta1: outer, zeta0: outlet, zeta1: inlet}\n"
        "rename: {floor: bottom}\n"
        "types: {bottom: symmetry, ceiling: wall}\n"
    )
    geometry = load_geometry(str(folder / "bend.yaml"))
    assert geometry.patches["xi0"] == ("bottom", "symmetry")
    assert geometry.patches["zeta0"] == ("outlet", "patch") and geometry.patches["zeta1"] == ("inlet", "patch")
    X = meshgen.mesh(geometry, (3, 4, 8), method="tfi").X
    assert quality_report(X, geometry)["inverted"]["count"] == 0
    # the node at the cube's (0, 0, 0) corner: floor (y = -0.3), inner wall (radius 1.5), outlet (x = 0)
    assert np.abs(X[0, 0, 0] - [0.0, -0.3, 1.5]).max() < 1e-12


def test_editing_a_geometry_files_surface_takes_effect_in_the_same_process(duct):
    # The loaded geometry is kept per state of the YAML file and of the surface it names: a surface
    # rewritten (here the duct made 2.5 times as large) is read again though the YAML is unchanged.
    folder, (vertices, triangles, labels) = duct
    write_ascii_stl(folder / "bend.stl", vertices, triangles, labels)
    (folder / "bend.yaml").write_text(
        "surface: bend.stl\nfaces: {xi0: floor, xi1: ceiling, eta0: inner, eta1: outer, zeta0: outlet, zeta1: inlet}\n"
    )
    first = meshgen.mesh(str(folder / "bend.yaml"), (2, 2, 4), method="tfi").X
    write_ascii_stl(folder / "bend.stl", 2.5 * vertices, triangles, labels)
    second = meshgen.mesh(str(folder / "bend.yaml"), (2, 2, 4), method="tfi").X
    np.testing.assert_allclose(second, 2.5 * first, rtol=1e-9, atol=1e-12)


def test_yaml_with_one_file_per_patch(duct):
    folder, (vertices, triangles, labels) = duct
    lines = []
    for k, name in enumerate(DUCT_NAMES):
        write_ascii_stl(folder / f"{name}.stl", vertices, triangles[labels == k], None)
        lines.append(f"  {name}: {{file: {name}.stl{', type: patch' if name == 'floor' else ''}}}")
    (folder / "parts.yml").write_text("patches:\n" + "\n".join(lines) + "\n")
    geometry = load_geometry(str(folder / "parts.yml"))
    assert sorted(name for name, _ in geometry.patches.values()) == sorted(DUCT_NAMES)
    assert dict(geometry.patches.values())["floor"] == "patch"
    X = meshgen.mesh(geometry, (3, 3, 6), method="tfi").X
    assert quality_report(X, geometry)["inverted"]["count"] == 0


def test_show_writes_each_triangle_with_its_cube_face(duct, run_cli):
    import meshio

    folder, (vertices, triangles, labels) = duct
    write_ascii_stl(folder / "duct.stl", vertices, triangles, labels)
    result = run_cli("geometries", "show", "duct.stl", "-o", "faces.vtu")
    assert result.returncode == 0, result.stderr
    assert len([line for line in result.stderr.splitlines() if "<-" in line]) == 6  # one line per face
    written = meshio.read(folder / "faces.vtu")
    face = written.cell_data["cube_face"][0]
    assert len(face) == len(triangles)
    geometry = load_geometry(str(folder / "duct.stl"))
    names = ["xi0", "xi1", "eta0", "eta1", "zeta0", "zeta1"]
    # every triangle of a solid carries the cube face that solid went to
    tri_of = {tuple(sorted(map(tuple, np.round(vertices[t], 12)))): labels[n] for n, t in enumerate(triangles)}
    for n, t in enumerate(written.cells_dict["triangle"]):
        solid = DUCT_NAMES[tri_of[tuple(sorted(map(tuple, np.round(written.points[t], 12))))]]
        assert geometry.patches[names[face[n]]][0] == solid


def test_the_layout_cache_is_keyed_by_the_file_content(duct):
    folder, (vertices, triangles, labels) = duct
    first = write_ascii_stl(folder / "a" / "duct.stl" if (folder / "a").mkdir() is None else None, vertices, triangles, labels)
    (folder / "b").mkdir()
    same = folder / "b" / "duct.stl"
    shutil.copy(first, same)
    changed = folder / "duct.stl"
    write_ascii_stl(changed, vertices * 1.5, triangles, labels)
    paths = [cache_path(load_geometry(str(p))) for p in (first, same, changed)]
    assert paths[0] == paths[1] != paths[2]
    assert paths[0].name.startswith("duct-")


def test_load_geometry_of_a_step_file_is_a_geometry(tmp_path):
    pytest.importorskip("gmsh", reason="CAD files need the gmsh Python package (pip install gmsh)")
    path = tmp_path / "part.step"
    write_twisted_loft(path)
    geometry = meshgen.load_geometry(str(path))
    assert isinstance(geometry, Geometry) and geometry.dim == 3 and geometry.name == "part"
    assert geometry.characteristic_length > 0


@needs_openfoam
def test_an_openfoam_case_of_a_step_solid_passes_check_mesh(tmp_path, run_cli):
    pytest.importorskip("gmsh", reason="CAD files need the gmsh Python package (pip install gmsh)")
    write_twisted_loft(tmp_path / "part.step")
    (tmp_path / "part.yaml").write_text(
        "surface: part.step\nrename: {face5: inlet, face6: outlet, face1: wall, face2: wall, face3: wall, face4: wall}\n"
    )
    result = run_cli(
        "mesh", "-g", "part.yaml", "--method", "elliptic", "--dims", "5", "5", "10", "--format", "openfoam", "-o", "case"
    )
    assert result.returncode == 0, result.stderr
    report = check_mesh(tmp_path / "case")
    assert report["ok"], report["log"][-2000:]
    assert set(report["patches"]) == {"inlet", "outlet", "wall"}


def test_geometries_lists_the_shape_formats(run_cli):
    result = run_cli("geometries")
    assert result.returncode == 0, result.stderr
    for extension in (".step", ".stp", ".iges", ".igs", ".brep", ".stl", ".obj", ".ply", ".yaml"):
        assert extension in result.stdout


def test_show_of_a_step_file_samples_its_faces(tmp_path, run_cli):
    pytest.importorskip("gmsh", reason="CAD files need the gmsh Python package (pip install gmsh)")
    import meshio

    write_twisted_loft(tmp_path / "part.step")
    result = run_cli("geometries", "show", "part.step", "-o", "faces.vtu", "--resolution", "4")
    assert result.returncode == 0, result.stderr
    written = meshio.read(tmp_path / "faces.vtu")
    face = written.cell_data["cube_face"][0]
    assert np.array_equal(np.bincount(face), [32] * 6)  # 2 x 4 x 4 triangles on each cube face
    # the zeta0 triangles lie on the loft's flat end z = 0
    zeta0 = written.cells_dict["triangle"][face == 4]
    assert np.abs(written.points[zeta0][..., 2]).max() < 1e-9


def test_yaml_corners_fix_the_assignment(duct):
    import itertools

    from meshgen.errors import GeometryError

    folder, (vertices, triangles, labels) = duct
    write_ascii_stl(folder / "bend.stl", vertices, triangles, labels)
    # xi across the width (inner to outer), eta up, zeta along the bend: right-handed
    corners = [duct_point(0.5 * np.pi * k, i - 0.5, 0.6 * j - 0.3).tolist() for i, j, k in itertools.product((0, 1), repeat=3)]
    (folder / "bend.yaml").write_text(f"surface: bend.stl\ncorners: {corners}\n")
    geometry = load_geometry(str(folder / "bend.yaml"))
    assert {face: name for face, (name, _) in geometry.patches.items()} == {
        "xi0": "inner",
        "xi1": "outer",
        "eta0": "floor",
        "eta1": "ceiling",
        "zeta0": "inlet",
        "zeta1": "outlet",
    }
    X = meshgen.mesh(geometry, (3, 3, 6), method="tfi").X
    assert np.array_equal(X[0, 0, 0], duct_point(0.0, -0.5, -0.3)) and np.array_equal(
        X[-1, -1, -1], duct_point(0.5 * np.pi, 0.5, 0.3)
    )
    swapped = [corners[i * 4 + k * 2 + j] for i, j, k in itertools.product((0, 1), repeat=3)]  # eta <-> zeta: left-handed
    (folder / "left.yaml").write_text(f"surface: bend.stl\ncorners: {swapped}\n")
    with pytest.raises(GeometryError, match="left-handed"):
        load_geometry(str(folder / "left.yaml"))
    (folder / "off.yaml").write_text(f"surface: bend.stl\ncorners: {[[9.0, 9.0, 9.0]] + corners[1:]}\n")
    with pytest.raises(GeometryError, match=r"corner \(0, 0, 0\) \(9, 9, 9\) is no corner"):
        load_geometry(str(folder / "off.yaml"))


def test_the_parametrisation_is_kept_between_runs(duct, monkeypatch):
    from meshgen.geometry import cube
    from meshgen.geometry.shapes import triangulated
    from meshgen.geometry.shapes.assemble import content_hash

    folder, (vertices, triangles, labels) = duct
    path = write_ascii_stl(folder / "duct.stl", vertices, triangles, labels)
    key = content_hash([path], {"test": "kept"})
    first = triangulated.surface_block([path], "duct", content_hash=key)
    points = cube.face_samples(3, 7)

    def refuse(*args, **kwargs):
        raise AssertionError("parametrised again")

    monkeypatch.setattr(triangulated, "parametrise", refuse)
    again = triangulated.surface_block([path], "duct", content_hash=key)  # from the cache file
    assert np.array_equal(first.pieces(points), again.pieces(points))
    with pytest.raises(AssertionError, match="parametrised again"):
        triangulated.surface_block([path], "duct", content_hash=content_hash([path], {"test": "other"}))

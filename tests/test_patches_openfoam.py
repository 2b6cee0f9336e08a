"""Named boundary patches, the OpenFOAM case writer and CGNS boundary conditions, checked by the
real tools: OpenFOAM's checkMesh and potentialFoam, cgnscheck; and by our own readers."""

import json
import shutil
import subprocess

import numpy as np
import pytest
from openfoam_helpers import check_mesh, needs_openfoam, read_vector_field, run_tool, solver_residuals, write_potential_flow

from meshgen.errors import MeshgenError
from meshgen.formats import read_mesh, read_patches, write_mesh
from meshgen.geometry import cube
from meshgen.geometry.patches import geometry_patches, parse_patch_options
from meshgen.geometry.plugins import load_geometry
from meshgen.methods.tfi import tfi
from meshgen.quality import cell_metrics, quality_report

cgnscheck = shutil.which("cgnscheck")
needs_cgnscheck = pytest.mark.skipif(cgnscheck is None, reason="cgnscheck not installed (Debian package cgns-convert)")


def expected_face_counts(patches, dims) -> dict[str, int]:
    """Faces of each patch of a structured grid of ``dims`` cells: a cube face normal to axis a
    has the product of the other axes' cell counts (2D meshes extruded: + frontAndBack)."""
    counts = {}
    for patch in patches:
        for name in patch.faces:
            face = cube.face_named(name, len(dims))
            counts[patch.name] = counts.get(patch.name, 0) + int(np.prod([n for d, n in enumerate(dims) if d != face.axis]))
    if len(dims) == 2:
        counts["frontAndBack"] = 2 * dims[0] * dims[1]
    return counts


def make(method, name, dims):
    from meshgen.methods.clustering import node_coordinates
    from meshgen.methods.registry import make_mesh

    geometry = load_geometry(name)
    X, _ = make_mesh(method, geometry, node_coordinates(dims))
    return geometry, X


# --- the patch model -----------------------------------------------------------------------


def test_builtins_name_their_faces_and_defaults_are_the_face_names(tmp_path):
    semicylinder = {p.name: (p.type, p.faces) for p in geometry_patches(load_geometry("semicylinder"))}
    assert semicylinder == {
        "inlet": ("patch", ("zeta0",)),
        "outlet": ("patch", ("zeta1",)),
        "wall": ("wall", ("xi0", "xi1", "eta1")),
        "symmetry": ("symmetry", ("eta0",)),
    }
    plugin = tmp_path / "plain.py"
    plugin.write_text("name = 'plain'\ndim = 2\ndescription = 'unit square'\ndef boundary(points):\n    return points\n")
    assert [(p.name, p.faces) for p in geometry_patches(load_geometry(str(plugin)))] == [
        (face, (face,)) for face in ("xi0", "xi1", "eta0", "eta1")
    ]


def test_patch_options_rename_retype_and_merge_faces():
    overrides = parse_patch_options(["zeta0=ends:patch", "zeta1=ends", "eta0=floor:wall"], 3)
    patches = geometry_patches(load_geometry("semicylinder"), overrides)
    assert {p.name: (p.type, p.faces) for p in patches} == {
        "wall": ("wall", ("xi0", "xi1", "eta1")),
        "floor": ("wall", ("eta0",)),
        "ends": ("patch", ("zeta0", "zeta1")),
    }
    with pytest.raises(MeshgenError, match="share its type"):
        geometry_patches(load_geometry("semicylinder"), parse_patch_options(["zeta0=wall"], 3))


@pytest.mark.parametrize(
    "item, message",
    [
        ("zeta0=in", "unknown face 'zeta0' of a 2D"),
        ("xi0=in:inflow", "unknown type 'inflow'"),
        ("xi0", "malformed"),
        ("xi0=a b", "not valid"),
    ],
)
def test_bad_patch_options_are_refused(item, message):
    with pytest.raises(MeshgenError, match=message):
        parse_patch_options([item], 2)


def test_geometries_json_lists_the_patches(run_cli):
    result = run_cli("geometries", "--json")
    listed = {g["name"]: g["patches"] for g in json.loads(result.stdout)}
    assert {p["name"] for p in listed["semicylinder"]} == {"inlet", "outlet", "wall", "symmetry"}
    for name, patches in listed.items():  # every face in exactly one patch
        faces = [face for p in patches for face in p["faces"]]
        if any("." in face for face in faces):  # a block set: block.face, interfaces left out
            continue
        assert sorted(faces) == sorted(cube.face_names(len(faces) // 2)), name


# --- OpenFOAM --------------------------------------------------------------------------------

CHECKMESH_CASES = [
    ("tfi", "semicylinder", (4, 5, 6), True),
    ("elliptic", "semicylinder", (4, 5, 6), False),
    ("neural", "semicylinder", (4, 5, 6), True),
    ("tfi", "topcurve", (5, 3, 4), False),
    ("elliptic", "topcurve", (5, 3, 4), True),
    ("tfi", "canal", (4, 4, 8), True),
    ("elliptic", "canal", (4, 4, 8), False),
    ("tfi", "flower", (4, 4, 5), False),
    ("elliptic", "flower", (4, 4, 5), True),
    ("tfi", "semidisk", (6, 4), True),
    ("elliptic", "bump", (8, 4), False),
]


@needs_openfoam
@pytest.mark.parametrize(
    "method, name, dims, binary", CHECKMESH_CASES, ids=[f"{m}-{n}-{'bin' if b else 'ascii'}" for m, n, _, b in CHECKMESH_CASES]
)
def test_checkmesh_says_mesh_ok_with_the_patches_and_face_counts(tmp_path, method, name, dims, binary):
    geometry, X = make(method, name, dims)
    patches = geometry_patches(geometry)
    case = write_mesh(tmp_path / "case", X, patches=patches, format="openfoam", binary=binary)
    report = check_mesh(case)
    assert report["ok"], report["log"][-3000:]
    assert report["patches"] == expected_face_counts(patches, dims)
    assert report["cells"] == int(np.prod(dims))
    assert read_patches(case) == patches
    # Our reader gives back the node array's points and meshgen's structured connectivity.
    mesh = read_mesh(case)
    np.testing.assert_array_equal(mesh.points[:, : X.shape[-1]], X.reshape(-1, X.shape[-1]))


@needs_openfoam
def test_potential_foam_converges_to_the_uniform_flow_of_a_straight_duct(tmp_path):
    """Potential flow through the semicylinder (slip walls, symmetry plane) from a uniform inlet is
    uniform, U = (0, 0, 1), exactly; on the TFI mesh (an extrusion of the section) the finite-volume
    solution is too, to solver tolerance."""
    geometry, X = make("tfi", "semicylinder", (6, 6, 8))
    case = write_mesh(tmp_path / "duct", X, patches=geometry_patches(geometry), format="openfoam")
    write_potential_flow(case, inlet="inlet", outlet="outlet", velocity=(0, 0, 1))
    result = run_tool("potentialFoam", case)
    assert result.returncode == 0 and "\nEnd" in result.stdout, result.stdout[-3000:]
    residuals = solver_residuals(result.stdout)
    assert residuals and residuals[-1][1] < 1e-8  # the last solve converged
    U = read_vector_field(case / "0" / "U")
    assert U.shape == (6 * 6 * 8, 3)
    np.testing.assert_allclose(U, np.tile([0.0, 0.0, 1.0], (len(U), 1)), atol=1e-6)


@needs_openfoam
def test_potential_foam_runs_on_the_case_as_meshgen_mesh_writes_it(run_cli, tmp_path):
    """The README's route: mesh, checkMesh, a solver; nothing added by hand. The starting fields
    meshgen writes (1 m/s normal to the inlet, p = 0 at the outlet, slip walls) give the uniform
    flow U = (0, 0, 1) of the straight duct."""
    result = run_cli("mesh", "--method", "tfi", "--dims", "4", "4", "6", "--format", "openfoam", "-o", "duct")
    assert result.returncode == 0, result.stderr
    assert check_mesh(tmp_path / "duct")["ok"]
    solved = run_tool("potentialFoam", tmp_path / "duct")
    assert solved.returncode == 0 and "\nEnd" in solved.stdout, solved.stdout[-3000:]
    U = read_vector_field(tmp_path / "duct" / "0" / "U")
    np.testing.assert_allclose(U, np.tile([0.0, 0.0, 1.0], (4 * 4 * 6, 1)), atol=1e-6)
    # Re-meshing keeps the user's set-up: 0/ and system/ are not rewritten.
    mine = "// my settings\n" + (tmp_path / "duct" / "system" / "fvSolution").read_text()
    (tmp_path / "duct" / "system" / "fvSolution").write_text(mine)
    assert run_cli("mesh", "--method", "tfi", "--dims", "3", "3", "3", "--format", "openfoam", "-o", "duct").returncode == 0
    assert (tmp_path / "duct" / "system" / "fvSolution").read_text() == mine
    assert check_mesh(tmp_path / "duct")["patches"]["inlet"] == 9


def test_openfoam_write_is_atomic_and_replaces_an_old_poly_mesh(tmp_path, monkeypatch):
    from meshgen.formats import _openfoam

    geometry = load_geometry("semicylinder")
    case = write_mesh(tmp_path / "case", tfi(geometry, (3, 3, 3)), format="openfoam", patches=geometry_patches(geometry))
    old_points = (case / "constant/polyMesh/points").read_bytes()

    def broken(folder, *args):
        (folder / "points").write_text("partial")
        raise OSError("disk full")

    monkeypatch.setattr(_openfoam, "_write_poly_mesh", broken)
    with pytest.raises(MeshgenError, match="disk full"):
        write_mesh(case, tfi(geometry, (4, 4, 4)), format="openfoam")
    assert (case / "constant/polyMesh/points").read_bytes() == old_points
    assert sorted(p.name for p in (case / "constant").iterdir()) == ["polyMesh"]
    with pytest.raises(MeshgenError):
        write_mesh(tmp_path / "fresh", tfi(geometry, (4, 4, 4)), format="openfoam")
    assert not (tmp_path / "fresh").exists()
    monkeypatch.undo()
    written = write_mesh(case / "constant" / "polyMesh", tfi(geometry, (4, 4, 4)), format="openfoam")
    assert written == case and len(read_mesh(case / "case.foam").points) == 125


def test_left_handed_map_still_gives_outward_normals(tmp_path):
    """Mirroring x makes the map left-handed; the writer must turn the faces round, which the
    face normals' sum over each patch (outward area vector) shows."""
    from meshgen.formats._openfoam import read_boundary, read_list

    X = tfi(load_geometry("topcurve"), (3, 4, 5))
    mirrored = X * np.array([-1.0, 1.0, 1.0])
    for nodes, outward_x in ((X, -1.0), (mirrored, 1.0)):
        case = write_mesh(tmp_path / f"c{outward_x}", nodes, format="openfoam")  # patches xi0 .. zeta1
        folder = case / "constant" / "polyMesh"
        points, faces = read_list(folder / "points", "points"), read_list(folder / "faces", "faces")
        entries = {name: (count, start) for name, _, count, start in read_boundary(folder)}
        count, start = entries["xi0"]
        quads = points[faces[start : start + count]]
        normal = np.cross(quads[:, 2] - quads[:, 0], quads[:, 3] - quads[:, 1]).sum(axis=0)
        assert np.sign(normal[0]) == outward_x  # xi0 is x = 0: outward is -x, mirrored +x


# --- CLI and bad input ------------------------------------------------------------------------


@needs_openfoam
def test_cli_openfoam_route_then_evaluate_reads_the_case(run_cli, tmp_path):
    result = run_cli(
        "mesh",
        "--method",
        "tfi",
        "-g",
        "canal",
        "--dims",
        "3",
        "3",
        "6",
        "--format",
        "openfoam",
        "-o",
        "canal",
        "--patch",
        "zeta0=in",
        "--patch",
        "zeta1=out:patch",
    )
    assert result.returncode == 0, result.stderr
    report = check_mesh(tmp_path / "canal")
    assert report["ok"] and report["patches"] == {"wall": 4 * 3 * 6, "in": 9, "out": 9}
    assert (tmp_path / "canal" / "canal.foam").is_file()
    evaluated = run_cli("evaluate", "canal", "--json", "-")
    assert evaluated.returncode == 0, evaluated.stderr
    report = json.loads(evaluated.stdout)
    expected = quality_report(tfi(load_geometry("canal"), (3, 3, 6)), load_geometry("canal"))
    assert report["cells"] == 54 and report["structured"]
    assert report["metrics"]["min_angle"]["mean"] == pytest.approx(expected["metrics"]["min_angle"]["mean"], rel=1e-12)
    assert report["boundary_deviation"]["max"] < 1e-12


@pytest.mark.parametrize(
    "args, message",
    [
        (["--patch", "nose=x"], "unknown face 'nose'"),
        (["--patch", "zeta0=x:inflow"], "unknown type 'inflow'"),
        (["--patch", "zeta0=in(1)"], "not an OpenFOAM word"),
        (["--patch", "zeta0=frontAndBack", "-g", "semidisk", "--dims", "3", "3"], "frontAndBack"),
    ],
)
def test_bad_patch_input_is_one_line_exit_2_and_writes_nothing(run_cli, tmp_path, args, message):
    dims = [] if "--dims" in args else ["--dims", "3", "3", "3"]
    result = run_cli("mesh", "--method", "tfi", *dims, *args, "--format", "openfoam", "-o", "case")
    assert result.returncode == 2 and message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and "Traceback" not in result.stderr
    assert list(tmp_path.iterdir()) == []


def test_openfoam_target_that_is_not_a_case_is_refused_untouched(run_cli, tmp_path):
    (tmp_path / "photos").mkdir()
    (tmp_path / "photos" / "cat.jpg").write_bytes(b"cat")
    (tmp_path / "notes.txt").write_text("keep")
    for target in ("photos", "notes.txt"):
        result = run_cli("mesh", "--method", "tfi", "--dims", "3", "3", "3", "--format", "openfoam", "-o", target)
        assert result.returncode == 2 and "not a" in result.stderr and len(result.stderr.strip().splitlines()) == 1
    assert [p.name for p in (tmp_path / "photos").iterdir()] == ["cat.jpg"]
    assert (tmp_path / "notes.txt").read_text() == "keep"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt", "photos"]


def test_patch_with_a_format_without_patches_is_refused(run_cli, tmp_path):
    result = run_cli("mesh", "--method", "tfi", "--dims", "3", "3", "3", "--patch", "zeta0=in", "-o", "m.vtu")
    assert result.returncode == 2 and "carry no boundary patches" in result.stderr
    assert list(tmp_path.iterdir()) == []


# --- CGNS boundary conditions ------------------------------------------------------------------


@needs_cgnscheck
@pytest.mark.parametrize("name, dims", [("semicylinder", (4, 3, 5)), ("bump", (5, 3))])
def test_cgns_zone_bc_passes_cgnscheck_and_reads_back(tmp_path, name, dims):
    import h5py

    geometry = load_geometry(name)
    patches = geometry_patches(geometry)
    X = tfi(geometry, dims)
    path = write_mesh(tmp_path / "m.cgns", X, cell_metrics(X), patches=patches)
    result = subprocess.run([cgnscheck, str(path)], capture_output=True, text=True, timeout=60)
    output = result.stdout + result.stderr
    assert result.returncode == 0 and "ERROR" not in output.upper().replace("NO ERRORS", ""), output
    for patch in patches:  # cgnscheck walked every BC and family
        assert f'checking family "{patch.name}"' in output
    assert read_patches(path) == patches
    # The PointRanges, read with h5py alone: each BC covers its face's vertex range.
    node_shape = X.shape[:-1]
    with h5py.File(path, "r") as root:
        zone_bc = root["Base/Zone/ZoneBC"]
        for patch in patches:
            for face_name in patch.faces:
                bc = zone_bc[patch.name if len(patch.faces) == 1 else f"{patch.name}_{face_name}"]
                first, last = bc["PointRange/ data"][()]
                face = cube.face_named(face_name, len(dims))
                plane = node_shape[face.axis] if face.side else 1
                assert first[face.axis] == last[face.axis] == plane
                assert [last[d] - first[d] + 1 for d in face.tangent_axes] == [node_shape[d] for d in face.tangent_axes]
                # FamilySpecified (what VTK's reader loads), the physical type in the family's FamilyBC.
                assert bc[" data"][()].tobytes().decode() == "FamilySpecified"
                kind = root[f"Base/{patch.name}/FamilyBC/ data"][()].tobytes().decode()
                assert kind == {"wall": "BCWall", "symmetry": "BCSymmetryPlane"}.get(
                    patch.type, {"inlet": "BCInflow", "outlet": "BCOutflow"}.get(patch.name)
                )


@needs_openfoam
def test_potential_foam_is_exact_on_the_elliptic_mesh_as_meshgen_mesh_writes_it(run_cli, tmp_path):
    """The smoothed boundary layout through the OpenFOAM writer: uniform flow on the default (smoothed-boundary)
    elliptic mesh is reproduced to solver accuracy; the fixed layout's bent end layers are not."""
    errors = {}
    for layout in ("smoothed", "fixed"):
        case = tmp_path / layout
        result = run_cli(
            "mesh",
            "--method",
            "elliptic",
            "--boundary-layout",
            layout,
            "--dims",
            "6",
            "6",
            "8",
            "--format",
            "openfoam",
            "-o",
            case.name,
        )
        assert result.returncode == 0, result.stderr
        solved = run_tool("potentialFoam", case)
        assert solved.returncode == 0 and "\nEnd" in solved.stdout, solved.stdout[-3000:]
        U = read_vector_field(case / "0" / "U")
        errors[layout] = np.abs(U - [0.0, 0.0, 1.0]).max()
    assert errors["smoothed"] < 1e-3
    assert errors["fixed"] > 1e-2  # the check can fail: the fixed layout does

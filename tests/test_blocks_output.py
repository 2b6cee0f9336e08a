"""Writing block sets: .cgns with a zone per block and 1-to-1 connectivity (our own reader: every
record has its reciprocal and the coordinates match; cgnscheck; VTK's CGNS reader shows every
patch), OpenFOAM (checkMesh, potentialFoam's uniform flow through the pipe), merged .vtu."""

import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from openfoam_helpers import check_mesh, needs_openfoam, read_vector_field, run_tool, solver_residuals, write_potential_flow

from meshgen.errors import FormatError
from meshgen.formats import read_mesh, write_mesh
from meshgen.formats._cgns import read_zones
from meshgen.formats.multiblock import write_blocks
from meshgen.geometry.blocks import load_block_set, tfi_blocks
from meshgen.geometry.patches import geometry_patches
from meshgen.geometry.plugins import load_geometry
from meshgen.methods.tfi import tfi

PIPE_DIMS = (6, 3, 4)


@pytest.fixture(scope="module")
def pipe():
    block_set = load_block_set("pipe", None, PIPE_DIMS)
    return block_set, tfi_blocks(block_set)


@pytest.fixture(scope="module")
def dfg():
    block_set = load_block_set("dfg-cylinder", None, (6, 4))
    return block_set, tfi_blocks(block_set)


def _donor_index(index, transform, begin, begin_donor):
    """CGNS SIDS: Index2 = T (Index1 - Begin1) + Begin2, written out independently of meshgen."""
    matrix = np.zeros((len(transform), len(transform)), dtype=int)
    for column, t in enumerate(transform):
        matrix[abs(t) - 1, column] = np.sign(t)
    return matrix @ (np.asarray(index) - begin) + begin_donor


@pytest.mark.parametrize("case", ["pipe", "dfg"])
def test_cgns_connectivity_is_reciprocal_and_coincident(tmp_path, case, request):
    block_set, Xs = request.getfixturevalue(case)
    path = write_blocks(tmp_path / "m.cgns", block_set, Xs, {"geometry": block_set.name})
    zones = {zone["name"]: zone for zone in read_zones(path)}
    assert list(zones) == list(block_set.names)
    records = 0
    for name, zone in zones.items():
        for link in zone["connections"]:
            records += 1
            donor = zones[link["donor"]]
            begin, end = link["range"]
            begin_donor, end_donor = link["donor_range"]
            assert np.array_equal(_donor_index(end, link["transform"], begin, begin_donor), end_donor)
            # The reciprocal record: in the donor, pointing back, covering the same donor face.
            back = [
                r for r in donor["connections"]
                if r["donor"] == name and {tuple(r["range"].min(axis=0)), tuple(r["range"].max(axis=0))}
                == {tuple(link["donor_range"].min(axis=0)), tuple(link["donor_range"].max(axis=0))}
            ]  # fmt: skip
            assert len(back) == 1, (name, link["name"])
            # Every vertex of the range, mapped by the Transform, has the donor's coordinates.
            axes = [np.arange(b, e + 1) for b, e in zip(begin, end)]
            grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, len(begin))
            mapped = np.array([_donor_index(i, link["transform"], begin, begin_donor) for i in grid])
            here = zone["X"][tuple((grid - 1).T)]
            there = donor["X"][tuple((mapped - 1).T)]
            assert np.array_equal(here, there)
    assert records == 2 * len(block_set.interfaces)


@pytest.mark.skipif(shutil.which("cgnscheck") is None, reason="cgnscheck (CGNS tools) not installed")
@pytest.mark.parametrize("case", ["pipe", "dfg"])
def test_cgnscheck_is_clean(tmp_path, case, request):
    block_set, Xs = request.getfixturevalue(case)
    path = write_blocks(tmp_path / "m.cgns", block_set, Xs, {"geometry": block_set.name})
    result = subprocess.run(["cgnscheck", str(path)], capture_output=True, text=True, timeout=60)
    output = result.stdout + result.stderr
    assert result.returncode == 0, output
    assert "error" not in output.lower() and "warning" not in output.lower(), output
    assert output.count("checking 1to1 connectivity") == 2 * len(block_set.interfaces)


def _vtk_patches(path) -> dict[str, set[str]]:
    """Zone -> names of the patch blocks VTK's (ParaView's) CGNS reader makes."""
    vtk = pytest.importorskip("vtk")
    reader = vtk.vtkCGNSReader()
    reader.SetFileName(str(path))
    reader.UpdateInformation()
    reader.EnableAllBases()
    reader.SetLoadBndPatch(1)
    reader.Update()
    name_key = vtk.vtkCompositeDataSet.NAME()
    base = reader.GetOutput().GetBlock(0)
    found = {}
    for z in range(base.GetNumberOfBlocks()):
        zone = base.GetBlock(z)
        names = [zone.GetMetaData(i).Get(name_key) for i in range(zone.GetNumberOfBlocks())]
        patches = zone.GetBlock(names.index("Patches")) if "Patches" in names else None
        found[base.GetMetaData(z).Get(name_key)] = (
            {patches.GetMetaData(i).Get(name_key) for i in range(patches.GetNumberOfBlocks())} if patches else set()
        )
    return found


def test_vtk_reader_shows_every_patch_of_a_single_block_file(tmp_path):
    geometry = load_geometry("semicylinder")
    patches = geometry_patches(geometry)
    path = write_mesh(tmp_path / "m.cgns", tfi(geometry, (4, 4, 4)), patches=patches)
    found = _vtk_patches(path)
    # One BC per face: a patch on several faces appears as <patch>_<face>.
    expected = {p.name if len(p.faces) == 1 else f"{p.name}_{face}" for p in patches for face in p.faces}
    assert found == {"Zone": expected}


def test_vtk_reader_shows_every_patch_of_each_zone(tmp_path, pipe):
    block_set, Xs = pipe
    found = _vtk_patches(write_blocks(tmp_path / "m.cgns", block_set, Xs))
    assert found == {"core": {"inlet", "outlet"}, **{ring: {"inlet", "outlet", "wall"} for ring in block_set.names[1:]}}


def test_merged_vtu_has_unique_nodes(tmp_path, pipe):
    import meshio

    block_set, Xs = pipe
    mesh = meshio.read(write_blocks(tmp_path / "m.vtu", block_set, Xs))
    n, m, a = PIPE_DIMS
    assert len(mesh.points) == ((n + 1) ** 2 + 4 * m * n) * (a + 1)
    assert len(np.unique(mesh.points, axis=0)) == len(mesh.points)
    assert sum(len(c.data) for c in mesh.cells) == block_set.cells


def test_single_block_formats_refuse_blocks(tmp_path, pipe):
    from meshgen.errors import FormatError

    with pytest.raises(FormatError, match="does not take multi-block meshes"):
        write_blocks(tmp_path / "m.vts", *pipe)
    assert not (tmp_path / "m.vts").exists()


def _pipe_patch_faces(n, m, a):
    """Boundary faces of the pipe's O-grid by patch: each end a core face and four wall-block faces."""
    end = n * n + 4 * n * m
    return {"inlet": end, "outlet": end, "wall": 4 * n * a}


def test_su2_of_a_block_set_is_merged_with_outward_markers(tmp_path, pipe):
    import meshio

    block_set, Xs = pipe
    path = write_blocks(tmp_path / "m.su2", block_set, Xs)
    text = path.read_text()
    n, m, a = PIPE_DIMS
    mesh = meshio.read(path, file_format="su2")
    assert len(mesh.points) == ((n + 1) ** 2 + 4 * m * n) * (a + 1)  # interface nodes written once
    assert sum(len(c.data) for c in mesh.cells if c.type == "hexahedron") == block_set.cells
    points = np.asarray(mesh.points)
    markers = re.findall(r"MARKER_TAG= (\S+)\nMARKER_ELEMS= (\d+)\n((?:9 .*\n?)*)", text)
    assert {name: int(count) for name, count, _ in markers} == _pipe_patch_faces(n, m, a)
    length = block_set.values["length"]
    for name, count, body in markers:
        quads = points[np.array(body.split(), dtype=int).reshape(int(count), 5)[:, 1:]]
        normals = np.cross(quads[:, 2] - quads[:, 0], quads[:, 3] - quads[:, 1])
        centres = quads.mean(axis=1)
        # Outward: the wall's normal points away from the axis, the inlet's (z = 0) down, the outlet's up.
        outward = {"wall": centres * [1, 1, 0], "inlet": [0, 0, -1], "outlet": [0, 0, 1]}[name]
        assert np.all(np.sum(normals * outward, axis=1) > 0), name
        if name != "wall":
            np.testing.assert_allclose(centres[:, 2], 0.0 if name == "inlet" else length, atol=1e-12)


@pytest.mark.skipif(shutil.which("gmsh") is None, reason="gmsh not installed (Debian package gmsh)")
@pytest.mark.parametrize("case", ["pipe", "dfg"])
def test_gmsh_reads_the_merged_msh_of_a_block_set(tmp_path, request, case):
    """Gmsh reads the .msh and writes it again as MSH 2.2: the groups it understood hold the
    patches' faces (counted from the block faces) and the cells."""
    block_set, Xs = request.getfixturevalue(case)
    path = write_blocks(tmp_path / "m.msh", block_set, Xs)
    result = subprocess.run(
        [shutil.which("gmsh"), str(path), "-0", "-o", str(tmp_path / "out.msh"), "-format", "msh22"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert result.returncode == 0 and "Error" not in result.stdout + result.stderr, result.stdout + result.stderr
    out = (tmp_path / "out.msh").read_text()
    names = {int(tag): name for _, tag, name in re.findall(r'^(\d) (\d+) "([^"]+)"$', out, re.M)}
    counts = {}
    for line in out.split("$Elements\n", 1)[1].split("$EndElements", 1)[0].split("\n")[1:-1]:
        group = names[int(line.split()[3])]
        counts[group] = counts.get(group, 0) + 1
    expected = {"domain": block_set.cells}
    for (block, face), (name, _) in block_set.patches.items():
        shape = [len(t) - 1 for t in block_set.coords[block]]
        axis = {"xi": 0, "eta": 1, "zeta": 2}[face[:-1]]
        expected[name] = expected.get(name, 0) + int(np.prod([s for i, s in enumerate(shape) if i != axis]))
    assert counts == expected


@needs_openfoam
@pytest.mark.parametrize("method", ["tfi", "elliptic", "neural"])
def test_openfoam_pipe_checkmesh_and_uniform_potential_flow(tmp_path, method):
    """The pipe's mesh is an extrusion of its section (the elliptic one too: its inlet and outlet
    nodes slide in their planes; the neural one by construction: a section model (tests/data),
    extruded): the finite-volume potential flow from a uniform inlet is uniform to solver accuracy."""
    from meshgen.methods.elliptic import elliptic_blocks
    from meshgen.neural.checkpoint import load_checkpoint
    from meshgen.neural.inference import neural_blocks

    length = 4.0 if method == "neural" else 1.0  # the stored model's pipe
    block_set = load_block_set("pipe", {"length": length}, (6, 3, 4))
    if method == "neural":
        model = load_checkpoint(Path(__file__).resolve().parent / "data" / "pipe-section-model.pt")["model"]
        Xs = neural_blocks(block_set, model)[0]
    else:
        Xs = tfi_blocks(block_set) if method == "tfi" else elliptic_blocks(block_set)[0]
    case = write_blocks(tmp_path / "pipe", block_set, Xs, format_name="openfoam")
    report = check_mesh(case)
    assert report["ok"], report["log"][-2000:]
    assert report["cells"] == block_set.cells
    assert set(report["patches"]) == {"inlet", "outlet", "wall"}
    write_potential_flow(case, inlet="inlet", outlet="outlet", velocity=(0, 0, 1))
    result = run_tool("potentialFoam", case)
    assert result.returncode == 0 and "\nEnd" in result.stdout, result.stdout[-3000:]
    assert solver_residuals(result.stdout)[-1][1] < 1e-8
    U = read_vector_field(case / "0" / "U")
    assert U.shape == (block_set.cells, 3)
    assert np.max(np.abs(U - [0.0, 0.0, 1.0])) < 1e-6


@needs_openfoam
def test_openfoam_dfg_is_extruded_and_valid(tmp_path, dfg):
    block_set, Xs = dfg
    case = write_blocks(tmp_path / "dfg", block_set, Xs, format_name="openfoam")
    report = check_mesh(case)
    assert report["ok"], report["log"][-2000:]
    assert report["cells"] == block_set.cells
    assert set(report["patches"]) == {"inlet", "outlet", "walls", "cylinder", "frontAndBack"}
    assert report["patches"]["frontAndBack"] == 2 * block_set.cells


def test_vtm_lists_a_vts_per_block(tmp_path, pipe):
    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import vtk_to_numpy

    block_set, Xs = pipe
    path = write_blocks(tmp_path / "pipe.vtm", block_set, Xs)
    reader = vtk.vtkXMLMultiBlockDataReader()
    reader.SetFileName(str(path))
    reader.Update()
    output = reader.GetOutput()
    names = [output.GetMetaData(i).Get(vtk.vtkCompositeDataSet.NAME()) for i in range(output.GetNumberOfBlocks())]
    assert names == list(block_set.names)
    for index, X in enumerate(Xs):
        points = vtk_to_numpy(output.GetBlock(index).GetPoints().GetData())
        # VTK's structured points run i fastest: the node array transposed.
        np.testing.assert_array_equal(points, np.transpose(X, (2, 1, 0, 3)).reshape(-1, 3))


@needs_openfoam
def test_openfoam_block_set_case_runs_potential_foam_from_its_own_fields(tmp_path):
    """A block set's case is as runnable as a single block's: ``meshgen mesh -g pipe --format
    openfoam`` writes ``0/U`` and ``0/p`` from the patches' types (inlet, outlet, wall), and
    potentialFoam runs on them with no file of ours: the pipe is an extrusion of its section, so
    the flow from the inlet's uniform 1 m/s (normal, into the domain) is uniform along +z."""
    case = tmp_path / "pipe"
    result = subprocess.run(
        ["meshgen", "mesh", "-g", "pipe", "--dims", "6", "3", "4", "--method", "tfi", "--format", "openfoam", "-o", str(case)],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0, result.stderr
    assert sorted(p.name for p in (case / "0").iterdir()) == ["U", "p"]
    record = json.loads((case / "constant" / "polyMesh" / "meshgen.json").read_text())
    assert record["block_set"] == "pipe" and "node_shape" not in record
    assert set(record["fields"]) == {"U", "p"}
    solved = run_tool("potentialFoam", case)
    assert solved.returncode == 0 and "\nEnd" in solved.stdout, solved.stdout[-3000:]
    U = read_vector_field(case / "0" / "U")
    assert U.shape == (load_block_set("pipe", None, (6, 3, 4)).cells, 3)
    assert np.max(np.abs(U - [0.0, 0.0, 1.0])) < 1e-5
    # Re-meshing follows the single-block rules (meshgen.formats._foam_fields): the solved fields
    # are meshgen's and are rewritten for the new mesh; a user's edit is kept, with a warning.
    result = subprocess.run(
        ["meshgen", "mesh", "-g", "pipe", "--dims", "6", "3", "4", "--method", "tfi", "--format", "openfoam", "-o", str(case)],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0 and "kept" not in result.stderr, result.stderr
    assert "internalField   uniform (0 0 0)" in (case / "0" / "U").read_text()
    (case / "0" / "p").write_text((case / "0" / "p").read_text().replace("uniform 0;", "uniform 5;"))
    result = subprocess.run(
        ["meshgen", "mesh", "-g", "pipe", "--dims", "6", "3", "4", "--method", "tfi", "--format", "openfoam", "-o", str(case)],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 0 and "kept 0/p" in result.stderr, result.stderr
    with pytest.raises(FormatError, match="block set 'pipe'"):
        read_mesh(case)


@needs_openfoam
def test_openfoam_2d_block_set_case_has_fields_with_empty_front_and_back(tmp_path, dfg):
    block_set, Xs = dfg
    case = write_blocks(tmp_path / "dfg", block_set, Xs, format_name="openfoam")
    text = (case / "0" / "p").read_text()
    for name, entry in (("inlet", "zeroGradient"), ("outlet", "fixedValue"), ("frontAndBack", "empty")):
        assert re.search(rf"{name}\s*\{{\s*type {entry};", text), text
    solved = run_tool("potentialFoam", case)
    assert solved.returncode == 0 and "\nEnd" in solved.stdout, solved.stdout[-3000:]

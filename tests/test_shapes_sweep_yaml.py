"""A YAML geometry file over a swept solid (meshgen.geometry.shapes.sweep_yaml): the sweep's block
set with the file's patch names and types, the same nodes as the bare file; ``caps`` choosing the
pair (and so the sweep's direction) through the cap search's own checks; what is refused (one
line, exit status 2, nothing written); the module cache following edits of either file; the
dispatch (topology files, six-faced solids and ``patches`` files as before) and the trust rules
for a recorded path."""

import os
import re

import numpy as np
import pytest
from shape_helpers import write_ascii_stl, write_sweep_solid

import meshgen
from meshgen.geometry import cube
from meshgen.geometry.blocks import block_spec
from meshgen.geometry.shapes.sweep_yaml import is_sweep_geometry

gmsh = pytest.importorskip("gmsh", reason="CAD files need the gmsh Python package (pip install gmsh)")

CYLINDER_DIMS = (4, 2, 3)


@pytest.fixture(scope="module")
def solids(tmp_path_factory):
    folder = tmp_path_factory.mktemp("sweep-yaml")
    for kind in ("cylinder", "pentagon"):
        write_sweep_solid(kind, folder / f"{kind}.step")
    if not gmsh.isInitialized():
        gmsh.initialize(readConfigFiles=False, interruptible=False)
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.model.add("box")
    gmsh.model.occ.addBox(0, 0, 0, 1, 2, 3)
    gmsh.model.occ.synchronize()
    from meshgen.geometry.shapes.cad import quiet_stdout

    with quiet_stdout():
        gmsh.write(str(folder / "box.step"))
    gmsh.model.remove()
    return folder


def write(folder, name, text):
    path = folder / name
    path.write_text(text)
    return path


def patch_nodes(mesh) -> dict:
    """Patch name -> (N, 3) the nodes of every block face on it."""
    found = {}
    for (block, face_name), (name, _) in mesh.geometry.patches.items():
        face = cube.face_named(face_name, 3)
        found.setdefault(name, []).append(np.take(mesh.blocks[block], 0 if face.side == 0 else -1, axis=face.axis).reshape(-1, 3))
    return {name: np.concatenate(parts) for name, parts in found.items()}


def boundary_file(case) -> dict:
    """Patch name -> type, from an OpenFOAM case's constant/polyMesh/boundary."""
    text = (case / "constant" / "polyMesh" / "boundary").read_text()
    return dict(re.findall(r"^\s+(\S+)\s*\{\s*type\s+(\w+);", text, flags=re.MULTILINE))


def refused(run_cli, folder, geometry, *words):
    before = sorted(p.name for p in folder.iterdir())
    result = run_cli("mesh", "-g", geometry, "--method", "tfi", "--dims", 2, 1, 2, "-o", "m.vtu", cwd=folder)
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.returncode == 2, result.stderr
    assert len(lines) == 1 and lines[0].startswith("Error: ") and "Traceback" not in result.stderr, result.stderr
    for word in words:
        assert word in lines[0], lines[0]
    assert sorted(p.name for p in folder.iterdir()) == before
    return lines[0]


@pytest.mark.parametrize("method", ["tfi", "elliptic"])
def test_a_yaml_file_over_a_cylinder_renames_and_types_its_patches(solids, tmp_path, run_cli, method):
    """The patches written carry the new names and types (the OpenFOAM boundary file), the nodes
    are the bare .step's, bit for bit, and the run says the renames."""
    text = "surface: {}\nrename: {{face1: side, face2: inlet, face3: outlet}}\ntypes: {{side: symmetry}}\n"
    yaml = write(tmp_path, "part.yaml", text.format(solids / "cylinder.step"))
    assert is_sweep_geometry(yaml) and block_spec(str(yaml)) == str(yaml)
    result = run_cli(
        "mesh", "-g", "part.yaml", "--method", method, "--dims", *CYLINDER_DIMS, "--format", "openfoam", "-o", "case"
    )
    assert result.returncode == 0, result.stderr
    assert boundary_file(tmp_path / "case") == {"side": "symmetry", "inlet": "patch", "outlet": "patch"}
    said = [line for line in result.stdout.splitlines() if line.startswith("part.yaml:")]
    assert "caps face2 as inlet (zeta0) and face3 as outlet (zeta1):" in said[0] and "named in" not in said[0]
    assert "patches face1 as side (symmetry), face2 as inlet (patch), face3 as outlet (patch)" in said[2]
    named = meshgen.mesh(str(yaml), CYLINDER_DIMS, method=method)
    bare = meshgen.mesh(str(solids / "cylinder.step"), CYLINDER_DIMS, method=method)
    assert named.geometry.names == bare.geometry.names
    assert all(np.array_equal(a, b) for a, b in zip(named.blocks, bare.blocks))
    renamed = {"face1": "side", "face2": "inlet", "face3": "outlet"}
    assert {key: name for key, (name, _) in named.geometry.patches.items()} == {
        key: renamed[name] for key, (name, _) in bare.geometry.patches.items()
    }


def test_caps_choose_the_sweep_direction(solids, tmp_path):
    """``caps: [face3, face2]`` turns the cylinder's sweep round: face3 on every block's zeta0, its
    nodes on face3's plane (where the bare file's face3 nodes lie), face2's on zeta1."""
    bare = meshgen.mesh(str(solids / "cylinder.step"), CYLINDER_DIMS, method="tfi")
    assert all(bare.geometry.patches[block, "zeta0"][0] == "face2" for block in range(len(bare.blocks)))
    height = {name: nodes[:, 2] for name, nodes in patch_nodes(bare).items() if name != "face1"}
    assert all(np.ptp(z) < 1e-12 for z in height.values()) and abs(height["face2"][0] - height["face3"][0]) == 2.0
    yaml = write(tmp_path, "turned.yaml", f"surface: {solids / 'cylinder.step'}\ncaps: [face3, face2]\n")
    turned = meshgen.mesh(str(yaml), CYLINDER_DIMS, method="tfi")
    for block, X in enumerate(turned.blocks):
        assert turned.geometry.patches[block, "zeta0"][0] == "face3"
        assert turned.geometry.patches[block, "zeta1"][0] == "face2"
        assert np.abs(X[:, :, 0, 2] - height["face3"][0]).max() < 1e-12
        assert np.abs(X[:, :, -1, 2] - height["face2"][0]).max() < 1e-12
    assert any("caps face3 (zeta0) and face2 (zeta1), named in turned.yaml" in line for line in turned.notes)
    report = turned.report()
    assert report["inverted"]["count"] == 0 and report["metrics"]["scaled_jacobian"]["min"] >= 0.4


def test_caps_naming_the_pair_the_search_finds_mesh_as_the_bare_file(solids, tmp_path):
    """Naming the caps the search finds anyway gives the bare file's nodes, and the run says they were named."""
    yaml = write(tmp_path, "same.yaml", f"surface: {solids / 'pentagon.step'}\ncaps: [face6, face7]\n")
    named = meshgen.mesh(str(yaml), (2, 1, 2), method="tfi")
    bare = meshgen.mesh(str(solids / "pentagon.step"), (2, 1, 2), method="tfi")
    assert all(np.array_equal(a, b) for a, b in zip(named.blocks, bare.blocks))
    assert any("named in same.yaml" in line for line in named.notes)


ROWS = {
    "touching": ("pentagon", "caps: [face2, face3]", ("'caps' face2 and face3 are not the caps of a sweep", "they touch")),
    "not-touching-both": ("pentagon", "caps: [face1, face3]", ("not the caps of a sweep", "face4 does not touch both")),
    "not-planar": ("cylinder", "caps: [face1, face2]", ("not the caps of a sweep", "face1 is not planar")),
    "unknown-cap": ("cylinder", "caps: [face2, inlet]", ("'caps' names no patch 'inlet'", "(patches: face1, face2, face3)")),
    "one-cap": ("cylinder", "caps: [face2]", ("'caps' must be two different patch names",)),
    "same-cap": ("cylinder", "caps: [face2, face2]", ("'caps' must be two different patch names",)),
    "faces": (
        "cylinder",
        "faces: {xi0: face1, xi1: face1, eta0: face1, eta1: face1, zeta0: face2, zeta1: face3}",
        ("'faces' assigns the six faces of one block", "is a sweep", "'caps'"),
    ),
    "corners": ("cylinder", "corners: " + str([[0, 0, 0]] * 8), ("'corners' assigns the six faces of one block",)),
    "unknown-rename": (
        "cylinder",
        "rename: {face9: inlet}",
        ("'rename' names no patch 'face9'", "(patches: face1, face2, face3)"),
    ),
    "unknown-type": ("cylinder", "types: {face2: inflow}", ("patch 'face2': unknown type 'inflow'", "wall, patch")),
    "type-of-nothing": ("cylinder", "types: {inlet: patch}", ("'types' names no patch 'inlet'",)),
    "bad-name": ("cylinder", "rename: {face2: 'in let'}", ("patch name 'in let' is not valid",)),
    "merged-types": (
        "cylinder",
        "rename: {face2: ends, face3: ends}\ntypes: {face2: patch, face3: wall}",
        ("patch 'ends'", "both patch and wall"),
    ),
    "angle-on-cad": ("cylinder", "feature_angle: 30", ("'feature_angle' splits a triangulated surface",)),
    "caps-on-a-box": ("box", "caps: [face1, face2]", ("is one block of six four-cornered faces", "'faces'")),
}


@pytest.mark.parametrize("row", list(ROWS))
def test_bad_yaml_over_a_sweep_is_one_line(solids, tmp_path, run_cli, row):
    kind, text, words = ROWS[row]
    write(tmp_path, "bad.yaml", f"surface: {solids / f'{kind}.step'}\n{text}\n")
    refused(run_cli, tmp_path, "bad.yaml", *words)


def cylinder_stl(path, sections=64, named=True):
    """A trimesh cylinder (radius 0.5, length 2 along z): an ASCII STL of three named solids (side,
    bottom, top) or, ``named`` false, trimesh's binary STL."""
    trimesh = pytest.importorskip("trimesh", reason="STL files need trimesh")
    mesh = trimesh.creation.cylinder(radius=0.5, height=2.0, sections=sections)
    if not named:
        mesh.export(path)
        return path
    vertices, triangles = np.asarray(mesh.vertices), np.asarray(mesh.faces)
    normals = np.asarray(mesh.face_normals)
    labels = np.where(normals[:, 2] < -0.9, 1, np.where(normals[:, 2] > 0.9, 2, 0))
    return write_ascii_stl(path, vertices, triangles, labels, names=("side", "bottom", "top"))


def test_a_named_stl_sweep_through_yaml(tmp_path, run_cli):
    """A multi-solid ASCII STL cylinder: the solids are the patches, renamed and typed by the YAML
    file, the nodes the bare file's; ``caps`` turns it round."""
    cylinder_stl(tmp_path / "tube.stl")
    write(tmp_path, "tube.yaml", "surface: tube.stl\nrename: {bottom: inlet, top: outlet, side: pipe}\n")
    result = run_cli("mesh", "-g", "tube.yaml", "--method", "tfi", "--dims", 4, 2, 3, "--format", "openfoam", "-o", "case")
    assert result.returncode == 0, result.stderr
    assert boundary_file(tmp_path / "case") == {"pipe": "wall", "inlet": "patch", "outlet": "patch"}
    named = meshgen.mesh(str(tmp_path / "tube.yaml"), (4, 2, 3), method="tfi")
    bare = meshgen.mesh(str(tmp_path / "tube.stl"), (4, 2, 3), method="tfi")
    assert all(np.array_equal(a, b) for a, b in zip(named.blocks, bare.blocks))
    first = bare.geometry.patches[0, "zeta0"][0]
    other = {"bottom": "top", "top": "bottom"}[first]
    write(tmp_path, "turned.yaml", f"surface: tube.stl\ncaps: [{other}, {first}]\n")
    turned = meshgen.mesh(str(tmp_path / "turned.yaml"), (4, 2, 3), method="tfi")
    assert {turned.geometry.patches[b, "zeta0"][0] for b in range(len(turned.blocks))} == {other}
    ends = patch_nodes(bare)
    assert np.abs(turned.blocks[0][:, :, 0, 2] - ends[other][0, 2]).max() < 1e-6
    write(tmp_path, "side.yaml", "surface: tube.stl\ncaps: [side, top]\n")
    refused(run_cli, tmp_path, "side.yaml", "'caps' side and top are not the caps of a sweep", "side is not planar")


def test_a_binary_stl_prism_through_yaml_and_its_feature_angle(tmp_path):
    """trimesh's hexagonal prism, binary: split at its sharp edges into 8 patches (patch1.., renamed
    here), or with ``feature_angle: 70`` (its sides meet at 60 degrees) into 3: one side patch."""
    cylinder_stl(tmp_path / "hex.stl", sections=6, named=False)
    bare = meshgen.mesh(str(tmp_path / "hex.stl"), (2, 1, 2), method="tfi")
    first = bare.geometry.patches[0, "zeta0"][0]
    write(tmp_path, "hex.yaml", f"surface: hex.stl\nrename: {{{first}: inlet}}\n")
    named = meshgen.mesh(str(tmp_path / "hex.yaml"), (2, 1, 2), method="tfi")
    assert all(np.array_equal(a, b) for a, b in zip(named.blocks, bare.blocks))
    assert len(patch_nodes(named)) == 8 and "inlet" in patch_nodes(named) and first not in patch_nodes(named)
    assert named.geometry.patches[0, "zeta0"] == ("inlet", "patch")
    write(tmp_path, "merged.yaml", "surface: hex.stl\nfeature_angle: 70\n")
    merged = meshgen.mesh(str(tmp_path / "merged.yaml"), (2, 1, 2), method="tfi")
    assert len(merged.blocks) == 6 and len(patch_nodes(merged)) == 3


def test_editing_either_file_takes_effect_in_the_same_process(solids, tmp_path):
    surface = tmp_path / "solid.step"
    surface.write_bytes((solids / "cylinder.step").read_bytes())
    yaml = write(tmp_path, "part.yaml", "surface: solid.step\nrename: {face2: inlet}\n")
    first = meshgen.mesh(str(yaml), (2, 1, 2), method="tfi")
    assert "inlet" in patch_nodes(first)
    yaml.write_text("surface: solid.step\nrename: {face2: intake}\n")
    os.utime(yaml, ns=(yaml.stat().st_atime_ns, yaml.stat().st_mtime_ns + 10**9))
    second = meshgen.mesh(str(yaml), (2, 1, 2), method="tfi")
    assert "intake" in patch_nodes(second) and "inlet" not in patch_nodes(second)
    assert "core" in second.geometry.names
    surface.write_bytes((solids / "pentagon.step").read_bytes())  # the YAML file as it was
    os.utime(surface, ns=(surface.stat().st_atime_ns, surface.stat().st_mtime_ns + 10**9))
    third = meshgen.mesh(str(yaml), (2, 1, 2), method="tfi")
    assert third.geometry.names == tuple(f"quad{k}" for k in range(5))
    assert len(patch_nodes(third)) == 7 and "intake" in patch_nodes(third)


def test_what_stays_as_it_was(solids, tmp_path):
    """A geometry file of a six-faced solid, a ``patches`` file and a topology file are no
    sweep's; the box's YAML file meshes its one block as before."""
    box = write(tmp_path, "box.yaml", f"surface: {solids / 'box.step'}\nrename: {{face1: inlet}}\n")
    assert not is_sweep_geometry(box) and block_spec(str(box)) is None
    X = meshgen.mesh(str(box), (2, 3, 4), method="tfi").X
    assert X.shape == (3, 4, 5, 3)
    listed = write(tmp_path, "listed.yaml", "patches:\n  inlet: a.stl\n")
    topology = write(tmp_path, "topology.yaml", "vertices: []\nblocks: []\n")
    missing = write(tmp_path, "missing.yaml", "surface: nowhere.step\n")
    assert not any(is_sweep_geometry(p) for p in (listed, topology, missing, tmp_path / "absent.yaml"))


def test_a_recorded_yaml_path_loads_only_when_given(solids, tmp_path, monkeypatch):
    """A file recording the YAML path (a checkpoint, a mesh's metadata) loads it only once the user
    named that YAML file in this process, as for the bare file; naming the surface it names, or
    the YAML file, trusts nothing else."""
    from meshgen.geometry.plugins import load_geometry, load_recorded_geometry
    from meshgen.run import trust

    monkeypatch.setattr(trust, "_GIVEN_PLUGIN_FILES", set())
    yaml = write(tmp_path, "part.yaml", f"surface: {solids / 'cylinder.step'}\nrename: {{face2: inlet}}\n")
    with pytest.raises(trust.UntrustedGeometry, match="pass -g PATH"):
        load_recorded_geometry(str(yaml), check=False, where="the checkpoint")
    load_geometry(str(solids / "cylinder.step"), check=False)  # the surface named: not the YAML file
    with pytest.raises(trust.UntrustedGeometry):
        load_recorded_geometry(str(yaml), check=False, where="the checkpoint")
    monkeypatch.setattr(trust, "_GIVEN_PLUGIN_FILES", set())
    geometry = load_geometry(str(yaml), check=False)
    assert geometry.source == str(yaml)
    assert load_recorded_geometry(str(yaml), check=False, where="the checkpoint").source == str(yaml)
    with pytest.raises(trust.UntrustedGeometry):
        load_recorded_geometry(str(solids / "cylinder.step"), check=False, where="the checkpoint")


EVIL_PLUGIN = """
from pathlib import Path
Path({marker!r}).write_text("imported")
name = "evil"
dim = 3
description = "writes a file when imported"
def boundary(points):
    return points
"""


@pytest.mark.slow
def test_training_on_the_yaml_file_and_a_checkpoint_naming_a_file(solids, tmp_path, run_cli, monkeypatch):
    """``meshgen train -g part.yaml`` trains the sweep's networks (the hint to mesh says -g
    part.yaml); its checkpoint meshes with -g part.yaml, the renamed patches written. Without -g,
    in a process where the user named no file, the checkpoint's recorded path is refused in one
    line, as is a block-set checkpoint whose recorded spec is a plugin file (never imported)."""
    torch = pytest.importorskip("torch")
    from meshgen.run import trust

    write(tmp_path, "part.yaml", f"surface: {solids / 'cylinder.step'}\nrename: {{face2: inlet, face3: outlet}}\n")
    result = run_cli("train", "-g", "part.yaml", "--out", "run", "-q", "--steps", 2, "--set", "pretrain.steps=2")
    assert result.returncode == 0, result.stderr
    assert "Mesh with: meshgen mesh -g part.yaml --method neural --checkpoint run/checkpoint.pt" in result.stdout
    meshed = run_cli(
        "mesh", "-g", "part.yaml", "--method", "neural", "--checkpoint", "run/checkpoint.pt", "--dims", 4, 2, 3,
        "--format", "openfoam", "-o", "case",
    )  # fmt: skip
    assert meshed.returncode == 0, meshed.stderr
    assert boundary_file(tmp_path / "case") == {"face1": "wall", "inlet": "patch", "outlet": "patch"}
    monkeypatch.setattr(trust, "_GIVEN_PLUGIN_FILES", set())  # a fresh process: the user named nothing yet
    (tmp_path / "evil.py").write_text(EVIL_PLUGIN.format(marker=str(tmp_path / "imported")))
    checkpoint = torch.load(tmp_path / "run" / "checkpoint.pt", weights_only=False)
    checkpoint["geometry"]["spec"] = str(tmp_path / "evil.py")
    torch.save(checkpoint, tmp_path / "hostile.pt")
    for name, words in (("run/checkpoint.pt", "part.yaml"), ("hostile.pt", "evil.py")):
        line = refused_checkpoint(run_cli, tmp_path, name)
        assert words in line and "pass -g PATH" in line
    assert not (tmp_path / "imported").exists()


def refused_checkpoint(run_cli, folder, checkpoint) -> str:
    before = sorted(p.name for p in folder.iterdir())
    result = run_cli("mesh", "--method", "neural", "--checkpoint", checkpoint, "--dims", 4, 2, 3, "-o", "n.vtu")
    lines = [line for line in result.stderr.splitlines() if line.strip()]
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert sorted(p.name for p in folder.iterdir()) == before
    return lines[0]

"""Cyclic patch pairs of topology files (``meshgen.geometry.cyclic``): the paired sides' nodes after
the elliptic solve, the OpenFOAM faces in matching order (checkMesh's coupled-point check), and the
one-line errors of pairs that do not match or are not pairs."""

import re
from pathlib import Path

import numpy as np
import pytest
from openfoam_helpers import check_mesh, missing_reason

from meshgen.errors import GeometryError
from meshgen.geometry.blocks import load_block_set, tfi_blocks
from meshgen.methods.elliptic import elliptic_blocks

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "topologies" / "periodic-channel-2d.yaml"
BOX = """vertices: {a: [0, 0, 0], b: [1, 0, 0], c: [1, 1, 0], d: [0, 1, 0], e: [0, 0, 1], f: [1, 0, 1], g: [1, 1, 1],
  h: [0, 1, 1], b2: [2, 0, 0], c2: [2, 1, 0], f2: [2, 0, 1], g2: [2, 1, 1]}
blocks: [[a, b, c, d, e, f, g, h], [b, b2, c2, c, f, f2, g2, g]]
edges: [{arc: [a, b], through: [0.5, 0.1, 0]}, {arc: [e, f], through: [0.5, 0.1, 1]}]
cells: {size: 0.125}
patches:
  left: {type: cyclic, neighbour: right, faces: [[a, d, h, e]]}
  right: {type: cyclic, neighbour: left, faces: [[b2, c2, g2, f2]]}
  front: {type: cyclic, neighbour: back, faces: [[a, b, c, d], [b, b2, c2, c]]}
  back: {type: cyclic, neighbour: front, faces: [[e, f, g, h], [f, f2, g2, g]]}
"""


def example_text() -> str:
    return EXAMPLE.read_text()


def test_paired_sides_match_to_round_off_after_the_elliptic_solve():
    blocks = load_block_set(str(EXAMPLE), None, (1, 1))
    assert blocks.cyclic == (("inlet", "outlet", (2.0, 0.0)),)
    start = tfi_blocks(blocks)
    Xs, info = elliptic_blocks(blocks)
    bump, flat = Xs[blocks.names.index("bump")], Xs[blocks.names.index("flat")]
    inlet, outlet = bump[0], flat[-1]  # xi0 of the bump block, xi1 of the flat one: both along eta
    assert inlet.shape == outlet.shape
    np.testing.assert_allclose(outlet - inlet, np.broadcast_to([2.0, 0.0], inlet.shape), rtol=0, atol=1e-13)
    moved = max(float(np.abs(X - X0).max()) for X, X0 in zip(Xs, start))
    assert moved > 1e-3  # the solve did move the mesh: the match is not the TFI's by default
    walls = np.abs(bump[1:-1, -1, 0] - start[0][1:-1, -1, 0]).max()
    assert walls > 1e-6  # the flat ceiling's nodes slid, the cyclic ones stayed


def read_list(path: Path, width: int) -> np.ndarray:
    """The rows of an ASCII polyMesh list (points or 4-node faces) as an array (n, width)."""
    text = path.read_text()
    body = text[text.index("(", text.index("}", text.index("FoamFile")) + 1) + 1 : text.rindex(")")]
    rows = re.findall(r"\(([^()]*)\)", body)
    return np.array([row.split() for row in rows], dtype=float).reshape(-1, width)


def boundary_entries(case: Path) -> dict:
    text = (case / "constant" / "polyMesh" / "boundary").read_text()
    text = text[text.find("}", text.find("FoamFile")) + 1 :]
    return {name: dict(re.findall(r"(\w+)\s+([^;]*);", body)) for name, body in re.findall(r"(\S+)\s*\{([^}]*)\}", text)}


def paired_faces(case: Path, a: str, b: str):
    """(points (F, 4, 3) of patch a's faces, those of b's, b's separationVector, a's)."""
    points = read_list(case / "constant" / "polyMesh" / "points", 3)
    faces = read_list(case / "constant" / "polyMesh" / "faces", 4).astype(int)
    entries = boundary_entries(case)
    assert entries[a]["neighbourPatch"] == b and entries[b]["neighbourPatch"] == a
    assert entries[a]["transform"] == entries[b]["transform"] == "translational"
    sides = []
    for name in (a, b):
        start, count = int(entries[name]["startFace"]), int(entries[name]["nFaces"])
        sides.append(points[faces[start : start + count]])
    vectors = [np.array(entries[name]["separationVector"].strip("()").split(), dtype=float) for name in (a, b)]
    return sides[0], sides[1], vectors[0], vectors[1]


def check_face_order(first, second, separation):
    """The i-th face of the second side is the i-th of the first translated, its first vertex the
    first's, its others in reverse (opposite normals): vertex k of b is vertex -k of a, moved."""
    assert first.shape == second.shape and len(first) > 0
    reverse = first[:, [0, 3, 2, 1]] + separation
    np.testing.assert_allclose(second, reverse, rtol=0, atol=1e-12)


def test_openfoam_case_pairs_faces_in_order_and_checkmesh_accepts_it(run_cli, tmp_path):
    result = run_cli("mesh", "-g", str(EXAMPLE), "--method", "elliptic", "--format", "openfoam", "-o", "case")
    assert result.returncode == 0, result.stderr
    inlet, outlet, forward, backward = paired_faces(tmp_path / "case", "inlet", "outlet")
    np.testing.assert_array_equal(forward, [2, 0, 0])
    np.testing.assert_array_equal(backward, [-2, 0, 0])
    check_face_order(inlet, outlet, forward)
    assert np.ptp(inlet[..., 2]) > 0  # the extruded faces: quads spanning the layer
    if missing_reason() is not None:
        pytest.skip(missing_reason())
    report = check_mesh(tmp_path / "case")
    assert report["ok"], report["log"][-2000:]
    assert "Coupled point location match" in report["log"]
    assert report["patches"]["inlet"] == report["patches"]["outlet"] == len(inlet)


def test_3d_box_with_two_pairs_one_over_two_block_faces(run_cli, tmp_path):
    (tmp_path / "box.yaml").write_text(BOX)
    result = run_cli("mesh", "-g", "box.yaml", "--method", "elliptic", "--format", "openfoam", "-o", "case")
    assert result.returncode == 0, result.stderr
    for a, b, separation in (("left", "right", [2, 0, 0]), ("front", "back", [0, 0, 1])):
        first, second, forward, _ = paired_faces(tmp_path / "case", a, b)
        np.testing.assert_array_equal(forward, separation)
        check_face_order(first, second, forward)
    if missing_reason() is not None:
        pytest.skip(missing_reason())
    report = check_mesh(tmp_path / "case")
    assert report["ok"], report["log"][-2000:]


def assert_one_line_error(tmp_path, text: str, old: str, new: str, words: str) -> None:
    """The topology ``text`` with ``old`` made ``new`` is refused in one line holding ``words``."""
    assert old in text
    (tmp_path / "bad.yaml").write_text(text.replace(old, new))
    with pytest.raises(GeometryError) as info:
        load_block_set(str(tmp_path / "bad.yaml"), None, (1, 1))
    assert words in str(info.value) and "\n" not in str(info.value)


@pytest.mark.parametrize(
    ("old", "new", "words"),
    [
        ("d: [2, 1]", "d: [2, 1.25]", "cyclic patches 'inlet' and 'outlet' do not match under a translation: the largest mismatch of their vertices is 0.125"),
        ("neighbour: outlet, ", "", "patch 'inlet': a cyclic patch needs 'neighbour'"),
        ("neighbour: inlet, ", "neighbour: floor, ", "cyclic patch 'inlet': its neighbour 'outlet' must be another cyclic patch whose neighbour is 'inlet'"),
        ("type: wall, faces: [[a, b]", "type: wall, neighbour: inlet, faces: [[a, b]", "patch 'floor': only a cyclic patch has a 'neighbour'"),
        ("  ceiling: {type: wall, faces: [[d, e], [e, f]]}", "default_patch: {name: top, type: cyclic}", "default_patch has type 'cyclic'"),
    ],
)  # fmt: skip
def test_bad_pairs_are_one_line(tmp_path, old, new, words):
    """Moving the outlet's top vertex up 0.25 moves its centre up 0.125: the translation between the
    centres leaves each of its vertices 0.125 off."""
    assert_one_line_error(tmp_path, example_text(), old, new, words)


def test_sides_whose_nodes_differ_name_the_pair_and_the_largest_mismatch(run_cli, tmp_path):
    """The vertices match but the inlet bulges 0.05 (an arc): the TFI's nodes on it are off the
    straight outlet's by at most the bulge, at the middle node (the count is even, the grading
    symmetric)."""
    text = example_text().replace("  - {arc: [a, b]", "  - {arc: [a, f], through: [-0.05, 0.5]}\n  - {arc: [a, b]")
    (tmp_path / "bad.yaml").write_text(text)
    blocks = load_block_set(str(tmp_path / "bad.yaml"), None, (1, 1))
    assert len(blocks.coords[0][1]) % 2 == 1  # an even count: a node at the middle
    result = run_cli("mesh", "-g", "bad.yaml", "--method", "elliptic", "--format", "openfoam", "-o", "case")
    assert result.returncode == 2
    line = result.stderr.strip()
    assert len(line.splitlines()) == 1, line
    found = re.search(
        r"cyclic patches 'inlet' and 'outlet' \(separation 2 0\) do not match: the largest mismatch of their nodes is (\S+)", line
    )
    assert found, line
    assert float(found[1]) == pytest.approx(0.05, rel=1e-3)
    assert not (tmp_path / "case").exists()


@pytest.mark.parametrize("output", ["x.su2", "x.msh"])
def test_formats_without_cyclic_patches_refuse_before_meshing(run_cli, tmp_path, output):
    result = run_cli("mesh", "-g", str(EXAMPLE), "--method", "elliptic", "-o", output)
    assert result.returncode == 2
    assert "does not take cyclic patches ('periodic-channel-2d' pairs inlet with outlet)" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not list(tmp_path.glob("x*"))


def cgns_periodic(path) -> list[dict]:
    """The periodic 1-to-1 records of a .cgns file read with h5py: zone, donor, PointRange,
    PointRangeDonor, Transform (1-based) and the Translation."""
    import h5py

    def data(node):
        return np.asarray(node[" data"][()]).T  # HDF5 stores CGNS arrays transposed

    found = []
    with h5py.File(path, "r") as root:
        base = root["Base"]
        for zone in base.values():
            if not isinstance(zone, h5py.Group) or "ZoneGridConnectivity" not in zone:
                continue
            for link in zone["ZoneGridConnectivity"].values():
                if "GridConnectivityProperty" not in link:
                    continue
                found.append(
                    {
                        "zone": zone.name.split("/")[-1],
                        "donor": bytes(link[" data"][()]).decode(),
                        "range": data(link["PointRange"]),
                        "donor_range": data(link["PointRangeDonor"]),
                        "transform": np.asarray(link["Transform"][" data"][()]),
                        "translation": np.asarray(link["GridConnectivityProperty/Periodic/Translation"][" data"][()]),
                    }
                )
    return found


def test_cgns_periodic_connectivity_maps_each_side_onto_the_other_translated(run_cli, tmp_path):
    """Each periodic record's nodes, carried to the donor by its Transform (CGNS: index_b = T
    (index_a - begin_a) + begin_b), are the donor's nodes there less the Translation; both
    directions are written; cgnscheck passes the file."""
    import shutil
    import subprocess

    from meshgen.formats.multiblock import read_zones

    (tmp_path / "box.yaml").write_text(BOX)
    result = run_cli("mesh", "-g", "box.yaml", "--method", "elliptic", "-o", "box.cgns")
    assert result.returncode == 0, result.stderr
    zones = {zone["name"]: zone["X"] for zone in read_zones(tmp_path / "box.cgns")}
    records = cgns_periodic(tmp_path / "box.cgns")
    assert len(records) == 2 * (1 + 2)  # left-right over one block face, front-back over two: both ways
    translations = sorted(tuple(r["translation"]) for r in records)
    assert translations == sorted([(2, 0, 0), (-2, 0, 0), (0, 0, 1), (0, 0, 1), (0, 0, -1), (0, 0, -1)])
    for record in records:
        X, donor = zones[record["zone"]], zones[record["donor"]]
        begin, end = record["range"][:, 0], record["range"][:, 1]  # (dim, 2) after the transpose
        begin_donor = record["donor_range"][:, 0]
        T = np.zeros((3, 3), dtype=int)
        for axis, t in enumerate(record["transform"]):
            T[abs(t) - 1, axis] = np.sign(t)
        grids = np.meshgrid(*[np.arange(min(b, e), max(b, e) + 1) for b, e in zip(begin, end)], indexing="ij")
        index = np.stack([g.reshape(-1) for g in grids], axis=1)  # 1-based
        index_donor = (index - begin) @ T.T + begin_donor
        here, there = X[tuple((index - 1).T)], donor[tuple((index_donor - 1).T)]
        np.testing.assert_allclose(there - here, np.broadcast_to(record["translation"], here.shape), rtol=0, atol=1e-12)
    if shutil.which("cgnscheck") is None:
        pytest.skip("cgnscheck (CGNS tools) not installed")
    check = subprocess.run(["cgnscheck", str(tmp_path / "box.cgns")], capture_output=True, text=True, timeout=120)
    assert check.returncode == 0 and "ERROR" not in check.stdout.upper(), check.stdout[-2000:]
    assert "checking periodic data Translation" in check.stdout


RING = """# a quarter annulus (radii 1 and 2) of two blocks, its two straight sides a rotational pair
vertices: {a: [1, 0], b: [2, 0], c: [1.4142135623730951, 1.4142135623730951],
  d: [0.7071067811865476, 0.7071067811865476], e: [0, 2], f: [0, 1]}
blocks: [[a, b, c, d], [d, c, e, f]]
edges:
  - {arc: [b, c], center: [0, 0]}
  - {arc: [c, e], center: [0, 0]}
  - {arc: [a, d], center: [0, 0]}
  - {arc: [d, f], center: [0, 0]}
cells: {size: 0.1}
patches:
  low: {type: cyclic, neighbour: high, rotation: {center: [0, 0], angle: 90}, faces: [[a, b]]}
  high: {type: cyclic, neighbour: low, faces: [[f, e]]}
"""
QUARTER = np.array([[0.0, -1.0], [1.0, 0.0]])  # +90 degrees about z: x @ QUARTER.T


def test_rotational_pair_matches_after_elliptic_and_in_openfoam(run_cli, tmp_path):
    (tmp_path / "ring.yaml").write_text(RING)
    blocks = load_block_set(str(tmp_path / "ring.yaml"), None, (1, 1))
    assert blocks.cyclic == (("low", "high", (0.0, 0.0), ((0.0, 0.0), (0.0, 0.0, 1.0), 90.0)),)
    Xs, _ = elliptic_blocks(blocks)
    low, high = Xs[0][:, 0], Xs[1][:, -1]  # eta0 of the first block (a -> b), eta1 of the second (f -> e)
    np.testing.assert_allclose(high, low @ QUARTER.T, rtol=0, atol=1e-13)
    result = run_cli("mesh", "-g", "ring.yaml", "--method", "elliptic", "--format", "openfoam", "-o", "case")
    assert result.returncode == 0, result.stderr
    case = tmp_path / "case"
    entries = boundary_entries(case)
    assert entries["low"]["transform"] == entries["high"]["transform"] == "rotational"
    assert entries["low"]["rotationAxis"] == entries["high"]["rotationAxis"] == "(0 0 1)"
    points = read_list(case / "constant" / "polyMesh" / "points", 3)
    faces = read_list(case / "constant" / "polyMesh" / "faces", 4).astype(int)
    sides = [points[faces[int(entries[n]["startFace"]) :][: int(entries[n]["nFaces"])]] for n in ("low", "high")]
    turned = sides[0][:, [0, 3, 2, 1]].copy()
    turned[..., :2] = turned[..., :2] @ QUARTER.T
    np.testing.assert_allclose(sides[1], turned, rtol=0, atol=1e-12)
    if missing_reason() is not None:
        pytest.skip(missing_reason())
    report = check_mesh(case)
    assert report["ok"], report["log"][-2000:]
    assert "Coupled point location match" in report["log"]


@pytest.mark.parametrize(
    ("old", "new", "words"),
    [
        ("angle: 90}", "angle: 80}", "do not match under the rotation 80 deg about (0 0 1) through (0 0): the largest mismatch of their vertices is " + f"{4 * np.sin(np.radians(5)):.3g}"),  # b at radius 2, 10 degrees short
        ("neighbour: low, ", "neighbour: low, rotation: {center: [0, 0], angle: -90}, ", "cyclic patches 'low' and 'high' both give a rotation"),
        ("center: [0, 0], angle", "center: [0, 0], axis: [1, 0, 0], angle", "axis must be a nonzero vector along z"),
        ("center: [0, 0], angle: 90", "angle: 90", "rotation needs center and angle"),
    ],
)  # fmt: skip
def test_bad_rotations_are_one_line(tmp_path, old, new, words):
    assert_one_line_error(tmp_path, RING, old, new, words)


def test_cgns_refuses_a_rotational_pair_before_meshing(run_cli, tmp_path):
    (tmp_path / "ring.yaml").write_text(RING)
    result = run_cli("mesh", "-g", "ring.yaml", "--method", "elliptic", "-o", "ring.cgns")
    assert result.returncode == 2
    assert "cgns: the cyclic pair 'low' and 'high' is rotational" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not list(tmp_path.glob("ring.cgns*"))

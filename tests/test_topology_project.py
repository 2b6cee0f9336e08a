"""Faces and edges of a topology file projected onto named surfaces
(``meshgen.geometry.topology_project``): wall nodes on the closed-form sphere and cylinder, on an
STL's facets (against a brute-force closest point over every triangle), conforming interfaces,
the elliptic mesh keeping them, checkMesh, and the one-line errors of bad projections."""

import itertools
from pathlib import Path

import numpy as np
import pytest

from meshgen.errors import GeometryError
from meshgen.geometry import cube
from meshgen.geometry.block_nodes import interface_gaps
from meshgen.geometry.blocks import block_patches, load_block_set, tfi_blocks
from meshgen.methods.tfi import tfi

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "topologies"
INNER, OUTER = 0.5, 1.0


def sphere_in_box(surface: str, project: bool = True, arcs: bool = False, cells: int = 6) -> str:
    """Six blocks between a sphere of radius INNER (its cube's corners on it) and the box |x| <= OUTER."""
    signs = list(itertools.product((-1, 1), repeat=3))
    a = INNER / np.sqrt(3.0)
    vertices = [(a * np.array(s)).tolist() for s in signs] + [(OUTER * np.array(s, float)).tolist() for s in signs]
    blocks, walls = [], []
    for axis, side in itertools.product(range(3), (-1, 1)):
        u, v = [d for d in range(3) if d != axis]
        quad = []
        for i, j in ((0, 0), (1, 0), (1, 1), (0, 1)):
            s = [0, 0, 0]
            s[axis], s[u], s[v] = side, 2 * i - 1, 2 * j - 1
            quad.append(signs.index(tuple(s)))
        points = np.array(vertices)
        frame = [points[quad[1]] - points[quad[0]], points[quad[3]] - points[quad[0]], points[quad[0] + 8] - points[quad[0]]]
        if np.linalg.det(frame) < 0:
            quad = quad[::-1]
        blocks.append(quad + [q + 8 for q in quad])
        walls.append(quad)
    edges = []
    if arcs:
        pairs = {tuple(sorted((w[k], w[(k + 1) % 4]))) for w in walls for k in range(4)}
        edges = [f"{{arc: [{i}, {j}], center: [0, 0, 0]}}" for i, j in sorted(pairs)]
    onto = ", project: ball" if project else ""
    return (
        f"surfaces: {{ball: {surface}}}\nvertices: {vertices}\nblocks: {blocks}\n"
        + (f"edges: [{', '.join(edges)}]\n" if edges else "")
        + f"cells: {{counts: [[0, 1, {cells}], [0, 2, {cells}], [0, 4, {cells}], [0, 8, {cells}]]}}\n"
        + f"patches: {{wall: {{type: wall{onto}, faces: {walls}}}}}\n"
    )


def write(tmp_path, text: str, name: str = "t.yaml") -> str:
    path = tmp_path / name
    path.write_text(text)
    return str(path)


def wall_nodes(blocks, Xs, patch: str) -> np.ndarray:
    found = []
    for X, patches in zip(Xs, block_patches(blocks)):
        for p in patches:
            if p.name == patch:
                for face in p.faces:
                    found.append(X[cube.face_named(face, blocks.dim).node_index].reshape(-1, X.shape[-1]))
    return np.concatenate(found)


SPHERE = f"{{sphere: {{center: [0, 0, 0], radius: {INNER}}}}}"


def test_sphere_faces_lie_on_the_sphere_where_arcs_sag(tmp_path):
    projected = load_block_set(write(tmp_path, sphere_in_box(SPHERE)), None, (1, 1, 1))
    Xs = tfi_blocks(projected)
    radius = np.linalg.norm(wall_nodes(projected, Xs, "wall"), axis=1)
    assert np.max(np.abs(radius - INNER)) <= 1e-14 * OUTER
    # The same blocks with great-circle arcs on the wall's edges: the Coons patch of four arcs sags inwards.
    arcs = load_block_set(write(tmp_path, sphere_in_box(SPHERE, project=False, arcs=True), "a.yaml"), None, (1, 1, 1))
    sag = INNER - np.linalg.norm(wall_nodes(arcs, tfi_blocks(arcs), "wall"), axis=1)
    assert 0.01 * INNER < np.max(sag) < 0.2 * INNER
    # The projected edges are the arcs' great circles: both sets of edge nodes lie on the sphere.
    for X in tfi_blocks(arcs):
        assert np.max(np.abs(np.linalg.norm(X[:, 0, 0], axis=1) - INNER)) <= 1e-14


def test_projected_interfaces_conform_before_unifying(tmp_path):
    blocks = load_block_set(write(tmp_path, sphere_in_box(SPHERE)), None, (1, 1, 1))
    raw = [tfi(g, None, list(c)) for g, c in zip(blocks.geometries, blocks.coords)]
    assert len(blocks.interfaces) == 12
    assert max(interface_gaps(blocks, raw)) <= 1e-14 * OUTER


def test_an_interface_face_projected_from_one_block_is_the_same_in_both(tmp_path):
    # Two unit cubes side by side; their shared face x = 1 is bulged onto a sphere through its corners.
    hexes = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]
    right = [[2, 0, 0], [2, 1, 0], [2, 1, 1], [2, 0, 1]]
    text = (
        f"surfaces: {{bulge: {{sphere: {{center: [-1, 0.5, 0.5], radius: {np.sqrt(4.5)}}}}}}}\n"
        f"vertices: {hexes + right}\n"
        "blocks: [{name: left, vertices: [0, 1, 2, 3, 4, 5, 6, 7], project: {xi1: bulge}}, [1, 8, 9, 2, 5, 11, 10, 6]]\n"
        "cells: {size: 0.125}\n"
    )
    blocks = load_block_set(write(tmp_path, text), None, (1, 1, 1))
    raw = [tfi(g, None, list(c)) for g, c in zip(blocks.geometries, blocks.coords)]
    assert max(interface_gaps(blocks, raw)) <= 1e-14
    face = raw[0][-1].reshape(-1, 3)
    assert np.max(np.abs(np.linalg.norm(face - [-1, 0.5, 0.5], axis=1) - np.sqrt(4.5))) <= 1e-14
    assert np.max(face[:, 0]) > 1.02  # bulged out of the plane x = 1 (by 2.12 - 2 at its middle)


def test_cylinder_example_wall_is_exact_where_straight_edges_sag(tmp_path):
    example = EXAMPLES / "cylinder-3d.yaml"
    blocks = load_block_set(str(example), None, (1, 1, 1))
    wall = wall_nodes(blocks, tfi_blocks(blocks), "cylinder")
    assert np.max(np.abs(np.linalg.norm(wall[:, :2], axis=1) - 0.05)) <= 1e-12 * 2.5
    assert np.ptp(wall[:, 2]) == pytest.approx(0.1)
    # Without the projection the wall's edges are the straight chords of 90-degree arcs: a sag of 1 - cos 45 degrees.
    straight = write(tmp_path, example.read_text().replace("type: wall, project: cylinder,", "type: wall,"))
    blocks = load_block_set(straight, None, (1, 1, 1))
    wall = wall_nodes(blocks, tfi_blocks(blocks), "cylinder")
    sag = 1.0 - np.min(np.linalg.norm(wall[:, :2], axis=1)) / 0.05
    assert sag == pytest.approx(1.0 - np.cos(np.pi / 4), rel=1e-9)


def elbow(project: bool) -> str:
    """examples/topologies/elbow-3d.yaml (radius 0.5 bent at radius 2 about z), its wall blocks' eta0 onto a torus."""
    text = (EXAMPLES / "elbow-3d.yaml").read_text()
    if project:
        text += "surfaces: {tube: {torus: {center: [0, 0, 0], axis: [0, 0, 1], major: 2, minor: 0.5}}}\n"
        for line in text.splitlines():
            if line.startswith("  - [bw"):
                text = text.replace(line, f"  - {{vertices: {line[4:]}, project: {{eta0: tube}}}}")
    return text


def test_elbow_wall_on_a_torus_where_its_arcs_sag(tmp_path):
    def distances(text):
        blocks = load_block_set(write(tmp_path, text, f"{len(text)}.yaml"), None, (1, 1, 1))
        Xs = tfi_blocks(blocks)
        wall = np.concatenate([Xs[b][:, 0].reshape(-1, 3) for b in range(1, 5)])  # eta0 of the wall blocks
        ring = 2.0 * np.column_stack([wall[:, :2] / np.linalg.norm(wall[:, :2], axis=1, keepdims=True), np.zeros(len(wall))])
        return np.abs(np.linalg.norm(wall - ring, axis=1) - 0.5) / 0.5

    before, after = distances(elbow(False)), distances(elbow(True))
    assert 0.01 < np.max(before) < 0.06  # the Coons patches between the arcs sag by some per cent of the radius
    assert np.max(after) <= 1e-14 / 0.5 * 4


def test_stl_faces_lie_on_the_facets(tmp_path):
    trimesh = pytest.importorskip("trimesh")
    trimesh.creation.icosphere(subdivisions=3, radius=INNER).export(str(tmp_path / "ball.stl"))
    ball = trimesh.load(str(tmp_path / "ball.stl"), force="mesh")  # float32 points, as the file holds them
    blocks = load_block_set(write(tmp_path, sphere_in_box("{file: ball.stl}", cells=5)), None, (1, 1, 1))
    Xs = tfi_blocks(blocks)
    wall = wall_nodes(blocks, Xs, "wall")
    # Brute force: the closest point of every node on every triangle (trimesh's per-triangle routine).
    triangles = ball.triangles
    pairs = trimesh.triangles.closest_point(np.repeat(triangles, len(wall), axis=0), np.tile(wall, (len(triangles), 1)))
    distance = np.linalg.norm(pairs - np.tile(wall, (len(triangles), 1)), axis=1).reshape(len(triangles), len(wall))
    assert np.max(distance.min(axis=0)) <= 1e-9 * 2 * OUTER
    # ... and not merely near it: the nodes sit inside the sphere where the facets are flat.
    assert np.min(np.linalg.norm(wall, axis=1)) < INNER * (1 - 1e-3)
    assert max(interface_gaps(blocks, [tfi(g, None, list(c)) for g, c in zip(blocks.geometries, blocks.coords)])) <= 1e-12


def test_elliptic_keeps_projected_nodes_on_the_surface(tmp_path):
    from meshgen.methods.elliptic import elliptic_blocks

    blocks = load_block_set(write(tmp_path, sphere_in_box(SPHERE, cells=4)), None, (1, 1, 1))
    Xs, _ = elliptic_blocks(blocks, max_iter=5)
    radius = np.linalg.norm(wall_nodes(blocks, Xs, "wall"), axis=1)
    assert np.max(np.abs(radius - INNER)) <= 1e-12


def test_an_edge_on_two_surfaces_lies_on_both(tmp_path):
    # One block whose top face goes onto a sphere and whose side face onto a tilted plane: their
    # shared edge lies on the circle where the two meet.
    hexes = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]]
    text = (
        "surfaces: {top: {sphere: {center: [0.5, 0.5, -3], radius: 4}}, side: {plane: {point: [1, 0, 0], normal: [1, 0, 0.05]}}}\n"
        f"vertices: {hexes}\n"
        "blocks: [{name: b, vertices: [0, 1, 2, 3, 4, 5, 6, 7], project: {zeta1: top, xi1: side}}]\n"
        "cells: {size: 0.1}\n"
    )
    blocks = load_block_set(write(tmp_path, text), None, (1, 1, 1))
    (X,) = tfi_blocks(blocks)
    edge = X[-1, :, -1]
    assert np.max(np.abs(np.linalg.norm(edge - [0.5, 0.5, -3], axis=1) - 4)) <= 1e-12
    assert np.max(np.abs((edge - [1, 0, 0]) @ np.array([1, 0, 0.05]))) <= 1e-12
    top, side = X[:, :, -1].reshape(-1, 3), X[-1].reshape(-1, 3)
    assert np.max(np.abs(np.linalg.norm(top - [0.5, 0.5, -3], axis=1) - 4)) <= 1e-12
    assert np.max(np.abs((side - [1, 0, 0]) @ np.array([1, 0, 0.05]))) <= 1e-12


def test_2d_patch_on_a_circle(tmp_path):
    text = (
        "surfaces: {round: {cylinder: {point: [0, 0], radius: 1}}}\n"
        "vertices: {a: [1, 0], b: [3, 0], c: [0, 3], d: [0, 1]}\nblocks: [[a, b, c, d]]\ncells: {size: 0.1}\n"
        "patches: {wall: {type: wall, project: round, faces: [[d, a]]}}\n"
    )
    blocks = load_block_set(write(tmp_path, text), None, (1, 1))
    wall = wall_nodes(blocks, tfi_blocks(blocks), "wall")
    assert len(wall) > 10 and np.max(np.abs(np.linalg.norm(wall, axis=1) - 1)) <= 1e-15


def test_an_edge_entry_projects_like_the_patch(tmp_path):
    base = (
        "surfaces: {round: {cylinder: {point: [0, 0], radius: 1}}}\n"
        "vertices: {a: [1, 0], b: [3, 0], c: [0, 3], d: [0, 1]}\nblocks: [[a, b, c, d]]\ncells: {size: 0.1}\n"
    )
    by_patch = base + "patches: {wall: {type: wall, project: round, faces: [[d, a]]}}\n"
    by_edge = base + "edges: [{line: [a, d], project: round}]\npatches: {wall: {type: wall, faces: [[d, a]]}}\n"
    found = []
    for name, text in (("patch", by_patch), ("edge", by_edge)):
        blocks = load_block_set(write(tmp_path, text, f"{name}.yaml"), None, (1, 1))
        found.append(tfi_blocks(blocks)[0])
    np.testing.assert_array_equal(found[0], found[1])
    with pytest.raises(GeometryError, match="a line entry only projects"):
        load_block_set(write(tmp_path, base + "edges: [{line: [a, d]}]\n", "line.yaml"), None, (1, 1))


@pytest.mark.parametrize(
    "change, words",
    [
        (("project: ball", "project: bal"), "unknown surface 'bal'"),
        (("{ball: {sphere:", "{ball: {spheer:"), "needs one surface kind"),
        ((f"radius: {INNER}", "radius: 0.05"), "does not contain it"),
        ((SPHERE, "{file: missing.stl}"), "no file"),
        ((SPHERE, "{file: ball.stl, face: 3}"), "'face' is for a CAD file"),
        ((SPHERE, "{file: part.step}"), "needs 'face'"),
        ((f"radius: {INNER}", "radius: -1"), "radius must be a positive number"),
    ],
)
def test_bad_projections_are_one_line(tmp_path, change, words):
    text = sphere_in_box(SPHERE).replace(*change)
    with pytest.raises(GeometryError, match=words) as error:
        load_block_set(write(tmp_path, text), None, (1, 1, 1))
    assert "\n" not in str(error.value)


def test_cli_bad_projection_exits_2_writing_nothing(run_cli, tmp_path):
    write(tmp_path, sphere_in_box(SPHERE).replace("project: ball", "project: bowl"), "bad.yaml")
    result = run_cli("mesh", "-g", "bad.yaml", "--method", "tfi", "-o", "x.cgns")
    assert result.returncode == 2
    assert "unknown surface 'bowl'" in result.stderr and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert not list(tmp_path.glob("x.*"))


QUARTER = """surfaces: {{pipe: {surface}}}
vertices: {{a: [0.5, 0, 0.5], b: [1, 0, 0.5], c: [1, 1, 0.5], m: [0.35, 0.35, 0.5], d: [0, 1, 0.5], e: [0, 0.5, 0.5],
  A: [0.5, 0, 1.5], B: [1, 0, 1.5], C: [1, 1, 1.5], M: [0.35, 0.35, 1.5], D: [0, 1, 1.5], E: [0, 0.5, 1.5]}}
blocks: [[a, b, c, m, A, B, C, M], [m, c, d, e, M, C, D, E]]
cells: {{size: 0.1}}
patches: {{wall: {{type: wall, project: pipe, faces: [[a, m, M, A], [m, e, E, M]]}}}}
"""


def test_cad_face_projection_is_the_cylinder(tmp_path):
    pytest.importorskip("gmsh")
    from shape_helpers import write_sweep_solid

    write_sweep_solid("cylinder", tmp_path / "rod.step")  # radius 0.5, 0 <= z <= 2 about the z axis
    import gmsh

    started = not gmsh.isInitialized()
    if started:
        gmsh.initialize(readConfigFiles=False, interruptible=False)
    gmsh.model.add("faces of the rod")
    gmsh.model.occ.importShapes(str(tmp_path / "rod.step"))
    gmsh.model.occ.synchronize()
    face = next(tag for dim, tag in gmsh.model.getEntities(2) if gmsh.model.getType(dim, tag) == "Cylinder")
    gmsh.model.remove()
    if started:
        gmsh.finalize()
    walls = {}
    for name, surface in (
        ("cad", f"{{file: rod.step, face: {face}}}"),
        ("exact", "{cylinder: {axis: [0, 0, 1], point: [0, 0, 0], radius: 0.5}}"),
    ):
        blocks = load_block_set(write(tmp_path, QUARTER.format(surface=surface), f"{name}.yaml"), None, (1, 1, 1))
        walls[name] = wall_nodes(blocks, tfi_blocks(blocks), "wall")
    assert np.max(np.abs(np.linalg.norm(walls["cad"][:, :2], axis=1) - 0.5)) <= 1e-9
    np.testing.assert_allclose(walls["cad"], walls["exact"], atol=1e-9)
    with pytest.raises(GeometryError, match="has no face 99"):
        load_block_set(write(tmp_path, QUARTER.format(surface="{file: rod.step, face: 99}"), "bad.yaml"), None, (1, 1, 1))


def _wall_line_angles(blocks, Xs) -> np.ndarray:
    """Degrees between each wall node's first grid line and the sphere's normal there."""
    angles = []
    for X, patches in zip(Xs, block_patches(blocks)):
        for face in (cube.face_named(f, 3) for p in patches if p.name == "wall" for f in p.faces):
            inner = list(face.node_index)
            inner[face.axis] = -2 if face.side else 1
            wall, line = X[face.node_index].reshape(-1, 3), X[tuple(inner)].reshape(-1, 3) - X[face.node_index].reshape(-1, 3)
            cos = np.abs(np.einsum("ij,ij->i", wall, line)) / np.linalg.norm(wall, axis=1) / np.linalg.norm(line, axis=1)
            angles.append(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))
    return np.concatenate(angles)


def test_a_sliding_wall_stays_on_its_surface_with_its_grid_lines_square(tmp_path):
    from meshgen.methods.elliptic import elliptic_blocks

    text = sphere_in_box(SPHERE, cells=6)
    fixed = load_block_set(write(tmp_path, text, "fixed.yaml"), None, (1, 1, 1))
    sliding = load_block_set(
        write(tmp_path, text.replace("project: ball", "project: ball, slide: true"), "slide.yaml"), None, (1, 1, 1)
    )
    assert not fixed.surfaces and len(sliding.surfaces) == 6
    stay, _ = elliptic_blocks(fixed, orthogonality=False)
    slid, info = elliptic_blocks(sliding, orthogonality=False)
    assert info["surface_rounds"] >= 1
    radius = np.linalg.norm(wall_nodes(sliding, slid, "wall"), axis=1)
    assert np.max(np.abs(radius - INNER)) <= 1e-12  # on the sphere, moved along it
    moved = np.abs(wall_nodes(sliding, slid, "wall") - wall_nodes(fixed, stay, "wall")).max()
    assert moved > 1e-3 * INNER
    # the grid lines leave the sphere closer to its normal than where the wall nodes stay put
    assert _wall_line_angles(sliding, slid).mean() < 0.5 * _wall_line_angles(fixed, stay).mean()


@pytest.mark.parametrize("entry", ["project: ball, slide: 1", "slide: true"])
def test_slide_is_true_or_false_on_a_projected_patch(tmp_path, entry):
    text = sphere_in_box(SPHERE).replace("project: ball", entry)
    with pytest.raises(GeometryError, match="'slide' is true or false, on a patch with 'project'") as error:
        load_block_set(write(tmp_path, text), None, (1, 1, 1))
    assert "\n" not in str(error.value)


def test_an_extruded_set_slides_its_wall_in_its_section(tmp_path):
    """cylinder-3d is solved as its 2D section: the surface's map goes to the section's frame."""
    from meshgen.methods.elliptic import elliptic_blocks

    text = (EXAMPLES / "cylinder-3d.yaml").read_text()
    sliding = load_block_set(
        write(tmp_path, text.replace("project: cylinder,", "project: cylinder, slide: true,"), "s.yaml"), None, (1, 1, 1)
    )
    fixed = load_block_set(write(tmp_path, text, "f.yaml"), None, (1, 1, 1))
    slid, info = elliptic_blocks(sliding, orthogonality=False)
    stay, _ = elliptic_blocks(fixed, orthogonality=False)
    assert info.get("extruded") and info["surface_rounds"] >= 1
    wall, kept = wall_nodes(sliding, slid, "cylinder"), wall_nodes(fixed, stay, "cylinder")
    assert np.max(np.abs(np.linalg.norm(wall[:, :2], axis=1) - 0.05)) <= 1e-14  # on the cylinder
    assert np.abs(wall - kept).max() > 1e-4 * 0.05  # and moved along it

"""The topology files that redo classy_blocks' examples (examples/topologies/karman-2d.yaml,
elbow-taper-3d.yaml): their cell counts against the anchors' (blockMesh on classy_blocks' files),
their boundary nodes against the closed-form circles, their grading, and checkMesh's verdict
against the anchors' figures (benchmarks/bench_topology.py measures both in one run)."""

import sys
from pathlib import Path

import numpy as np
import pytest
from openfoam_helpers import check_mesh, needs_openfoam

from meshgen.geometry.blocks import load_block_set, tfi_blocks

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples" / "topologies"
KARMAN, ELBOW = str(EXAMPLES / "karman-2d.yaml"), str(EXAMPLES / "elbow-taper-3d.yaml")
# checkMesh on blockMesh's meshes of classy_blocks 1.10's karman.py and elbow.py (benchmarks/bench_topology.py).
ANCHOR = {"karman": (2424, 40.6891, 0.401626), "elbow": (5040, 38.8301, 1.07589)}


def cells(block_set) -> int:
    return sum(int(np.prod([n - 1 for n in shape])) for shape in block_set.node_shapes)


def test_karman_matches_the_anchor_cells_and_cylinder():
    blocks = load_block_set(KARMAN, None, (1, 1))
    assert cells(blocks) == ANCHOR["karman"][0]
    Xs = tfi_blocks(blocks)
    ring = [blocks.names.index(f"b{i}") for i in range(4)]  # the O-ring: eta runs from the square to the cylinder
    for b in ring:
        X = Xs[b]
        np.testing.assert_allclose(
            np.linalg.norm(X[:, -1], axis=-1), 0.01, rtol=1e-8
        )  # on the cylinder (the file gives 10 digits)
        np.testing.assert_allclose(np.linalg.norm(X[:, 0], axis=-1), 0.015, rtol=1e-8)  # on the ring's outer arc
        first = np.linalg.norm(X[:, -1] - X[:, -2], axis=-1)
        np.testing.assert_allclose(first, 1e-4, rtol=1e-6)  # grading: first_cell on the cylinder
        widths = np.linalg.norm(np.diff(X[7], axis=0), axis=-1)
        assert np.all(np.diff(widths) < 0)  # cells shrink towards the cylinder
    x = np.concatenate([X[..., 0].ravel() for X in Xs])
    y = np.concatenate([X[..., 1].ravel() for X in Xs])
    assert (x.min(), x.max(), y.min(), y.max()) == pytest.approx((-0.03, 0.05, -0.025, 0.025), abs=1e-12)


def test_elbow_matches_the_anchor_cells_and_its_circles():
    blocks = load_block_set(ELBOW, None, (1, 1, 1))
    assert cells(blocks) == ANCHOR["elbow"][0]
    Xs = tfi_blocks(blocks)
    walls = [blocks.names.index(f"b{i}") for i in range(1, 5)]  # eta0: the pipe wall
    angle = -np.pi / 3  # the outlet: the inlet turned by -60 degrees about z through (2, 0, 0), radius 0.4
    centre = np.array([2 - 2 * np.cos(angle), -2 * np.sin(angle), 0.0])
    normal = np.array([-np.sin(angle), np.cos(angle), 0.0])
    for b in walls:
        inlet, outlet = Xs[b][:, 0, 0], Xs[b][:, 0, -1]
        np.testing.assert_allclose(inlet[:, 1], 0.0, atol=1e-12)
        np.testing.assert_allclose(np.linalg.norm(inlet, axis=-1), 1.0, rtol=1e-8)
        np.testing.assert_allclose((outlet - centre) @ normal, 0.0, atol=1e-9)
        np.testing.assert_allclose(np.linalg.norm(outlet - centre, axis=-1), 0.4, rtol=1e-8)
        radial = np.linalg.norm(np.diff(Xs[b][7, :, 0], axis=0), axis=-1)  # wall -> core at the inlet
        assert radial[-1] / radial[0] == pytest.approx(8.0, rel=1e-6)  # ratio 0.125 core -> wall


def _check(path, method, tmp_path):
    import meshgen

    dims = (1, 1) if path == KARMAN else (1, 1, 1)
    made = meshgen.mesh(path, dims=dims, method=method)
    case = tmp_path / method
    made.write(case, "openfoam", quality=False)
    found = check_mesh(case)
    log = found["log"]

    def number(key):
        return float(log.split(key, 1)[1].split()[0])

    return found, number("Mesh non-orthogonality Max:"), number("Max skewness =")


@needs_openfoam
def test_karman_checkmesh_against_the_anchor(tmp_path):
    count, non_orthogonal, skewness = ANCHOR["karman"]
    tfi, tfi_angle, tfi_skew = _check(KARMAN, "tfi", tmp_path)
    assert tfi["ok"] and tfi["cells"] == count
    # The TFI of the file's edges is blockMesh's interpolation of classy_blocks' file: the same figures.
    assert tfi_angle == pytest.approx(non_orthogonal, abs=1e-3) and tfi_skew == pytest.approx(skewness, abs=1e-5)
    elliptic, angle, _ = _check(KARMAN, "elliptic", tmp_path)
    assert elliptic["ok"] and elliptic["cells"] == count
    assert angle < 0.5 * tfi_angle  # smoothing lowers the max non-orthogonality at the same boundary nodes


@needs_openfoam
def test_elbow_checkmesh_against_the_anchor(tmp_path):
    count, non_orthogonal, skewness = ANCHOR["elbow"]
    tfi, angle, skew = _check(ELBOW, "tfi", tmp_path)
    assert tfi["ok"] and tfi["cells"] == count
    assert angle <= non_orthogonal and skew <= skewness


def test_bench_input_lines(tmp_path):
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from bench_topology import input_lines

    path = tmp_path / "f.yaml"
    path.write_text("# a comment\nname: x\n\n   # indented comment\nvertices: [] # trailing\n  \n")
    assert input_lines(path) == (2, 6)


def min_corner_jacobian(X: np.ndarray) -> float:
    """The smallest of the 8 corner Jacobians (triple products of the edges at the corner) of the hexes of X."""
    n = [s - 1 for s in X.shape[:3]]
    found = np.inf
    for corner in np.ndindex(2, 2, 2):
        at = tuple(slice(c, c + m) for c, m in zip(corner, n))
        edges = []
        for axis in range(3):
            other = list(at)
            other[axis] = slice(1 - corner[axis], 1 - corner[axis] + n[axis])
            edges.append((X[tuple(other)] - X[at]) * (1 - 2 * corner[axis]))
        found = min(found, float(np.einsum("...i,...i", np.cross(edges[0], edges[1]), edges[2]).min()))
    return found


def test_tapered_elbow_caps_do_not_slide_and_elliptic_does_not_fold():
    from meshgen.geometry.block_nodes import global_numbering
    from meshgen.methods.elliptic import elliptic_blocks
    from meshgen.methods.sliding import planar_sliding

    for path, slides in ((ELBOW, False), (str(EXAMPLES / "elbow-3d.yaml"), True)):
        blocks = load_block_set(path, None, (1, 1, 1))
        Xs = tfi_blocks(blocks)
        numbering, count = global_numbering(blocks)
        # The taper's wall meets its flat inlet and outlet ~17 degrees off their normals; the
        # constant-radius elbow's meets them at right angles, so its caps slide.
        assert (planar_sliding(blocks, Xs, numbering, count) is not None) == slides
    blocks = load_block_set(ELBOW, None, (1, 1, 1))
    Xs, info = elliptic_blocks(blocks)
    assert info["converged"]
    assert min(min_corner_jacobian(X) for X in Xs) > 0  # sliding caps folded 14 cells at the outlet rim

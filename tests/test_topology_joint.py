"""The ``joint`` shorthand of topology files (``meshgen.geometry.topology_shorthand``): pipes of one
radius meeting in a plane, expanded into mitred 8-block O-grid arms; its cell count against the
closed form, its walls and mitres against the cylinders and bisector planes, its one-line errors,
and checkMesh on examples/topologies/t-joint-3d.yaml against classy_blocks' T-joint."""

from pathlib import Path

import numpy as np
import pytest
from openfoam_helpers import check_mesh, needs_openfoam

from meshgen.errors import GeometryError
from meshgen.geometry.blocks import load_block_set, tfi_blocks

TJOINT = str(Path(__file__).resolve().parents[1] / "examples" / "topologies" / "t-joint-3d.yaml")
CENTER = np.array([5.0, 5.0, 0.0])
ENDS = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [0.0, 10.0, 0.0]])


def joint(tmp_path, body: str) -> str:
    path = tmp_path / "j.yaml"
    path.write_text(body)
    return str(path)


def test_t_joint_cells_walls_and_mitres():
    blocks = load_block_set(TJOINT, None, (1, 1, 1))
    core, radial, along = 8, 5, 15  # the file's cells
    section = 2 * core * (2 * core) + radial * (4 * core + 2 * (2 * core))  # 2 core blocks, 6 wall blocks
    assert sum(int(np.prod([n - 1 for n in s])) for s in blocks.node_shapes) == 3 * along * section
    Xs = tfi_blocks(blocks)
    axes = (ENDS - CENTER) / np.linalg.norm(ENDS - CENTER, axis=1)[:, None]
    for b, X in enumerate(Xs):
        arm = b // 8  # blocks come arm by arm, 8 each
        offset = X - CENTER
        radial_distance = np.linalg.norm(offset - (offset @ axes[arm])[..., None] * axes[arm], axis=-1)
        # Inside the arm's cylinder, up to the mitre splines' error (3.5e-5 of the radius with 15 points; 3.7e-4 with 7).
        assert radial_distance.max() <= 2.0 * (1 + 1e-4)
        if (b, "eta0") in blocks.patches and blocks.patches[b, "eta0"][0] == "walls":
            wall = radial_distance[:, 0]
            # The end arcs and the mitre ellipses (splines through 15 exact points) lie on the cylinder.
            np.testing.assert_allclose(wall[:, 0], 2.0, rtol=1e-9)
            np.testing.assert_allclose(wall[:, -1], 2.0, rtol=1e-4)
        mitre = X[:, :, -1]  # every block runs from its arm's end to the mitre
        along_arm = (mitre - CENTER) @ axes[arm]
        side = (mitre - CENTER) @ np.cross([0, 0, 1], axes[arm])
        # On the bisector planes: 45 degrees towards a perpendicular arm (along = |side|), across the
        # axis towards the opposite one (along = 0); side > 0 faces the next arm counterclockwise about z.
        slope = {0: (1, 1), 1: (0, 1), 2: (1, 0)}[arm]  # on the side > 0 and the side < 0
        expected = np.where(side > 0, slope[0] * side, -slope[1] * side)
        np.testing.assert_allclose(along_arm, expected, atol=1e-9)


def test_joint_errors(tmp_path):
    good = "joint: {center: [0, 0, 0], radius: 1, arms: [{end: [4, 0, 0]}, {end: [0, 4, 0]}, {end: [-4, 0, 0]}]}\n"
    load_block_set(joint(tmp_path, good), None, (1, 1, 1))
    cases = {
        good.replace("[-4, 0, 0]", "[-4, 0, 1]"): "not in one plane",
        good.replace("[4, 0, 0]", "[1.2, 0, 0]"): "shorter than its mitre",
        good.replace("radius: 1", "radius: 1, cels: {core: 4}"): "did you mean 'cells'",
        good.replace("[0, 4, 0]", "[4, 0, 0]").replace("radius: 1", "radius: 1, normal: [0, 0, 1]"): "same way",
        good.replace("[0, 4, 0]", "[4, 0, 0]"): "on one line",
        "joint: {center: [0, 0, 0], radius: 1, arms: [{end: [4, 0, 0]}, {end: [0, 4, 0]}]}\n": "more than 180 degrees",
    }
    for text, said in cases.items():
        with pytest.raises(GeometryError, match=said) as caught:
            load_block_set(joint(tmp_path, text), None, (1, 1, 1))
        assert "\n" not in str(caught.value)


@needs_openfoam
def test_t_joint_checkmesh_against_classy_blocks(tmp_path):
    import meshgen

    made = meshgen.mesh(TJOINT, dims=(1, 1, 1), method="tfi")
    made.write(tmp_path / "case", "openfoam", quality=False)
    found = check_mesh(tmp_path / "case")
    log = found["log"]
    angle = float(log.split("Mesh non-orthogonality Max:", 1)[1].split()[0])
    skew = float(log.split("Max skewness =", 1)[1].split()[0])
    # blockMesh on classy_blocks 1.10's t_joint.py: 25,020 cells, max non-orthogonality 51.6, max skewness 2.38.
    assert found["ok"] and abs(found["cells"] / 25020 - 1) <= 0.1
    assert angle <= 51.6 and skew <= 2.38
    assert set(found["patches"]) == {"inlet", "outlet_1", "outlet_2", "walls"}
    assert found["patches"]["inlet"] == found["patches"]["outlet_1"] == 2 * 8 * 16 + 5 * (4 * 8 + 2 * 16)


def test_t_joint_elliptic_does_not_fold_at_its_inner_block_corners():
    from test_topology_examples import min_corner_jacobian

    from meshgen.methods.elliptic import elliptic_blocks

    # The mitres' block corners are inside the set (6 and 12 blocks meet there): they had no
    # junction equation and stayed at the TFI while their neighbours moved by ~0.5, folding 30 cells.
    blocks = load_block_set(TJOINT, None, (1, 1, 1))
    Xs, info = elliptic_blocks(blocks)
    assert info["converged"]
    assert min(min_corner_jacobian(X) for X in Xs) > 0
    moved = [np.abs(X - T).max() for X, T in zip(Xs, tfi_blocks(blocks))]
    assert max(moved) > 0.1  # the solve did move the mesh (not the TFI returned)


@pytest.mark.parametrize(
    "arms, normal",
    [
        ("[{end: [4, 0, 0]}, {end: [-2, 3.4641016151, 0]}, {end: [-2, -3.4641016151, 0]}]", ""),  # a Y, 120 degrees apart
        ("[{end: [4, 0, 0]}, {end: [0, 0, 4]}, {end: [-4, 0, 0]}, {end: [0, 0, -4]}]", "normal: [0, 1, 0], "),  # a cross
    ],
)
def test_other_joints_conform_and_do_not_fold(tmp_path, arms, normal):
    from test_topology_examples import min_corner_jacobian

    path = joint(
        tmp_path, f"joint: {{center: [0, 0, 0], radius: 1, {normal}arms: {arms}, cells: {{core: 3, radial: 2, along: 6}}}}\n"
    )
    blocks = load_block_set(path, None, (1, 1, 1))
    count = arms.count("end")
    # Per arm 13 interfaces inside its sections; its 8 mitre faces are shared with its neighbours'.
    assert len(blocks.names) == 8 * count and len(blocks.interfaces) == 13 * count + 8 * count // 2
    assert min(min_corner_jacobian(X) for X in tfi_blocks(blocks)) > 0

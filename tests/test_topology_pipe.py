"""The ``pipe`` shorthand of topology files (``meshgen.geometry.topology_shorthand.expand_pipe``):
5-block O-grid pipes, straight or bent. The bent, tapered one against the same blocks written
out by hand (examples/topologies/elbow-taper-3d.yaml), a straight one against its cylinder and
the closed-form cell count, and the one-line errors."""

from pathlib import Path

import numpy as np
import pytest

from meshgen.errors import GeometryError
from meshgen.geometry.blocks import load_block_set, tfi_blocks

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "topologies"


def test_elbow_shorthand_is_the_hand_written_elbow():
    short = load_block_set(str(EXAMPLES / "elbow-pipe-3d.yaml"), None, (1, 1, 1))
    written = load_block_set(str(EXAMPLES / "elbow-taper-3d.yaml"), None, (1, 1, 1))
    assert short.node_shapes == written.node_shapes
    assert set(short.patches.items()) == set(written.patches.items())
    for X, Y in zip(tfi_blocks(short), tfi_blocks(written)):
        np.testing.assert_allclose(X, Y, atol=2e-9)  # the hand-written file's coordinates have 10 digits


def test_straight_pipe_on_its_cylinder(tmp_path):
    path = tmp_path / "p.yaml"
    path.write_text(
        "pipe: {start: {center: [1, 2, 3], normal: [1, 1, 0], radius: 0.5}, length: 4, core: 0.35,\n"
        "       cells: {tangential: 6, radial: 3, along: 9}, grading: {radial: 0.2}}\n"
    )
    blocks = load_block_set(str(path), None, (1, 1, 1))
    assert sum(int(np.prod([n - 1 for n in s])) for s in blocks.node_shapes) == 9 * (6 * 6 + 4 * 6 * 3)
    axis = np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
    Xs = tfi_blocks(blocks)
    for b in range(1, 5):  # the wall blocks: eta0 on the wall
        offset = Xs[b][:, 0] - np.array([1.0, 2.0, 3.0])
        along = offset @ axis
        np.testing.assert_allclose(np.linalg.norm(offset - along[..., None] * axis, axis=-1), 0.5, rtol=1e-12)
        np.testing.assert_allclose(along[:, -1], 4.0, atol=1e-12)
        radial = np.linalg.norm(np.diff(Xs[b][2, :, 0], axis=0), axis=-1)  # wall -> core
        assert radial[-1] / radial[0] == pytest.approx(5.0, rel=1e-9)
    assert sorted({name for name, _ in blocks.patches.values()}) == ["inlet", "outlet", "walls"]


@pytest.mark.parametrize(
    "entry, said",
    [
        ("start: {center: [0, 0, 0], normal: [0, 1, 0], radius: 1}", "needs one of 'bend'"),
        (
            "start: {center: [0, 0, 0], normal: [0, 1, 0], radius: 1}, length: 2, bend: {center: [2, 0, 0], axis: [0, 0, 1], angle: 90}",
            "needs one of",
        ),
        (
            "start: {center: [0, 0, 0], normal: [1, 0, 0], radius: 1}, bend: {center: [2, 0, 0], axis: [0, 0, 1], angle: 90}",
            "tangent to the bend",
        ),
        (
            "start: {center: [0, 0, 0], normal: [0, 1, 0], radius: 1}, bend: {center: [0.5, 0, 0], axis: [0, 0, 1], angle: 90}",
            "would fold",
        ),
        ("start: {center: [0, 0, 0], normal: [0, 1, 0], radius: 1}, length: 2, core: 0.8", "core must be below"),
        ("start: {center: [0, 0, 0], normal: [0, 1, 0], radius: 1}, length: 2, cells: {along: 2.5}", "whole number"),
        ("start: {center: [0, 0, 0], normal: [0, 1, 0], radius: 1}, lenght: 2", "did you mean 'length'"),
    ],
)
def test_pipe_errors(tmp_path, entry, said):
    path = tmp_path / "p.yaml"
    path.write_text(f"pipe: {{{entry}}}\n")
    with pytest.raises(GeometryError, match=said) as caught:
        load_block_set(str(path), None, (1, 1, 1))
    assert "\n" not in str(caught.value) and ": pipe: " in str(caught.value)

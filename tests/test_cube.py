"""The reference cube's tables against direct enumeration."""

import itertools

import numpy as np
import pytest

from meshgen.geometry import cube


@pytest.mark.parametrize("dim", [2, 3])
def test_faces_select_the_boundary_nodes_of_a_grid(dim):
    shape = (3, 4, 5)[:dim]
    coords = [np.linspace(0, 1, n) for n in shape]
    X = np.stack(np.meshgrid(*coords, indexing="ij"), axis=-1)
    names = []
    for face in cube.faces(dim):
        nodes = X[face.node_index].reshape(-1, dim)
        assert np.all(nodes[:, face.axis] == face.side)
        np.testing.assert_array_equal(nodes, face.points(coords))
        names.append(face.name)
    assert names == list(cube.face_names(dim))
    assert len(set(names)) == 2 * dim
    assert cube.face_named("eta1", dim).axis == 1 and cube.face_named("eta1", dim).side == 1
    with pytest.raises(KeyError):
        cube.face_named("zeta0" if dim == 2 else "chi0", dim)


def test_edges_are_the_twelve_intersections_of_two_faces():
    X = np.stack(np.meshgrid(*[np.linspace(0, 1, 4)] * 3, indexing="ij"), axis=-1)
    seen = set()
    for edge in cube.edges():
        nodes = X[edge.node_index]
        assert nodes.shape == (4, 3)
        for axis, side in zip(edge.axes, edge.sides):
            assert np.all(nodes[:, axis] == side)
        assert np.ptp(nodes[:, edge.free_axis]) == 1.0
        seen.add(edge.name)
    assert len(seen) == 12


@pytest.mark.parametrize("dim", [2, 3])
def test_corners_and_samples(dim):
    assert {tuple(c) for c in cube.corners(dim)} == set(itertools.product((0.0, 1.0), repeat=dim))
    samples = cube.face_samples(dim, 5)
    assert samples.shape == (2 * dim * 5 ** (dim - 1), dim)
    assert np.all(np.any((samples == 0) | (samples == 1), axis=1))

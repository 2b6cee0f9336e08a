"""The compiled face and cell geometry (``meshgen.quality.faces_compiled``) against the NumPy
definition of ``meshgen.quality.faces_openfoam`` (itself held to checkMesh in
``tests/test_checkmesh_non_orthogonality.py``): the same face centres and areas, cell centres to
round-off (the compiled ones from the nodes alone), the internal faces' cosines reduced as NumPy
reduces them, and the same non-orthogonality report on perturbed, left-handed, degenerate and 2D
meshes."""

from __future__ import annotations

import numpy as np
import pytest

from meshgen.quality import faces_compiled, faces_openfoam
from meshgen.quality.faces_openfoam import non_orthogonality
from meshgen.quality.structured import NUMPY_CELLS


def perturbed_box(shape, amplitude, seed=0):
    """Nodes of a box grid of ``shape`` nodes, each moved at random by up to ``amplitude`` (N(0, a))."""
    grid = np.stack(np.meshgrid(*[np.linspace(0.0, 1.0 + 0.3 * axis, n) for axis, n in enumerate(shape)], indexing="ij"), -1)
    return grid + np.random.default_rng(seed).normal(0.0, amplitude, grid.shape)


def assert_same_report(ours: dict, reference: dict) -> None:
    for family in ("non_orthogonality_internal", "non_orthogonality_boundary"):
        got, expected = ours[family], reference[family]
        assert got["faces"] == expected["faces"] and got["worst_face"] == expected["worst_face"]
        assert got["max"] == pytest.approx(expected["max"], abs=1e-9)
        assert got["average"] == pytest.approx(expected["average"], abs=1e-9)


MESHES = {
    "perturbed": perturbed_box((7, 8, 9), 0.02),
    "strongly perturbed": perturbed_box((6, 5, 7), 0.06, seed=3),
    "left-handed": perturbed_box((7, 8, 9), 0.02)[:, :, ::-1],
    "thin": perturbed_box((2, 9, 3), 0.01, seed=5),
    # 13 layers of cells: tasks of faces_compiled.CHUNK_LAYERS layers meet three times
    "long": perturbed_box((14, 5, 6), 0.03, seed=7),
}


@pytest.mark.parametrize("name", sorted(MESHES))
def test_faces_and_cells_are_the_numpy_definitions(name):
    X = MESHES[name]
    faces = [faces_openfoam.face_centres_and_areas(X, axis) for axis in range(3)]
    compiled = [faces_compiled.face_centres_and_areas(X, axis) for axis in range(3)]
    for (centres, areas), (our_centres, our_areas) in zip(faces, compiled):
        # The same operations in the same order: equal to the last bit.
        assert np.array_equal(our_centres, centres) and np.array_equal(our_areas, areas)
    expected = faces_openfoam.cell_centres(X, faces)
    assert np.abs(faces_compiled.cell_centres(X) - expected).max() <= 1e-14 * np.abs(expected).max()


@pytest.mark.parametrize("name", sorted(MESHES))
def test_internal_faces_reduced_as_numpy_reduces_their_cosines(name):
    """The compiled reduction (sum, count, least and where) of the internal faces' cosines against
    the NumPy definition's array of them reduced by NumPy."""
    X = MESHES[name]
    faces = [faces_openfoam.face_centres_and_areas(X, axis) for axis in range(3)]
    sign = faces_openfoam._orientation(faces)
    C = faces_openfoam.cell_centres(X, faces, sign)
    for axis, (_, areas) in enumerate(faces):
        cosines = faces_openfoam._angles(
            faces_openfoam._along(C, axis, 1, None) - faces_openfoam._along(C, axis, 0, -1),
            sign * faces_openfoam._along(areas, axis, 1, -1),
        )
        total, count, least, where = faces_compiled.cells_and_internal_cosines(X, sign)[1][axis]
        if not cosines.size:  # one cell along the axis
            assert (total, count, least, where) == (0.0, 0, None, None)
            continue
        assert count == cosines.size and total == pytest.approx(cosines.sum(), rel=1e-12)
        assert least == pytest.approx(cosines.min(), abs=1e-14)
        assert cosines[where] == pytest.approx(least, abs=1e-14)


def test_a_nan_cosine_is_the_least_where_the_first_nan_lies():
    """As ``np.min`` and ``np.argmin``: a NaN cosine (a non-finite node) is the least, the first NaN
    in C order its index."""
    X = perturbed_box((6, 7, 8), 0.02)
    X[3, 4, 5] = np.nan
    for axis in range(3):
        total, count, least, where = faces_compiled.cells_and_internal_cosines(X, 1.0)[1][axis]
        cells = np.zeros((5, 6, 7), dtype=bool)  # the cells of the node (3, 4, 5)
        cells[2:4, 3:5, 4:6] = True
        nan = faces_openfoam._along(cells, axis, 1, None) | faces_openfoam._along(cells, axis, 0, -1)
        assert np.isnan(total) and np.isnan(least) and count == nan.size
        assert where == np.unravel_index(int(np.argmax(nan)), nan.shape)


def test_no_internal_faces_along_a_one_cell_axis():
    X = perturbed_box((2, 5, 6), 0.01)
    assert faces_compiled.cells_and_internal_cosines(X, 1.0)[1][0] == (0.0, 0, None, None)


@pytest.mark.parametrize("name", sorted(MESHES))
def test_non_orthogonality_report_is_the_numpy_one(name):
    X = MESHES[name]
    assert_same_report(non_orthogonality(X, kernels="compiled"), non_orthogonality(X, kernels="numpy"))


def test_degenerate_faces_and_cells_take_the_numpy_fallbacks():
    X = perturbed_box((5, 6, 7), 0.02)
    X[2, 3, :] = X[2, 2, :]  # faces of zero area along a line of nodes: centre = mean of the corners
    X[1:3, 1, 1] = X[1, 1, 1]
    for axis in range(3):
        centres, areas = faces_openfoam.face_centres_and_areas(X, axis)
        our_centres, our_areas = faces_compiled.face_centres_and_areas(X, axis)
        assert np.array_equal(our_centres, centres) and np.array_equal(our_areas, areas)
    assert_same_report(non_orthogonality(X, kernels="compiled"), non_orthogonality(X, kernels="numpy"))


def test_two_d_meshes_are_measured_extruded_by_both():
    X = perturbed_box((9, 7), 0.02, seed=2)
    ours, reference = non_orthogonality(X, kernels="compiled"), non_orthogonality(X, kernels="numpy")
    assert_same_report(ours, reference)
    assert reference["non_orthogonality_internal"]["faces"] == 7 * 6 + 8 * 5  # in-plane faces only


def test_auto_picks_by_mesh_size(monkeypatch):
    calls = []
    original = faces_compiled.cells_and_internal_cosines
    monkeypatch.setattr(faces_compiled, "cells_and_internal_cosines", lambda *a: calls.append(1) or original(*a))
    X = perturbed_box((5, 5, 5), 0.01)
    non_orthogonality(X)  # 64 cells: NumPy
    assert not calls
    monkeypatch.setattr(faces_openfoam, "use_compiled", lambda cells, kernels: cells >= 64)
    non_orthogonality(X)
    assert calls and NUMPY_CELLS > 64

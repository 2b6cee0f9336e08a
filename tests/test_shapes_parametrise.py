"""Patches onto the unit square (meshgen.geometry.shapes.parametrise): one-to-one on random patches with
ears, corners and sides where they belong, planar maps reproduced, holes and handles refused."""

import numpy as np
import pytest
from scipy.spatial import Delaunay
from shape_helpers import random_patch

from meshgen.errors import GeometryError
from meshgen.geometry.shapes.parametrise import SQUARE_CORNERS, parametrise, signed_areas


@pytest.mark.parametrize("seed", range(20))
def test_random_patches_fold_over_nowhere(seed):
    vertices, triangles, corners = random_patch(2000, seed)
    patch = parametrise(vertices, triangles, corners)
    areas = signed_areas(patch.uv, patch.triangles)
    assert len(patch.triangles) > len(triangles)  # the ears were split
    assert areas.min() > 0  # every triangle keeps its orientation: no foldover
    assert abs(areas.sum() - 1.0) < 1e-12  # and together they tile the square once
    assert np.array_equal(patch.uv[list(corners)], SQUARE_CORNERS)
    for k, chain in enumerate(patch.sides):  # each side spaced by its own arc length
        steps = np.linalg.norm(np.diff(vertices[chain], axis=0), axis=1)
        fraction = np.concatenate([[0.0], np.cumsum(steps)]) / steps.sum()
        expected = SQUARE_CORNERS[k] + fraction[:, None] * (SQUARE_CORNERS[(k + 1) % 4] - SQUARE_CORNERS[k])
        assert np.allclose(patch.uv[chain], expected, atol=1e-14)


def planar_square(n=12, seed=0):
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, n + 1)
    sides = np.concatenate(
        [
            np.column_stack([t[:-1], 0 * t[:-1]]),
            np.column_stack([1 + 0 * t[:-1], t[:-1]]),
            np.column_stack([1 - t[:-1], 1 + 0 * t[:-1]]),
            np.column_stack([0 * t[:-1], 1 - t[:-1]]),
        ]
    )
    xy = np.concatenate([sides, rng.uniform(0.05, 0.95, (n * n, 2))])
    triangles = Delaunay(xy).simplices
    return xy, triangles, [0, n, 2 * n, 3 * n]


def test_a_flat_square_maps_onto_itself():
    # Mean-value weights reproduce linear functions: a flat unit square is its own parametrisation.
    xy, triangles, corners = planar_square()
    patch = parametrise(np.column_stack([xy, np.zeros(len(xy))]), triangles, corners)
    assert np.abs(patch.uv - xy).max() < 1e-12


def test_corners_given_the_other_way_round_reverse_the_square():
    xy, triangles, corners = planar_square()
    patch = parametrise(np.column_stack([xy, np.zeros(len(xy))]), triangles, corners[::-1])
    # (0,1), (1,1), (1,0), (0,0) go to (0,0), (1,0), (1,1), (0,1): the map (x, y) -> (x, 1 - y)
    assert np.abs(patch.uv - np.column_stack([xy[:, 0], 1 - xy[:, 1]])).max() < 1e-12
    assert signed_areas(patch.uv, patch.triangles).min() > 0


def test_a_patch_with_a_hole_is_refused():
    xy, triangles, corners = planar_square()
    centres = xy[triangles].mean(axis=1)
    keep = np.linalg.norm(centres - 0.5, axis=1) > 0.2
    with pytest.raises(GeometryError, match="hole: 2 boundary loops"):
        parametrise(np.column_stack([xy, np.zeros(len(xy))]), triangles[keep], corners)


def test_a_patch_with_a_handle_is_refused():
    # A grid on a square whose two middle columns are glued: a torus-like handle, one boundary loop.
    n = 6
    index = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    quads = np.stack([index[:-1, :-1], index[1:, :-1], index[1:, 1:], index[:-1, 1:]], -1).reshape(-1, 4)
    triangles = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    # a tube: cut a hole at two places and join them by a cylinder of triangles
    holes = [(1, 1), (1, 4)]
    cells = [q for q in range(len(quads)) if (q // n, q % n) not in holes]
    kept = np.concatenate([quads[cells][:, [0, 1, 2]], quads[cells][:, [0, 2, 3]]])
    ring_a = index[[1, 2, 2, 1], [1, 1, 2, 2]]
    ring_b = index[[1, 2, 2, 1], [5, 5, 4, 4]]
    tube = np.concatenate(
        [[[ring_a[k], ring_b[k], ring_b[(k + 1) % 4]], [ring_a[k], ring_b[(k + 1) % 4], ring_a[(k + 1) % 4]]] for k in range(4)]
    )
    xy = np.stack(np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij"), -1).reshape(-1, 2) / n
    vertices = np.column_stack([xy, np.zeros(len(xy))])
    corners = [index[0, 0], index[n, 0], index[n, n], index[0, n]]
    del triangles
    for orientation in (tube, tube[:, ::-1]):
        try:
            parametrise(vertices, np.concatenate([kept, orientation]), corners)
        except GeometryError as exc:
            if "handle" in str(exc):
                return
    pytest.fail("a patch with a handle was accepted")

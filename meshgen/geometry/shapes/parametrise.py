"""A triangulated patch with four corners onto the unit square (design notes, shapes from files).

The patch must be a topological disk (one boundary loop, Euler characteristic 1). Its four
corners go to the square's corners, each of its four sides to a side of the square spaced by arc
length, and every interior vertex to the weighted mean of its neighbours with Floater's
mean-value weights (positive for any triangle star, and reproducing planar maps). Tutte's and
Floater's theorem: positive weights and a convex boundary give a one-to-one map, provided no
interior edge joins two vertices of the same side ("dividing" edges: they would flatten the
triangles beside them onto the side). Such edges are split at their midpoints first, which
leaves the surface unchanged. One sparse LU factorisation, one solve per coordinate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshgen.errors import GeometryError

__all__ = [
    "PatchMap",
    "boundary_loops",
    "check_disk",
    "edge_table",
    "mean_value_matrix",
    "parametrise",
    "signed_areas",
    "SQUARE_CORNERS",
]

SQUARE_CORNERS = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])  # counter-clockwise


@dataclass(frozen=True)
class PatchMap:
    """A patch parametrised onto the unit square: ``vertices`` (n, 3) (the patch's own, plus the
    midpoints of split dividing edges), ``triangles`` (m, 3) oriented counter-clockwise in the
    square, ``uv`` (n, 2) the square's coordinates of each vertex, ``corners`` the four corner
    vertex indices at (0, 0), (1, 0), (1, 1), (0, 1), ``sides`` the four vertex chains from
    corner k to corner k + 1 (corners included)."""

    vertices: np.ndarray
    triangles: np.ndarray
    uv: np.ndarray
    corners: tuple
    sides: tuple


def signed_areas(uv: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Signed areas (m,) of the triangles (m, 3) over 2D points ``uv`` (n, 2); positive when
    counter-clockwise."""
    a, b, c = (uv[triangles[:, k]] for k in range(3))
    return 0.5 * ((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0]))


def edge_table(triangles: np.ndarray):
    """The triangles' edges: ``directed`` (3m, 2) in triangle order (edge k of triangle t at row
    k * m + t), ``key`` (3m,) one integer per undirected edge, ``count`` (3m,) how many triangles
    hold that undirected edge; ``edges`` the number of undirected edges."""
    directed = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    n = int(triangles.max()) + 1
    key = np.minimum(directed[:, 0], directed[:, 1]) * n + np.maximum(directed[:, 0], directed[:, 1])
    _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    return directed, key, counts[inverse], len(counts)


def boundary_loops(triangles: np.ndarray, what: str = "patch", table=None) -> list[np.ndarray]:
    """The boundary loops of an oriented triangle set, each an array of vertex indices in the
    direction of the triangles' orientation. GeometryError at a vertex with two boundary edges
    leaving it (two sheets touching at a point)."""
    directed, _, count, _ = table if table is not None else edge_table(triangles)
    edges = directed[count == 1]
    if len(edges) == 0:
        return []
    starts, counts = np.unique(edges[:, 0], return_counts=True)
    if np.any(counts > 1):
        raise GeometryError(f"{what}: two boundary edges leave the vertex {int(starts[counts > 1][0])} (sheets touch at a point)")
    following = dict(zip(edges[:, 0].tolist(), edges[:, 1].tolist()))
    loops, seen = [], set()
    for start in edges[:, 0].tolist():
        if start in seen:
            continue
        loop, vertex = [], start
        while vertex not in seen:
            seen.add(vertex)
            loop.append(vertex)
            vertex = following.get(vertex)
            if vertex is None:
                raise GeometryError(f"{what}: its boundary is not a closed loop (the triangles are not consistently oriented)")
        loops.append(np.array(loop))
    return loops


def check_disk(triangles: np.ndarray, what: str = "patch", table=None) -> np.ndarray:
    """The single boundary loop of a patch that is a topological disk; GeometryError for a patch
    with a hole (several loops), a handle (Euler characteristic below 1) or no boundary."""
    table = table if table is not None else edge_table(triangles)
    loops = boundary_loops(triangles, what, table)
    if len(loops) == 0:
        raise GeometryError(f"{what} has no boundary: it is a closed surface, not a four-cornered face")
    if len(loops) > 1:
        raise GeometryError(f"{what} has a hole: {len(loops)} boundary loops, a face needs exactly one")
    used = np.count_nonzero(np.bincount(triangles.ravel()))
    euler = used - table[3] + len(triangles)
    if euler != 1:
        raise GeometryError(f"{what} has a handle: Euler characteristic {euler} (a disk has 1; genus {(1 - euler) // 2})")
    return loops[0]


def mean_value_matrix(vertices: np.ndarray, triangles: np.ndarray):
    """Floater's mean-value weights as a sparse (n, n) matrix W: W[i, j] = (tan(a/2) + tan(b/2))
    / |x_i - x_j|, a and b the angles at vertex i of the two triangles beside edge ij (3D angles,
    so the weights are positive whatever the surface's shape)."""
    from scipy import sparse

    rows, cols, values = [], [], []
    for k in range(3):
        i, j, o = triangles[:, k], triangles[:, (k + 1) % 3], triangles[:, (k + 2) % 3]
        e1, e2 = vertices[j] - vertices[i], vertices[o] - vertices[i]
        n1, n2 = np.linalg.norm(e1, axis=1), np.linalg.norm(e2, axis=1)
        cross = np.linalg.norm(np.cross(e1, e2), axis=1)
        half_tan = cross / np.maximum(n1 * n2 + (e1 * e2).sum(1), 1e-300)  # tan(angle / 2)
        rows += [i, i]
        cols += [j, o]
        values += [half_tan / np.maximum(n1, 1e-300), half_tan / np.maximum(n2, 1e-300)]
    n = len(vertices)
    return sparse.csr_matrix((np.concatenate(values), (np.concatenate(rows), np.concatenate(cols))), shape=(n, n))


def _oriented_corners(loop: np.ndarray, corners, what: str) -> tuple[np.ndarray, list[int]]:
    """The loop turned (reversed if needed) so that the corners come in the order given; with
    the positions of the corners in it."""
    position = {v: k for k, v in enumerate(loop.tolist())}
    missing = [c for c in corners if c not in position]
    if missing:
        raise GeometryError(f"{what}: corner vertex {missing[0]} is not on the patch's boundary")
    places = [position[c] for c in corners]
    n = len(loop)
    forward = all((places[(k + 1) % 4] - places[k]) % n < (places[(k + 2) % 4] - places[k]) % n for k in range(4))
    if not forward:
        loop = loop[::-1].copy()
        position = {v: k for k, v in enumerate(loop.tolist())}
        places = [position[c] for c in corners]
        if not all((places[(k + 1) % 4] - places[k]) % n < (places[(k + 2) % 4] - places[k]) % n for k in range(4)):
            raise GeometryError(f"{what}: its four corners are not in boundary order")
    return loop, places


def _side_chains(loop: np.ndarray, places: list[int]) -> list[np.ndarray]:
    n = len(loop)
    chains = []
    for k in range(4):
        start, stop = places[k], places[(k + 1) % 4]
        count = (stop - start) % n
        chains.append(loop[(start + np.arange(count + 1)) % n])
    return chains


def _arc_fraction(points: np.ndarray) -> np.ndarray:
    length = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    if not length[-1] > 0:
        raise GeometryError("a side of a patch has zero length")
    return length / length[-1]


def _split_dividing_edges(vertices, triangles, side_sets, table):
    """Split at its midpoint every interior edge whose two ends lie on one side of the square
    (``side_sets``: the vertex chain of each side, corners in two). Returns new arrays."""
    membership = np.zeros((len(vertices), 4), dtype=bool)
    for k, side in enumerate(side_sets):
        membership[side, k] = True
    directed, key, count, _ = table
    candidates = (count == 2) & np.any(membership[directed[:, 0]] & membership[directed[:, 1]], axis=1)
    _, first = np.unique(key[candidates], return_index=True)
    dividing = directed[candidates][first]
    if len(dividing) == 0:
        return vertices, triangles
    # The triangles around each vertex, to look an edge's two triangles up without a full scan;
    # triangles made by earlier splits are searched too.
    order = np.argsort(triangles.ravel(), kind="stable")
    starts = np.searchsorted(triangles.ravel()[order], np.arange(len(vertices) + 1))
    triangles = triangles.copy()
    original = len(triangles)
    added: list[list[int]] = []  # triangles made by the splits, numbered from original on
    new_points = []
    for a, b in dividing.tolist():
        m = len(vertices) + len(new_points)
        new_points.append(0.5 * (vertices[a] + vertices[b]))
        around = (order[starts[a] : starts[a + 1]] // 3).tolist() + list(range(original, original + len(added)))
        for t in around:
            tri = triangles[t].tolist() if t < original else added[t - original]
            if a not in tri or b not in tri:
                continue
            while {tri[0], tri[1]} != {a, b}:  # rotate: the edge first, in the triangle's own order
                tri = tri[1:] + tri[:1]
            p, q, r = tri
            if t < original:
                triangles[t] = (p, m, r)
            else:
                added[t - original] = [p, m, r]
            added.append([m, q, r])
    triangles = np.concatenate([triangles, np.array(added, dtype=np.int64).reshape(-1, 3)])
    return np.concatenate([vertices, np.array(new_points)]), triangles


def parametrise(vertices: np.ndarray, triangles: np.ndarray, corners, what: str = "patch") -> PatchMap:
    """Map a disk-like patch onto the unit square (module docstring).

    ``vertices`` (n, 3) float, ``triangles`` (m, 3) int (consistently oriented, unused vertices
    allowed), ``corners``: four vertex indices on the patch's boundary, to go to (0, 0), (1, 0),
    (1, 1), (0, 1) in this order (either direction round the boundary). GeometryError for a patch
    that is not a disk or whose corners are not on its boundary in order.
    """
    from scipy.sparse.linalg import splu

    vertices = np.asarray(vertices, dtype=float)
    triangles = np.asarray(triangles, dtype=np.int64)
    corners = [int(c) for c in corners]
    if len(set(corners)) != 4:
        raise GeometryError(f"{what}: needs four distinct corners, got {corners}")
    table = edge_table(triangles)
    loop = check_disk(triangles, what, table)
    loop, places = _oriented_corners(loop, corners, what)
    chains = _side_chains(loop, places)
    reversed_loop = _loop_direction_reversed(triangles, loop)
    if reversed_loop:
        triangles = triangles[:, ::-1].copy()  # the triangles now run the way the loop does
    vertices, triangles = _split_dividing_edges(vertices, triangles, chains, table)
    n = len(vertices)
    uv = np.full((n, 2), np.nan)
    for k, chain in enumerate(chains):
        s = _arc_fraction(vertices[chain])
        start, stop = SQUARE_CORNERS[k], SQUARE_CORNERS[(k + 1) % 4]
        uv[chain] = start + s[:, None] * (stop - start)
    for k, corner in enumerate(corners):
        uv[corner] = SQUARE_CORNERS[k]
    on_boundary = np.zeros(n, dtype=bool)
    on_boundary[np.concatenate(chains)] = True
    used = np.zeros(n, dtype=bool)
    used[triangles.ravel()] = True
    inner = np.flatnonzero(used & ~on_boundary)
    if len(inner):
        W = mean_value_matrix(vertices, triangles)
        degree = np.asarray(W.sum(axis=1)).ravel()
        from scipy import sparse

        W_inner = W[inner]
        system = (sparse.diags(degree[inner]) - W_inner[:, inner]).tocsc()
        rhs = W_inner[:, np.flatnonzero(on_boundary)] @ uv[on_boundary]
        factor = splu(system)
        uv[inner] = np.column_stack([factor.solve(np.ascontiguousarray(rhs[:, c])) for c in range(2)])
    uv[~used] = 0.0
    return PatchMap(vertices, triangles, uv, tuple(corners), tuple(chains))


def _loop_direction_reversed(triangles: np.ndarray, loop: np.ndarray) -> bool:
    """True when the triangles' orientation runs the boundary ``loop`` backwards."""
    a, b = int(loop[0]), int(loop[1])
    directed = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    return not bool(np.any((directed[:, 0] == a) & (directed[:, 1] == b)))

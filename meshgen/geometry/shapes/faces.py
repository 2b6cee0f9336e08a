"""Six four-cornered patches as the six faces of the unit cube, and the boundary map they make.

Topology: two patches are opposite when they share no corner; a block needs six patches of four
corners each, eight corners in all, each corner in three patches, each patch with one opposite.

Face assignment (automatic, unless given): the zeta pair is the opposite pair of smallest total
area (the ends of a duct), zeta0 the one of them that comes first (file order); xi0 is the first
remaining patch, xi1 its opposite; the last pair goes on eta0 and eta1 so that the map is
right-handed (the boundary, oriented by the cube's outward normals, encloses a positive volume).
Each cube corner is then the one corner the three patches of its faces share.

The boundary map evaluates a point of the cube's boundary by the piece it lies on, told by its
exact 0/1 coordinates: a corner gives its corner point, an edge its edge curve (one function per
edge, shared by its two faces, so they agree bit for bit), a face its face map.
"""

from __future__ import annotations

import itertools

import numpy as np

from meshgen.errors import GeometryError
from meshgen.geometry import cube

__all__ = [
    "FACE_NAMES",
    "OPPOSITE",
    "BoundaryPieces",
    "assign_faces",
    "faces_from_corners",
    "corner_of_cube",
    "face_corners",
    "edge_ends",
    "signed_volume",
]

FACE_NAMES = cube.face_names(3)
SWEEP_HINT = (
    "a prism or a bend, two planar caps, one the other moved along a line or turned about an axis, the sides the "
    "outline's sweep, is cut into blocks; lofts and other sweeps from their CAD file: STEP, IGES or BREP, "
    "docs/shapes-from-files.md; else describe its blocks in a topology file, docs/topologies.md"
)
OPPOSITE = {name: name[:-1] + ("1" if name.endswith("0") else "0") for name in FACE_NAMES}


def _check_block(corner_sets: list[set], names, what: str) -> None:
    counts = [len(c) for c in corner_sets]
    if len(corner_sets) != 6 or any(c != 4 for c in counts):
        listed = ", ".join(f"{n}: {c}" for n, c in zip(names, counts))
        raise GeometryError(
            f"{what} splits into {len(corner_sets)} patch(es) with corners ({listed}); a block needs six patches of four "
            f"corners each ({SWEEP_HINT})"
        )
    everything = set().union(*corner_sets)
    in_patches = {v: sum(v in c for c in corner_sets) for v in everything}
    if len(everything) != 8 or any(k != 3 for k in in_patches.values()):
        raise GeometryError(
            f"{what}: its six patches meet at {len(everything)} corner(s), not at eight corners of three patches each"
        )
    for p, corners in enumerate(corner_sets):
        opposite = [q for q in range(6) if q != p and not (corners & corner_sets[q])]
        if len(opposite) != 1:
            raise GeometryError(f"{what}: patch '{names[p]}' has {len(opposite)} opposite patch(es); a block face has one")


def assign_faces(corner_sets: list[set], areas, names, what: str, given: dict | None = None) -> dict[str, int]:
    """Cube face name -> patch index (module docstring's rule, or ``given``: face -> patch name,
    all six faces, opposite patches on opposite faces). The eta pair is put in an arbitrary
    order; the caller orients it (``signed_volume``) unless it was given."""
    _check_block(corner_sets, names, what)
    opposite_of = {p: next(q for q in range(6) if q != p and not (corner_sets[p] & corner_sets[q])) for p in range(6)}
    if given:
        missing = [f for f in FACE_NAMES if f not in given]
        unknown = [n for n in given.values() if n not in names]
        if missing or unknown or set(given) - set(FACE_NAMES):
            problem = (
                f"no patch for {', '.join(missing)}"
                if missing
                else f"unknown patch '{unknown[0]}'"
                if unknown
                else "unknown face"
            )
            raise GeometryError(f"{what}: face assignment: {problem} (faces {', '.join(FACE_NAMES)}; patches {', '.join(names)})")
        assignment = {face: list(names).index(given[face]) for face in FACE_NAMES}
        if len(set(assignment.values())) != 6:
            raise GeometryError(f"{what}: face assignment puts one patch on two faces")
        for face in ("xi0", "eta0", "zeta0"):
            if opposite_of[assignment[face]] != assignment[OPPOSITE[face]]:
                raise GeometryError(
                    f"{what}: face assignment puts '{names[assignment[face]]}' and '{names[assignment[OPPOSITE[face]]]}' on "
                    f"opposite faces {face} and {OPPOSITE[face]}, but the patches are neighbours"
                )
        return assignment
    pairs = sorted({tuple(sorted((p, q))) for p, q in opposite_of.items()})
    zeta = min(pairs, key=lambda pair: (areas[pair[0]] + areas[pair[1]], pair))
    rest = [p for p in range(6) if p not in zeta]
    xi0 = rest[0]
    eta = [p for p in rest if p not in (xi0, opposite_of[xi0])]
    return {"xi0": xi0, "xi1": opposite_of[xi0], "eta0": eta[0], "eta1": eta[1], "zeta0": zeta[0], "zeta1": zeta[1]}


def faces_from_corners(corner_sets: list[set], positions: dict, given, names, what: str) -> dict[str, str]:
    """Face name -> patch name from the eight corner points ``given`` (8, 3), listed at the cube's
    corners (xi, eta, zeta) in (0,0,0), (0,0,1), (0,1,0), ... order: each snaps to the nearest corner
    vertex (``positions``: corner id -> (3,) point), within 1e-6 of the corners' extent."""
    given = np.asarray(given, dtype=float)
    ids = sorted(set().union(*corner_sets))
    points = np.array([positions[i] for i in ids])
    size = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0))) or 1.0
    chosen = []
    for ijk, point in zip(itertools.product((0, 1), repeat=3), given):
        distance = np.linalg.norm(points - point, axis=1)
        nearest = int(np.argmin(distance))
        if distance[nearest] > 1e-6 * size:
            where = ", ".join(f"{c:.6g}" for c in point)
            raise GeometryError(
                f"{what}: corner {ijk} ({where}) is no corner of the patches (nearest at distance {distance[nearest]:.3g})"
            )
        chosen.append(ids[nearest])
    if len(set(chosen)) != 8:
        raise GeometryError(f"{what}: two of the eight corners given are the same corner vertex")
    by_cube = dict(zip(itertools.product((0, 1), repeat=3), chosen))
    faces = {}
    for face in cube.faces(3):
        wanted = {v for ijk, v in by_cube.items() if ijk[face.axis] == face.side}
        patch = next((p for p, corners in enumerate(corner_sets) if corners == wanted), None)
        if patch is None:
            raise GeometryError(f"{what}: the corners given for face {face.name} are not the four corners of one patch")
        faces[face.name] = names[patch]
    return faces


def swap_eta(assignment: dict[str, int]) -> dict[str, int]:
    return {**assignment, "eta0": assignment["eta1"], "eta1": assignment["eta0"]}


def corner_of_cube(assignment: dict[str, int], corner_sets: list[set], what: str) -> dict[tuple, int]:
    """Cube corner (i, j, k) in {0, 1}^3 -> the corner id the three patches there share."""
    corners = {}
    for ijk in itertools.product((0, 1), repeat=3):
        shared = set.intersection(*(corner_sets[assignment[f"{axis}{side}"]] for axis, side in zip(cube.AXIS_NAMES, ijk)))
        if len(shared) != 1:
            raise GeometryError(f"{what}: the patches on the faces at cube corner {ijk} share {len(shared)} corners, not one")
        corners[ijk] = shared.pop()
    return corners


def face_corners(face: cube.Face, corners: dict[tuple, int]) -> list[int]:
    """The corner ids of ``face`` at (t_a, t_b) = (0, 0), (1, 0), (1, 1), (0, 1), (a, b) its
    tangent axes in increasing order."""
    a, b = face.tangent_axes
    ids = []
    for ta, tb in ((0, 0), (1, 0), (1, 1), (0, 1)):
        ijk = [0, 0, 0]
        ijk[face.axis], ijk[a], ijk[b] = face.side, ta, tb
        ids.append(corners[tuple(ijk)])
    return ids


def edge_ends(edge: cube.Edge, corners: dict[tuple, int]) -> tuple[int, int]:
    """The corner ids at the ends of a cube edge: free coordinate 0, then 1."""
    ends = []
    for t in (0, 1):
        ijk = [0, 0, 0]
        ijk[edge.axes[0]], ijk[edge.axes[1]], ijk[edge.free_axis] = edge.sides[0], edge.sides[1], t
        ends.append(corners[tuple(ijk)])
    return ends[0], ends[1]


class BoundaryPieces:
    """The boundary map of the cube from its pieces: ``faces[name]`` maps (N, 2) tangent
    coordinates (t_a, t_b) to (N, 3) points, ``edges[name]`` (N,) free coordinates to (N, 3),
    ``corners[(i, j, k)]`` a (3,) point. ``reflect_eta``: evaluate at eta -> 1 - eta (how an
    automatic assignment is made right-handed without redoing the faces). ``content_hash``
    identifies the source (files and options) for the layout cache."""

    def __init__(self, faces, edges, corners, reflect_eta: bool = False, content_hash: str = "", what: str = "geometry"):
        self.faces, self.edges, self.corners = faces, edges, corners
        self.reflect_eta = reflect_eta
        self.content_hash = content_hash
        self.what = what
        self.face_lines: tuple[str, ...] = ()  # "xi0 <- name (type)" per face, for the user
        self.surface_faces = None  # a triangulated surface's (vertices, triangles, cube face per triangle)

    def __call__(self, points, **_values):
        points = np.array(points, dtype=float)
        if self.reflect_eta:
            points[:, 1] = 1.0 - points[:, 1]
        on_side = (points == 0.0) | (points == 1.0)
        count = on_side.sum(axis=1)
        if np.any(count == 0):
            raise GeometryError(f"{self.what}: boundary points must lie on the unit cube's boundary")
        out = np.empty_like(points)
        corner_rows = np.flatnonzero(count == 3)
        for ijk, point in self.corners.items():
            rows = corner_rows[np.all(points[corner_rows] == np.array(ijk, dtype=float), axis=1)]
            out[rows] = point
        for edge in cube.edges():
            (a, b), (sa, sb) = edge.axes, edge.sides
            rows = np.flatnonzero((count == 2) & (points[:, a] == sa) & (points[:, b] == sb))
            if len(rows):
                out[rows] = self.edges[edge.name](points[rows, edge.free_axis])
        for face in cube.faces(3):
            rows = np.flatnonzero((count == 1) & (points[:, face.axis] == face.side))
            if len(rows):
                out[rows] = self.faces[face.name](points[rows][:, list(face.tangent_axes)])
        return out


def signed_volume(boundary, n: int = 12) -> float:
    """The volume the image of the cube's boundary encloses, each face triangulated n x n and
    oriented by the cube's outward normal: positive for a right-handed map."""
    t = np.linspace(0.0, 1.0, n + 1)
    index = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    quads = np.stack([index[:-1, :-1], index[1:, :-1], index[1:, 1:], index[:-1, 1:]], -1).reshape(-1, 4)
    triangles = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    volume = 0.0
    for face in cube.faces(3):
        points = boundary(face.points([t, t, t]))
        a, b = face.tangent_axes
        # (e_a x e_b) is +e_axis for xi and zeta faces, -e_eta for the eta faces
        along = 1.0 if (a, b, face.axis) in ((1, 2, 0), (0, 1, 2)) else -1.0
        outward = 1.0 if face.side == 1 else -1.0
        p, q, r = (points[triangles[:, k]] for k in range(3))
        volume += along * outward * float(np.einsum("ij,ij->i", p, np.cross(q, r)).sum()) / 6.0
    return volume

"""A Geometry from a closed triangulated surface (STL, OBJ, PLY): patches, faces, boundary map.

Each of the six patches is parametrised onto its cube face (``parametrise``) with its corners on
the face's corners (kept between runs per file content and assignment: ``cache``); its face map is the piecewise-linear surface over that parametrisation, so
every boundary node lies on a triangle of the surface. Each cube edge is the vertex chain the two
patches share, by arc length from its lower corner.
"""

from __future__ import annotations

import numpy as np

from meshgen.errors import GeometryError
from meshgen.geometry import cube
from meshgen.geometry.shapes.cache import parametrisation_path, read_patch_maps, write_patch_maps
from meshgen.geometry.shapes.faces import (
    FACE_NAMES,
    BoundaryPieces,
    assign_faces,
    corner_of_cube,
    edge_ends,
    face_corners,
    faces_from_corners,
    signed_volume,
    swap_eta,
)
from meshgen.geometry.shapes.locate import build_locator
from meshgen.geometry.shapes.parametrise import parametrise
from meshgen.geometry.shapes.surface_patches import (
    DEFAULT_FEATURE_ANGLE,
    Surface,
    check_closed,
    check_patches_connected,
    patch_corners,
    read_surfaces,
    split_at_sharp_edges,
)

__all__ = ["SurfaceBlock", "surface_block", "surface_pieces"]


class SurfaceBlock:
    """A surface split into six patches assigned to the cube's faces: ``surface`` (labels = patch
    index), ``assignment`` face name -> patch index, ``corners`` cube corner -> vertex index,
    ``pieces`` the boundary map (``faces.BoundaryPieces``)."""

    def __init__(self, surface, assignment, corners, pieces):
        self.surface, self.assignment, self.corners, self.pieces = surface, assignment, corners, pieces

    @property
    def names(self) -> tuple:
        return self.surface.names

    def extent(self) -> tuple[np.ndarray, np.ndarray]:
        """The surface's bounding box: (lowest, highest) corner, each (3,)."""
        return self.surface.vertices.min(axis=0), self.surface.vertices.max(axis=0)

    def face_of_triangle(self) -> np.ndarray:
        """(m,) the cube face index (``meshgen.geometry.cube.faces`` order) of each triangle."""
        face_of_patch = np.empty(6, dtype=np.int64)
        for index, face in enumerate(cube.faces(3)):
            face_of_patch[self.assignment[face.name]] = index
        return face_of_patch[self.surface.labels]


def _patch_area(surface: Surface) -> np.ndarray:
    v, t = surface.vertices, surface.triangles
    area = 0.5 * np.linalg.norm(np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]]), axis=1)
    return np.bincount(surface.labels, weights=area, minlength=len(surface.names))


def surface_pieces(surface: Surface, assignment: dict, what: str, content_hash: str = "") -> tuple[BoundaryPieces, dict]:
    """The boundary map of ``surface`` with patches on the faces as ``assignment`` says."""
    corner_sets = patch_corners(surface)
    corners = corner_of_cube(assignment, corner_sets, what)
    cache = parametrisation_path(content_hash, assignment, corners)
    maps = read_patch_maps(cache, FACE_NAMES)
    if maps is None:
        maps = {}
        for face in cube.faces(3):
            label = assignment[face.name]
            triangles = surface.triangles[surface.labels == label]
            ids = face_corners(face, corners)
            maps[face.name] = parametrise(surface.vertices, triangles, ids, what=f"{what}: patch '{surface.names[label]}'")
        write_patch_maps(cache, maps)
    faces, chains = {}, {}
    for name, patch in maps.items():
        faces[name] = _face_map(build_locator(patch.uv, patch.triangles), patch.vertices)
        for chain in patch.sides:
            chains[(int(chain[0]), int(chain[-1]))] = chain
    edges = {}
    for edge in cube.edges():
        start, stop = edge_ends(edge, corners)
        chain = chains.get((start, stop))
        if chain is None:
            chain = chains[(stop, start)][::-1]
        edges[edge.name] = _edge_map(surface.vertices[chain])
    corner_points = {ijk: surface.vertices[v].copy() for ijk, v in corners.items()}
    return BoundaryPieces(faces, edges, corner_points, content_hash=content_hash, what=what), corners


def _face_map(locator, vertices):
    return lambda uv: locator.evaluate(vertices, uv)


def _edge_map(points: np.ndarray):
    length = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    fraction = length / length[-1]

    def edge(t):
        return np.column_stack([np.interp(t, fraction, points[:, c]) for c in range(3)])

    return edge


def surface_block(
    paths,
    what: str,
    names=None,
    feature_angle: float | None = None,
    given_faces: dict | None = None,
    content_hash: str = "",
    given_corners=None,
) -> SurfaceBlock:
    """Read, check, split and assign a triangulated surface (one file, or one file per patch
    with ``names``); ``given_faces``: face -> patch name, or ``given_corners`` the eight corner
    points (``faces.faces_from_corners``); else the automatic rule."""
    surface = read_surfaces(paths, names)
    check_closed(surface, what)
    if len(surface.names) == 0:
        surface = split_at_sharp_edges(surface, DEFAULT_FEATURE_ANGLE if feature_angle is None else feature_angle)
    check_patches_connected(surface, what)
    corner_sets = patch_corners(surface)
    if given_corners is not None:
        positions = {v: surface.vertices[v] for v in set().union(*corner_sets)}
        given_faces = faces_from_corners(corner_sets, positions, given_corners, surface.names, what)
    assignment = assign_faces(corner_sets, _patch_area(surface), surface.names, what, given_faces)
    pieces, corners = surface_pieces(surface, assignment, what, content_hash)
    volume = signed_volume(pieces)
    if volume < 0:
        if given_faces:
            raise GeometryError(
                f"{what}: the face assignment is left-handed (the mapped cube turns inside out); swap two opposite faces, "
                "e.g. eta0 and eta1"
            )
        assignment = swap_eta(assignment)
        pieces.reflect_eta = True
        corners = {(i, 1 - j, k): v for (i, j, k), v in corners.items()}
    block = SurfaceBlock(surface, assignment, corners, pieces)
    pieces.surface_faces = (surface.vertices, surface.triangles, block.face_of_triangle())
    return block

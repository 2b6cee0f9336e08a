"""An OpenFOAM polyMesh of an unstructured hexahedral mesh (ASCII): the merged mesh of a block set,
whose block interfaces become internal faces.

Faces are found from the cells: each hexahedron's six faces (VTK corner order, normals out of a
positively oriented cell), matched by their sorted node labels; a face met twice is internal
(owner: the lower-numbered cell, its nodes going round as the owner sees them, so the normal points
from owner to neighbour), once is a boundary face, which must be one of the patches'. Internal
faces are in upper-triangular order (by owner, then neighbour), the boundary faces patch by patch.
A 2D mesh is extruded one cell along +z (``extrude_quads``) with the ``empty`` patch
``frontAndBack``, as ``meshgen.formats._openfoam`` does for a single block.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from meshgen.errors import FormatError

__all__ = ["HEX_FACES", "align_cyclic", "extrude_quads", "write_poly_mesh"]

HEX_FACES = np.array([[0, 3, 2, 1], [4, 5, 6, 7], [0, 1, 5, 4], [1, 2, 6, 5], [2, 3, 7, 6], [3, 0, 4, 7]])
BANNER = """/*--------------------------------*- C++ -*----------------------------------*\\\\
  Written by meshgen
\\\\*---------------------------------------------------------------------------*/
FoamFile
{{
    version     2.0;
    format      ascii;
    class       {class_name};
    location    "{location}";
    object      {name};
}}
"""


def extrude_quads(points: np.ndarray, quads: np.ndarray, boundary_edges: list, depth: float | None = None):
    """A 2D mesh (points (N, 2), counterclockwise quads (M, 4)) as one layer of hexahedra of
    thickness ``depth`` (default: sqrt(area / cells)): (points (2N, 3), hexahedra (M, 8), patch
    faces: each (E, 2) array of ``boundary_edges`` as quads, plus the front and back (2M, 4))."""
    n = len(points)
    x, y = points[quads, 0], points[quads, 1]
    area = 0.5 * np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y)
    depth = float(np.sqrt(abs(area) / len(quads))) if depth is None else float(depth)
    points3 = np.zeros((2 * n, 3))
    points3[:n, :2] = points3[n:, :2] = points
    points3[n:, 2] = depth
    hexes = np.concatenate([quads, quads + n], axis=1)
    walls = [np.stack([e[:, 0], e[:, 1], e[:, 1] + n, e[:, 0] + n], axis=1) for e in boundary_edges]
    return points3, hexes, walls, np.concatenate([quads, quads + n]), depth


def _faces(cells: np.ndarray):
    """All cell faces (6M, 4), their cell, and a key per face (sorted labels)."""
    faces = cells[:, HEX_FACES].reshape(-1, 4)
    owner = np.repeat(np.arange(len(cells)), 6)
    return faces, owner, np.sort(faces, axis=1)


def poly_mesh(points, cells, patches):
    """(faces, owner, neighbour, boundary entries (name, type, nFaces, startFace)) of hexahedra
    ``cells`` (M, 8) with ``patches`` a list of (name, type, faces (F, 4) node labels)."""
    faces, owner, keys = _faces(cells)
    _, first, inverse, counts = np.unique(keys, axis=0, return_index=True, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    if np.any(counts > 2):
        raise FormatError("a face is shared by more than two cells: the blocks overlap")
    order = np.argsort(inverse, kind="stable")  # the occurrences of each unique face, together
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    internal = counts == 2
    one, two = order[starts[internal]], order[starts[internal] + 1]  # the lower cell first (stable)
    internal_faces, internal_owner, neighbour = faces[one], owner[one], owner[two]
    sequence = np.lexsort((neighbour, internal_owner))
    internal_faces, internal_owner, neighbour = internal_faces[sequence], internal_owner[sequence], neighbour[sequence]

    boundary_rows = first[~internal]  # a row of ``faces`` for each boundary face
    patch_keys = [np.sort(np.asarray(faces_of_patch), axis=1) for _, _, faces_of_patch in patches]
    together = np.concatenate([keys[boundary_rows], *patch_keys])
    _, which = np.unique(together, axis=0, return_inverse=True)
    which = which.reshape(-1)
    row_of = np.full(which.max() + 1, -1)
    row_of[which[: len(boundary_rows)]] = boundary_rows
    taken = np.zeros(len(keys), dtype=bool)
    all_faces, all_owner, entries = [internal_faces], [internal_owner], []
    start, offset = len(internal_faces), len(boundary_rows)
    for (name, kind, _), patch in zip(patches, patch_keys):
        rows = row_of[which[offset : offset + len(patch)]]
        offset += len(patch)
        if np.any(rows < 0):
            raise FormatError(f"patch '{name}' has a face that is not on the mesh's boundary")
        taken[rows] = True
        all_faces.append(faces[rows])
        all_owner.append(owner[rows])
        entries.append((name, kind, len(rows), start))
        start += len(rows)
    left = np.count_nonzero(~taken[boundary_rows])
    if left:
        raise FormatError(f"{left} boundary face(s) are in no patch")
    return np.concatenate(all_faces), np.concatenate(all_owner), neighbour, entries


def align_cyclic(points3: np.ndarray, faces: np.ndarray, entries: list, pair) -> None:
    """Turn the faces of the cyclic pair ``pair`` (patch a, patch b, R (3, 3), t (3,): b's points
    are a's @ R.T + t), already in matching order, so that each b face starts at the image of its
    a face's first vertex (its others then run backwards, the normals being opposite), as
    OpenFOAM's coupled patches need; in place in ``faces``."""
    a, b, R, t = pair[:4]
    span = {name: slice(first, first + count) for name, _, count, first in entries}
    first, second = faces[span[a]], faces[span[b]]
    target = points3[first[:, 0]] @ np.asarray(R).T + np.asarray(t)
    gaps = np.linalg.norm(points3[second] - target[:, None], axis=2)  # (F, 4): each b vertex to a's first, mapped
    turn = np.argmin(gaps, axis=1)
    faces[span[b]] = np.take_along_axis(second, (turn[:, None] + np.arange(4)) % 4, axis=1)


def write_poly_mesh(folder, points3, cells, patches, cyclic=()) -> None:
    """Write the polyMesh files (ASCII) of hexahedra ``cells`` on ``points3`` (N, 3) with
    ``patches`` [(name, type, faces)] into ``folder`` (a new polyMesh folder, which
    ``meshgen.formats._openfoam.write_case`` swaps in with the case's other files); ``cyclic``:
    [(patch a, patch b, R, t, {patch: the lines its boundary entry adds})] pairs whose faces are
    given in matching order (``align_cyclic``)."""
    faces, owner, neighbour, entries = poly_mesh(points3, cells, patches)
    extras = {}
    for pair in cyclic:
        align_cyclic(points3, faces, entries, pair)
        extras.update(pair[4])
    folder = Path(folder)
    note = f"nPoints:{len(points3)} nCells:{len(cells)} nFaces:{len(faces)} nInternalFaces:{len(neighbour)}"
    _write(folder / "points", "vectorField", "points", points3, "({:.17g} {:.17g} {:.17g})")
    _write(folder / "faces", "faceList", "faces", faces, "4({} {} {} {})")
    _write(folder / "owner", "labelList", "owner", owner, "{}", note)
    _write(folder / "neighbour", "labelList", "neighbour", neighbour, "{}", note)
    lines = [
        BANNER.format(class_name="polyBoundaryMesh", location="constant/polyMesh", name="boundary"),
        f"{len(entries)}\n(\n",
    ]
    for name, kind, count, first in entries:
        group = f"        inGroups        1({kind});\n" if kind in ("wall", "empty", "symmetry", "cyclic") else ""
        more = extras.get(name, "")
        lines.append(
            f"    {name}\n    {{\n        type            {kind};\n{group}        nFaces          {count};\n        startFace       {first};\n{more}    }}\n"
        )
    lines.append(")\n")
    (folder / "boundary").write_text("".join(lines))


def _write(path: Path, class_name: str, name: str, values: np.ndarray, row: str, note: str = "") -> None:
    header = BANNER.format(class_name=class_name, location="constant/polyMesh", name=name)
    if note:
        header = header.replace(f"    object      {name};", f'    note        "{note}";\n    object      {name};')
    values = np.asarray(values)
    spec = row.replace("{:.17g}", "%.17g").replace("{}", "%d") + "\n"
    with open(path, "w") as file:
        file.write(header)
        file.write(f"{len(values)}\n(\n")
        block = 1 << 16
        for first in range(0, len(values), block):
            rows = values[first : first + block]
            file.write((spec * len(rows)) % tuple(rows.reshape(-1).tolist()))
        file.write(")\n")

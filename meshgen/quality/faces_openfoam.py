"""Non-orthogonality as OpenFOAM's ``checkMesh`` defines it, on a structured node array.

OpenFOAM's geometry of a cell (``primitiveMeshFaceCentresAndAreas``, ``...CellCentresAndVols``):

- a face's centre and area vector from its triangle decomposition about the mean of its points:
  triangles (p_m, p_m+1, c0), n_m = (p_m+1 - p_m) x (c0 - p_m); area vector S = sum n_m / 2,
  centre = sum |n_m| (p_m + p_m+1 + c0) / (3 sum |n_m|);
- a cell's centre from its pyramid decomposition about the mean of its face centres c_e: pyramid
  volumes (times 3) v_f = S_f . (x_f - c_e), S_f pointing out of the cell, and centre =
  sum v_f (3/4 x_f + 1/4 c_e) / sum v_f.

Internal faces (``non_orthogonality_internal``): the angle between S and d = C_N - C_P, owner to
neighbour, arccos(d . S / (|d| |S|)), in degrees. checkMesh prints "Mesh non-orthogonality Max:
the largest angle, average: arccos of the mean of the cosines" over the internal faces; this module
gives both the same way. Boundary faces (``non_orthogonality_boundary``, not a checkMesh figure):
the angle between a boundary face's outward S and the vector from its cell's centre to the face
centre. A 2D mesh (n1+1, n2+1, 2) is measured as the writer extrudes it (one cell thick), which
leaves the angles of the in-plane faces unchanged; the front and back faces are left out.
"""

from __future__ import annotations

import numpy as np

from meshgen.quality.structured import use_compiled

__all__ = ["DEFINITIONS", "cell_centres", "face_centres_and_areas", "non_orthogonality", "quad_centres_and_areas"]

DEFINITIONS = {
    "non_orthogonality_internal": (
        "checkMesh's: angle between an internal face's area vector and the owner-to-neighbour cell-centre vector "
        "(OpenFOAM's face triangle and cell pyramid decompositions); max, and average = arccos(mean cosine)"
    ),
    "non_orthogonality_boundary": (
        "angle between a boundary face's outward area vector and the vector from its cell's centre to the face centre"
    ),
}
ROOT_VSMALL = 1e-150  # OpenFOAM's ROOTVSMALL (double), added to |d| |S|


def _face_corners(X: np.ndarray, axis: int) -> list[np.ndarray]:
    """The four corners of every face normal to ``axis`` (the grid's node layer index along
    ``axis``, cell indices along the others), in the cyclic order whose right-hand normal points
    along +``axis`` on a right-handed map: each (.., 3)."""
    first, second = [(1, 2), (2, 0), (0, 1)][axis]

    def shifted(a: int, b: int) -> np.ndarray:
        index = [slice(None)] * 3
        index[first] = slice(a, X.shape[first] - 1 + a)
        index[second] = slice(b, X.shape[second] - 1 + b)
        return X[tuple(index)]

    return [shifted(0, 0), shifted(1, 0), shifted(1, 1), shifted(0, 1)]


def face_centres_and_areas(X: np.ndarray, axis: int) -> tuple[np.ndarray, np.ndarray]:
    """OpenFOAM's face centres and area vectors (module docstring) of the faces normal to ``axis``
    of the 3D node array ``X``: two arrays shaped like the face grid (node layers along ``axis``,
    cells along the others) + (3,); area vectors along +``axis`` for a right-handed map."""
    return quad_centres_and_areas([[np.ascontiguousarray(corner[..., c]) for c in range(3)] for corner in _face_corners(X, axis)])


def quad_centres_and_areas(corners) -> tuple[np.ndarray, np.ndarray]:
    """OpenFOAM's centres and area vectors of quadrilateral faces given as their four corners in
    cyclic order, each corner three component arrays of one shape: (shape + (3,)) twice. Computed
    component by component (plain arrays, no (.., 3) temporaries)."""
    estimate = [0.25 * (corners[0][c] + corners[1][c] + corners[2][c] + corners[3][c]) for c in range(3)]
    shape = estimate[0].shape
    sum_n = [np.zeros(shape) for _ in range(3)]
    sum_a = np.zeros(shape)
    sum_ac = [np.zeros(shape) for _ in range(3)]
    for m in range(4):
        point, following = corners[m], corners[(m + 1) % 4]
        e = [following[c] - point[c] for c in range(3)]
        f = [estimate[c] - point[c] for c in range(3)]
        n = (e[1] * f[2] - e[2] * f[1], e[2] * f[0] - e[0] * f[2], e[0] * f[1] - e[1] * f[0])
        a = np.sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2])
        sum_a += a
        for c in range(3):
            sum_n[c] += n[c]
            sum_ac[c] += a * (point[c] + following[c] + estimate[c])
    centres = np.empty(shape + (3,))
    areas = np.empty(shape + (3,))
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(sum_a > 0, 1.0 / (3.0 * sum_a), 0.0)
    for c in range(3):
        centres[..., c] = np.where(sum_a > 0, sum_ac[c] * scale, estimate[c])
        areas[..., c] = 0.5 * sum_n[c]
    return centres, areas


def _along(array: np.ndarray, axis: int, start: int, stop: int | None) -> np.ndarray:
    index = [slice(None)] * 3
    index[axis] = slice(start, stop)
    return array[tuple(index)]


def cell_centres(X: np.ndarray, faces=None, orientation: float | None = None) -> np.ndarray:
    """OpenFOAM's cell centres (pyramid decomposition, module docstring) of the 3D node array
    ``X``: (n1, n2, n3, 3). ``faces``: the three axes' :func:`face_centres_and_areas` when the
    caller has them; ``orientation``: +1 or -1, the sign of the map's total volume."""
    faces = faces or [face_centres_and_areas(X, axis) for axis in range(3)]
    sign = orientation if orientation is not None else _orientation(faces)
    estimate = sum(_along(c, a, 0, -1) + _along(c, a, 1, None) for a, (c, _) in enumerate(faces)) / 6.0
    volume = np.zeros(estimate.shape[:-1])
    weighted = np.zeros_like(estimate)
    for axis, (centres, areas) in enumerate(faces):
        for side, outward in ((0, -sign), (1, sign)):
            centre = _along(centres, axis, side, None if side else -1)
            area = _along(areas, axis, side, None if side else -1)
            pyramid = outward * np.einsum("...i,...i->...", area, centre - estimate)
            volume += pyramid
            weighted += pyramid[..., None] * (0.75 * centre + 0.25 * estimate)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(np.abs(volume[..., None]) > 1e-300, weighted / volume[..., None], estimate)


def _orientation(faces) -> float:
    """+1 or -1: the sign of the map's total volume (sum over boundary faces of x_f . S_f / 3)."""
    return _orientation_of_sides(_sides(faces))


def _sides(faces):
    """The boundary faces of the three axes' ``faces``: per axis, the (centres, areas) of its first
    and last node layer, that axis dropped (``_boundary_faces``' form)."""
    return [
        [(np.take(centres, side, axis), np.take(areas, side, axis)) for side in (0, centres.shape[axis] - 1)]
        for axis, (centres, areas) in enumerate(faces)
    ]


def _extruded(X: np.ndarray) -> np.ndarray:
    """A 2D node array extruded one unit along +z (angles of in-plane faces do not depend on it)."""
    flat = np.concatenate([X, np.zeros(X.shape[:-1] + (1,))], axis=-1)
    top = flat.copy()
    top[..., 2] = float(np.ptp(X[..., 0]) + np.ptp(X[..., 1])) / max(X.shape[0] + X.shape[1] - 2, 1)
    return np.stack([flat, top], axis=2)


def _angles(d: np.ndarray, S: np.ndarray) -> np.ndarray:
    """cosines of the angle between vectors d and S (.., 3), as OpenFOAM's faceOrthogonality."""
    dot = np.einsum("...i,...i->...", d, S)
    lengths = np.sqrt(np.einsum("...i,...i->...", d, d)) * np.sqrt(np.einsum("...i,...i->...", S, S))
    return dot / (lengths + ROOT_VSMALL)


def non_orthogonality(X: np.ndarray, kernels: str = "auto") -> dict:
    """checkMesh's internal-face non-orthogonality and the boundary-face figure (module docstring)
    of node array ``X`` (3D, or 2D measured extruded). JSON-ready:
    {"non_orthogonality_internal": {"max", "average", "worst_face", "faces"},
    "non_orthogonality_boundary": {"max", "average", "worst_face", "faces"}}, angles in degrees;
    ``worst_face`` {"axis", "index": node layer along the axis and cells along the others}.

    ``kernels``: "numpy" (this module's arithmetic), "compiled" (the same per face and per cell in
    ``meshgen.quality.faces_compiled``, agreeing to round-off) or "auto": compiled from
    ``meshgen.quality.structured.NUMPY_CELLS`` cells up, as the per-cell metrics choose (the mesh's
    size alone decides)."""
    X = np.asarray(X, dtype=float)
    two_d = X.shape[-1] == 2
    X3 = _extruded(X) if two_d else X
    if use_compiled(int(np.prod([n - 1 for n in X3.shape[:-1]])), kernels):
        return _non_orthogonality_compiled(X3, two_d)
    faces = [face_centres_and_areas(X3, axis) for axis in range(3)]
    sign = _orientation(faces)
    C = cell_centres(X3, faces, sign)
    internal = []  # ``_reduced`` cosines, with their axis and index offset along it
    for axis, (_, areas) in enumerate(faces[: 2 if two_d else 3]):
        d = _along(C, axis, 1, None) - _along(C, axis, 0, -1)
        internal.append(_reduced(_angles(d, _along(sign * areas, axis, 1, -1)), axis, 1))
    return {
        "non_orthogonality_internal": _summary(internal),
        "non_orthogonality_boundary": _summary(_boundary_parts(C, _sides(faces), 2 if two_d else 3, sign)),
    }


def _non_orthogonality_compiled(X3: np.ndarray, two_d: bool) -> dict:
    """:func:`non_orthogonality` of the 3D node array ``X3`` with the compiled kernels (``two_d``:
    the front and back faces of an extruded 2D mesh left out): the cell centres from the nodes, the
    internal faces' cosines reduced as they are computed (no face or cosine arrays: at 1e6 cells
    those were 200 MB, and their first touch most of the time), the boundary faces as the NumPy
    definition has them."""
    from meshgen.quality import faces_compiled  # numba

    X3 = np.ascontiguousarray(X3, dtype=np.float64)
    sides = [_boundary_faces(X3, axis) for axis in range(3)]
    sign = _orientation_of_sides(sides)
    C, reduced = faces_compiled.cells_and_internal_cosines(X3, sign)
    return {
        "non_orthogonality_internal": _summary([(*reduced[axis], axis, 1) for axis in range(2 if two_d else 3)]),
        "non_orthogonality_boundary": _summary(_boundary_parts(C, sides, 2 if two_d else 3, sign)),
    }


def _boundary_faces(X: np.ndarray, axis: int):
    """``face_centres_and_areas`` of the two boundary node layers along ``axis`` (first, last),
    each with that axis dropped: [(centres, areas), (centres, areas)], shapes (cells along the
    other two axes) + (3,). NumPy: the compiled kernel's values to the bit (tested), for a few
    layers, without another kernel to load."""
    sides = []
    for layer in (0, X.shape[axis] - 1):
        centres, areas = face_centres_and_areas(np.take(X, [layer], axis=axis), axis)
        sides.append((np.take(centres, 0, axis), np.take(areas, 0, axis)))
    return sides


def _boundary_parts(C: np.ndarray, sides, axes: int, sign: float) -> list[tuple]:
    """``_reduced`` cosines of the boundary faces of the first ``axes`` axes (``sides``: their
    ``_sides`` or ``_boundary_faces``) with cell centres ``C`` and orientation ``sign``: the angle
    between the outward area vector and the vector from the face's cell to its centre."""
    parts = []
    for axis in range(axes):
        last = C.shape[axis]  # the last node layer
        for (centres, areas), outward, cell, side in zip(sides[axis], (-1.0, 1.0), (0, -1), (0, last)):
            cosines = _angles(centres - np.take(C, cell, axis), outward * (sign * areas))
            parts.append(_reduced(np.expand_dims(cosines, axis), axis, side))
    return parts


def _orientation_of_sides(sides) -> float:
    """``_orientation`` from the boundary faces alone: ``sides[axis]`` the (centres, areas) of the
    first and the last node layer along ``axis``, that axis dropped."""
    total = 0.0
    for axis_sides in sides:
        for (centres, areas), sign in zip(axis_sides, (-1.0, 1.0)):
            total += sign * float(np.sum(centres * areas))
    return 1.0 if total >= 0 else -1.0


def _reduced(cosines: np.ndarray, axis: int, offset: int) -> tuple:
    """(sum, count, least, index of the least, axis, offset) of an array of face ``cosines``: the
    form ``_summary`` takes; least and index None when there are none."""
    if not cosines.size:
        return 0.0, 0, None, None, axis, offset
    flat = int(np.argmin(cosines))  # the first NaN, else the first least
    index = tuple(int(i) for i in np.unravel_index(flat, cosines.shape))
    return float(cosines.sum()), int(cosines.size), float(cosines.reshape(-1)[flat]), index, axis, offset


def _summary(parts) -> dict:
    """max angle, arccos(mean cosine), worst face of ``parts`` [(sum, count, least cosine, its
    index, axis, index offset along the axis)]."""
    parts = [p for p in parts if p[1]]
    if not parts:
        return {"max": None, "average": None, "worst_face": None, "faces": 0}
    count = sum(p[1] for p in parts)
    mean_cos = sum(p[0] for p in parts) / count
    _, _, worst_cos, index, axis, offset = min(parts, key=lambda p: p[2])
    index = list(index)
    index[axis] += offset
    worst = float(np.degrees(np.arccos(np.clip(worst_cos, -1.0, 1.0))))
    return {
        "max": worst,
        "average": float(np.degrees(np.arccos(np.clip(mean_cos, -1.0, 1.0)))),
        "worst_face": {"axis": axis, "index": index},
        "faces": int(count),
    }

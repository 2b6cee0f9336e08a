"""Face non-orthogonality as checkMesh measures it, with its gradient, and its reduction by moving
a mesh's interior nodes (design notes §20, "Orthogonality polish").

checkMesh's non-orthogonality of an internal face is the angle between the face's area vector S
and the vector d from its owner cell's centre to its neighbour's; of a boundary face, between S
and the vector from its cell's centre to the face's centre (the angle whose tangent a boundary
face's skewness measures). OpenFOAM computes a face's centre and area from the triangles between
each edge and the corners' mean (a quadrilateral's S is 0.5 (x2 - x0) x (x3 - x1)), and a cell's
centre from the pyramids between its faces and the faces' mean centre, each weighted by its volume
(``meshgen.quality.faces_openfoam``). The functions here compute the same for hexahedra (a quad
mesh measured extruded one unit, as checkMesh sees a 2D case), and the exact gradient of a
function of the faces' cosines with respect to the nodes (the reverse pass written out,
``meshgen.methods.face_angles_compiled``).

``reduce_non_orthogonality`` minimises the sum over faces of
(max(0, cos(theta_t) - cos(theta)) / (1 - cos(theta_t)))^POWER over the free nodes by L-BFGS
from the given mesh, theta_t one threshold for internal faces and one for boundary faces:
faces under it do not count, the worst face counts most.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshgen.geometry import cube
from meshgen.geometry.block_nodes import global_numbering, merged_mesh
from meshgen.geometry.grid import HEX_FACE_LOOPS
from meshgen.methods.interfaces import gather

__all__ = [
    "FLOOR",
    "MAX_ITERATIONS",
    "POLISH_TARGET",
    "POWER",
    "RINGS",
    "SHEAR_SCALE",
    "Faces",
    "as_hexahedra",
    "boundary_nodes",
    "face_cosines",
    "faces_of",
    "largest_angles",
    "polish_block_set",
    "reduce_non_orthogonality",
]

_HEX_EDGES = ((0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7))
POWER = 4  # the penalty's power: the worst faces dominate
MAX_ITERATIONS = 100  # L-BFGS iterations at most
RINGS = 2  # rings of cells around the faces over a threshold whose nodes move
POLISH_TARGET = 0.9  # polish_block_set's thresholds: this fraction of the start's largest angles
SHEAR_SCALE = 0.05  # a corner's scaled Jacobian this far below its floor costs as much as a face at twice its threshold's 1 - cos
FLOOR = 10.0  # degrees: polish_block_set leaves faces under this alone
LBFGS_MEMORY = 10  # L-BFGS's stored steps
FIRST_STEP = 0.1  # the first L-BFGS step moves the node with the steepest gradient this many of its cell sizes
TOLERANCE = 1e-9  # L-BFGS stops at this penalty: every face within about 0.1 degrees of its threshold
STALL, STALL_WINDOW = 0.01, 10  # or when STALL_WINDOW steps lowered the penalty by less than this fraction
TINY = 1e-300


def _compiled():
    """``meshgen.methods.face_angles_compiled``, imported on first use: numba stays out of a process
    that polishes nothing (the quality worker forks only while numba is not loaded)."""
    from meshgen.methods import face_angles_compiled

    return face_angles_compiled


@dataclass(frozen=True)
class Faces:
    """The faces of hexahedra: ``owner``, ``slot`` (0-5), ``neighbour`` (F,) for each face two
    cells share (once, the owner the lower-numbered cell); ``cell``, ``side`` (B,) for each face of
    one cell only (``faces_of``)."""

    owner: np.ndarray
    slot: np.ndarray
    neighbour: np.ndarray
    cell: np.ndarray
    side: np.ndarray

    def subset(self, internal: np.ndarray, boundary: np.ndarray, renumber: np.ndarray) -> Faces:
        """The faces ``internal`` and ``boundary`` (indices), cells renumbered by ``renumber``."""
        return Faces(
            renumber[self.owner[internal]],
            self.slot[internal],
            renumber[self.neighbour[internal]],
            renumber[self.cell[boundary]],
            self.side[boundary],
        )


def faces_of(cells: np.ndarray) -> Faces:
    """The ``Faces`` of hexahedra ``cells`` (M, 8), VTK order, matched by their sorted corners."""
    cells = np.asarray(cells, dtype=np.int64)
    quads = np.sort(cells[:, HEX_FACE_LOOPS].reshape(-1, 4), axis=1)  # (6M, 4): slot = cell * 6 + face
    _, key, counts = np.unique(quads, axis=0, return_inverse=True, return_counts=True)
    key = key.reshape(-1)
    if counts.max(initial=0) > 2:
        raise ValueError("a face is shared by more than two cells")
    shared = np.flatnonzero(counts[key] == 2)
    order = shared[np.argsort(key[shared], kind="stable")]
    first, second = order[0::2], order[1::2]
    alone = np.flatnonzero(counts[key] == 1)
    return Faces(first // 6, first % 6, second // 6, alone // 6, alone % 6)


def _norm(v: np.ndarray) -> np.ndarray:
    return np.sqrt(np.einsum("ij,ij->i", v, v))


def _pairs(Sf, C, c, faces: Faces):
    """The (S, d) pairs whose angle checkMesh measures: internal faces, then boundary faces."""
    S = np.concatenate([Sf[faces.owner, faces.slot], Sf[faces.cell, faces.side]])
    d = np.concatenate([C[faces.neighbour] - C[faces.owner], c[faces.cell, faces.side] - C[faces.cell]])
    return S, d


def _orientation(X: np.ndarray) -> float:
    """+1 when the cells ``X`` (M, 8, 3) are right-handed in their corner order (their total
    volume positive), else -1."""
    return 1.0 if float(_compiled().forward(X, 1.0)[2].sum()) >= 0 else -1.0


def _cosines(X: np.ndarray, orientation: float, faces: Faces):
    """(cosines of the faces (internal, then boundary), the cells' ``forward`` geometry)."""
    geometry = _compiled().forward(X, orientation)
    S, d = _pairs(*geometry[:2], geometry[3], faces)
    return np.einsum("ij,ij->i", S, d) / np.maximum(_norm(S) * _norm(d), TINY), geometry


def face_cosines(points: np.ndarray, cells: np.ndarray, faces: Faces | None = None) -> tuple[np.ndarray, np.ndarray]:
    """cos(non-orthogonality) of the internal faces and of the boundary faces (``faces_of(cells)``
    order; ``faces`` when the caller has them) of hexahedra ``cells`` (M, 8) over ``points``
    (N, 3); checkMesh's angles are their arccos."""
    cells = np.asarray(cells, dtype=np.int64)
    faces = faces_of(cells) if faces is None else faces
    cos, geometry = _cosines(np.asarray(points, dtype=float)[cells], 1.0, faces)
    # left-handed cells: the area vectors turn, the centres do not (a sign, not a second pass)
    cos *= 1.0 if float(geometry[2].sum()) >= 0 else -1.0
    return cos[: len(faces.owner)], cos[len(faces.owner) :]


def _cosine_gradient(X: np.ndarray, orientation: float, faces: Faces, gcos: np.ndarray, geometry=None) -> np.ndarray:
    """d(sum of gcos * cos)/dX (M, 8, 3) over the ``faces`` (internal, then boundary) of the
    hexahedra with corners ``X`` (M, 8, 3); ``geometry``: their ``forward`` when the caller has it."""
    Sf, C, _, c = _compiled().forward(X, orientation) if geometry is None else geometry
    S, d = _pairs(Sf, C, c, faces)
    nS, nd = _norm(S), _norm(d)
    cos = np.einsum("ij,ij->i", S, d) / np.maximum(nS * nd, TINY)
    gS = gcos[:, None] * (d / np.maximum(nS * nd, TINY)[:, None] - (cos / np.maximum(nS, TINY) ** 2)[:, None] * S)
    gd = gcos[:, None] * (S / np.maximum(nS * nd, TINY)[:, None] - (cos / np.maximum(nd, TINY) ** 2)[:, None] * d)
    n = len(faces.owner)
    gSf, gc, gC = np.zeros_like(Sf), np.zeros_like(c), np.zeros_like(C)
    np.add.at(gSf, (faces.owner, faces.slot), gS[:n])
    np.add.at(gSf, (faces.cell, faces.side), gS[n:])
    np.add.at(gc, (faces.cell, faces.side), gd[n:])
    for k in range(3):
        gC[:, k] = (
            np.bincount(faces.neighbour, gd[:n, k], len(C))
            - np.bincount(faces.owner, gd[:n, k], len(C))
            - np.bincount(faces.cell, gd[n:, k], len(C))
        )
    return _compiled().backward(X, orientation, gSf, gc, gC)


def _node_sizes(points: np.ndarray, cells: np.ndarray, edges) -> np.ndarray:
    """Each node's shortest cell edge (N,) over the hexahedra's ``edges`` (corner pairs)."""
    size = np.full(len(points), np.inf)
    for i, j in edges:
        length = np.sqrt(np.sum((points[cells[:, i]] - points[cells[:, j]]) ** 2, axis=1))
        np.minimum.at(size, cells[:, i], length)
        np.minimum.at(size, cells[:, j], length)
    return size


def _region(cells: np.ndarray, faces: Faces, over: np.ndarray, free: np.ndarray, n_points: int, rings: int):
    """The part of the mesh that moves: (nodes free to move, cells whose geometry counts, the
    internal and the boundary faces that count). Moving: the free nodes of the cells within
    ``rings`` rings (cells sharing a node) of the faces ``over`` a threshold (internal, then
    boundary); counting: every face of a cell holding a moving node, and the cells at those faces."""
    n = len(faces.owner)
    in_region = np.zeros(len(cells), dtype=bool)
    in_region[faces.owner[over[:n]]] = in_region[faces.neighbour[over[:n]]] = True
    in_region[faces.cell[over[n:]]] = True
    for _ in range(rings):
        touched = np.zeros(n_points, dtype=bool)
        touched[cells[in_region].reshape(-1)] = True
        in_region = touched[cells].any(axis=1)
    moving = np.zeros(n_points, dtype=bool)
    moving[cells[in_region].reshape(-1)] = True
    is_free = np.zeros(n_points, dtype=bool)
    is_free[free] = True
    moving &= is_free
    affected = moving[cells].any(axis=1)
    internal = np.flatnonzero(affected[faces.owner] | affected[faces.neighbour])
    boundary = np.flatnonzero(affected[faces.cell])
    used = affected.copy()
    used[faces.owner[internal]] = used[faces.neighbour[internal]] = True
    return np.flatnonzero(moving), np.flatnonzero(used), internal, boundary


def as_hexahedra(points: np.ndarray, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hexahedra as they are, or quads (M, 4) over (N, 2) points as one layer of hexahedra one unit
    thick (2N, 3), (M, 8) (checkMesh's view of a 2D mesh)."""
    points, cells = np.asarray(points, dtype=float), np.asarray(cells, dtype=np.int64)
    if points.shape[1] == 3:
        return points, cells
    points3 = np.zeros((2 * len(points), 3))
    points3[: len(points), :2] = points3[len(points) :, :2] = points
    points3[len(points) :, 2] = 1.0
    return points3, np.concatenate([cells, cells + len(points)], axis=1)


def _largest(cos: np.ndarray) -> float:
    return float(np.degrees(np.arccos(np.clip(cos.min(initial=1.0), -1.0, 1.0))))


def largest_angles(points: np.ndarray, cells: np.ndarray, faces: Faces | None = None) -> tuple[float, float]:
    """checkMesh's largest non-orthogonality (degrees) of the internal faces and of the boundary
    faces of hexahedra (M, 8) or quads (M, 4; the front and back of the extruded layer are square
    to it) over ``points`` (N, 3 or 2); ``faces``: those of ``as_hexahedra``'s cells, when the
    caller has them."""
    internal, boundary = face_cosines(*as_hexahedra(points, cells), faces)
    return _largest(internal), _largest(boundary)


def _lbfgs(fun, x: np.ndarray, max_iterations: int, done=lambda: False, memory: int = LBFGS_MEMORY) -> tuple[np.ndarray, int]:
    """Minimise ``fun`` (x -> (value, gradient)) from ``x`` by L-BFGS (two-loop recursion) with a
    backtracking (Armijo) line search, the first step ``FIRST_STEP`` long; stops at a value of
    ``TOLERANCE`` or less, after ``max_iterations``, or when ``STALL_WINDOW`` steps gained less than
    ``STALL`` of the value, or when ``done()`` says so after a step. A value of inf
    (a folded cell) makes the line search step back. Returns (x, iterations)."""
    value, gradient = fun(x)
    values = [value]
    history: list[tuple[np.ndarray, np.ndarray, float]] = []
    for iteration in range(1, max_iterations + 1):
        if value <= TOLERANCE:
            return x, iteration - 1
        direction = -gradient
        alphas = []
        for s, y, rho in reversed(history):
            alphas.append(rho * (s @ direction))
            direction = direction - alphas[-1] * y
        if history:
            s, y, _ = history[-1]
            direction = direction * ((s @ y) / (y @ y))
        else:
            direction = direction * (FIRST_STEP / max(float(np.abs(gradient).max()), TINY))
        for (s, y, rho), alpha in zip(history, reversed(alphas)):
            direction = direction + (alpha - rho * (y @ direction)) * s
        slope = float(gradient @ direction)
        if not slope < 0:  # not a descent direction: start the memory again
            history.clear()
            direction = -gradient * (FIRST_STEP / max(float(np.abs(gradient).max()), TINY))
            slope = float(gradient @ direction)
        step = 1.0
        while True:
            new_value, new_gradient = fun(x + step * direction)
            if new_value <= value + 1e-4 * step * slope:
                break
            step *= 0.5
            if step < 1e-8:
                return x, iteration
        s, y = step * direction, new_gradient - gradient
        if s @ y > 0:
            history.append((s, y, 1.0 / float(s @ y)))
            del history[:-memory]
        x, value, gradient = x + s, new_value, new_gradient
        if done():
            return x, iteration
        values.append(value)
        if len(values) > STALL_WINDOW and value > (1.0 - STALL) * values[-1 - STALL_WINDOW]:
            return x, iteration
    return x, max_iterations


def reduce_non_orthogonality(
    points: np.ndarray,
    cells: np.ndarray,
    free: np.ndarray,
    thresholds: tuple[float, float],
    max_iterations: int = MAX_ITERATIONS,
    rings: int = RINGS,
    faces: Faces | None = None,
) -> tuple[np.ndarray, dict]:
    """``points`` (N, dim) with ``free`` nodes (indices) moved to reduce the non-orthogonality of
    the faces of ``cells`` (M, 8) (2D: quads (M, 4), measured extruded) above ``thresholds``
    (degrees: internal faces, boundary faces; module docstring): the free nodes within ``rings``
    rings of cells of such faces move (``_lbfgs``); no corner folds, and a corner whose scaled
    Jacobian falls below the smaller of its start value and the mesh's smallest adds
    (shortfall / SHEAR_SCALE)^POWER to the penalty. Returns (points, info: ``iterations``,
    ``moved`` nodes, ``before``/``after`` the largest angles (internal, boundary) in degrees,
    ``penalty_before``/``after``). ``faces``: those of ``as_hexahedra``'s cells, when the caller
    has them."""
    points = np.asarray(points, dtype=float)
    dim, n_points = points.shape[1], len(points)
    free = np.asarray(free, dtype=np.int64)
    points3, cells3 = as_hexahedra(points, cells)
    free3 = free if dim == 3 else np.concatenate([free, free + n_points])
    faces = faces_of(cells3) if faces is None else faces
    orientation = _orientation(points3[cells3])
    n_internal = len(faces.owner)
    limit = np.cos(np.radians(np.repeat(np.asarray(thresholds, dtype=float), [n_internal, len(faces.cell)])))
    cos = _cosines(points3[cells3], orientation, faces)[0]
    before = (_largest(cos[:n_internal]), _largest(cos[n_internal:]))
    info = {"iterations": 0, "moved": 0, "before": before, "after": before, "penalty_before": 0.0, "penalty_after": 0.0}
    moving3, used, internal, boundary = _region(cells3, faces, cos < limit, free3, len(points3), rings)
    moving = moving3[moving3 < n_points]  # 2D: the z = 0 copies; their z = 1 twins move with them
    if not len(moving):
        return points, info
    copies = (moving,) if dim == 3 else (moving, moving + n_points)
    renumber = np.full(len(cells3), -1, dtype=np.int64)
    renumber[used] = np.arange(len(used))
    sub_cells, sub_faces = cells3[used], faces.subset(internal, boundary, renumber)
    sub_limit = np.concatenate([limit[internal], limit[n_internal + boundary]])
    scale = 1.0 - sub_limit
    # variables: each moving node's displacement in units of its shortest edge, so that L-BFGS sees
    # a thin wall cell's nodes and a core cell's alike
    size = _node_sizes(points3, sub_cells, _HEX_EDGES if dim == 3 else _HEX_EDGES[:8])[moving][:, None]
    origin = points[moving]
    work = points3.copy()
    best = {"value": np.inf, "x": np.zeros(origin.size)}
    # a corner's scaled Jacobian below its own start value and the mesh's smallest is penalised
    floor = np.minimum(
        orientation * _compiled().corner_jacobians(points3[sub_cells]),
        orientation * _compiled().corner_jacobians(points3[cells3]).min(),
    )

    def penalty(x: np.ndarray):
        for copy in copies:
            work[copy, :dim] = origin + size * x.reshape(-1, dim)
        X = work[sub_cells]
        cos, geometry = _cosines(X, orientation, sub_faces)
        jacobian = orientation * _compiled().corner_jacobians(X)
        if not np.all(jacobian > 0):
            return np.inf, np.zeros_like(x)  # a corner folded: the line search steps back
        excess = np.maximum(0.0, sub_limit - cos) / scale
        shear = np.maximum(0.0, floor - jacobian) / SHEAR_SCALE
        faces_value = float(np.sum(excess**POWER))
        value = faces_value + float(np.sum(shear**POWER))
        best["faces"] = faces_value
        gX = _cosine_gradient(X, orientation, sub_faces, -POWER * excess ** (POWER - 1) / scale, geometry)
        gX += _compiled().corner_jacobians_backward(X, -orientation * POWER * shear ** (POWER - 1) / SHEAR_SCALE)
        gradient = np.zeros((len(work), dim))
        for k in range(dim):
            gradient[:, k] = np.bincount(sub_cells.reshape(-1), gX[..., k].reshape(-1), len(work))
        if value < best["value"]:
            best.update(value=value, x=x.copy())
        return value, (sum(gradient[copy] for copy in copies) * size).reshape(-1)

    start = penalty(np.zeros(origin.size))[0]
    if not np.isfinite(start):  # a corner folded already: nothing here can be trusted to improve it
        return points, info
    iterations = _lbfgs(penalty, np.zeros(origin.size), max_iterations, done=lambda: best["faces"] <= TOLERANCE)[1]
    moved = points.copy()
    moved[moving] = origin + size * best["x"].reshape(-1, dim)
    return moved, {
        **info,
        "iterations": iterations,
        "moved": len(moving),
        "after": largest_angles(moved, cells, faces),
        "penalty_before": start,
        "penalty_after": float(best["value"]),
    }


def boundary_nodes(block_set) -> np.ndarray:
    """(nodes,) bool in ``global_numbering`` order: the nodes on a block face that is not an interface."""
    numbering, count = global_numbering(block_set)
    glued = {(i.a, i.face_a) for i in block_set.interfaces} | {(i.b, i.face_b) for i in block_set.interfaces}
    on_boundary = np.zeros(count, dtype=bool)
    for block, ids in enumerate(numbering):
        for face in cube.faces(block_set.dim):
            if (block, face) not in glued:
                on_boundary[ids[face.node_index].reshape(-1)] = True
    return on_boundary


def polish_block_set(block_set, Xs: list, start: list) -> tuple[list, dict | None]:
    """The block set's elliptic mesh ``Xs`` (node arrays, interface nodes equal) made at least as
    orthogonal as its ``start`` (the mesh the solve started from, on the same boundary: the TFI)
    where it is not.

    When its largest non-orthogonality of internal faces or of boundary faces exceeds the start's,
    its nodes off the boundary (block interiors and interfaces) move to bring every face under
    ``POLISH_TARGET`` times the start's largest angle of its kind, or ``FLOOR``, whichever is
    larger (``reduce_non_orthogonality``); the result is kept where neither largest angle grew.
    Returns (node arrays, None when nothing was to do (no face over the thresholds), else the figures: ``start``, ``before``,
    ``after`` (internal, boundary) degrees, ``moved``, ``iterations``, ``kept``)."""
    numbering, count = global_numbering(block_set)
    points, cells, _ = merged_mesh(block_set, Xs)
    faces = faces_of(as_hexahedra(points, cells)[1])  # one matching for the start, the mesh and the polish
    before, reference = largest_angles(points, cells, faces), largest_angles(gather(start, numbering, count), cells, faces)
    if before[0] <= reference[0] and before[1] <= reference[1]:
        return Xs, None
    thresholds = tuple(max(FLOOR, POLISH_TARGET * angle) for angle in reference)
    free = np.flatnonzero(~boundary_nodes(block_set))
    moved, info = reduce_non_orthogonality(points, cells, free, thresholds, faces=faces)
    if not info["moved"]:  # no face over the thresholds (10 degrees at least)
        return Xs, None
    figures = {"start": reference, "before": before, "moved": info["moved"], "iterations": info["iterations"]}
    if info["after"][0] > before[0] or info["after"][1] > before[1]:
        return Xs, {**figures, "after": before, "kept": False}
    return [moved[ids] for ids in numbering], {**figures, "after": info["after"], "kept": True}

"""Smoothed boundary layout: a reparametrisation of the cube's boundary that moves boundary
nodes within their face.

The "fixed" layout puts the boundary node at parametric point p on the geometry's boundary
map g(p): on a curved face that is the transfinite (Coons) layout of its edges, and the interior
grid lines of an elliptic mesh bend over many layers to meet it. The smoothed layout replaces g by
g(s(p)), s a reparametrisation of the unit cube's boundary that maps every edge onto itself and
every face onto itself:

1. edges: s is the inverse of the normalised arc length of g along the edge (the 1D Winslow
   solution: nodes equally spaced along the curve);
2. faces (3D): on each face, with its edges from step 1 held fixed, the face parameters (u, v) of
   a fixed fine grid of ``RESOLUTION`` cells per side solve the 2D Winslow equations of the surface
   grid x = g(u, v): the tangential part of ``g22 x_xixi - 2 g12 x_xieta + g11 x_etaeta`` (the
   same discrete operator as ``meshgen.winslow``, on the surface's physical points) is zero. The
   normal part is the surface's curvature and is left alone, so the nodes stay exactly on the
   surface. Solved by frozen-coefficient (Picard) steps: pull the physical residual back to the
   face parameters through the surface's tangents (central differences of the map) and solve the
   scalar Winslow operator for the parameter update (a sparse direct solve, Anderson-mixed; at the
   mesh's resolution, where the start is the layout and close, the factorisation is kept while each
   step shrinks to at most ``REFACTOR_RATE`` of the one before, a chord method: the frozen
   coefficients change little from step to step, and factorising costs ten times a solve);
3. between the fine nodes s is the tensor product of C1 cubic Hermite interpolation (slopes by
   finite differences), which on an edge reduces to the 1D interpolation of the edge's values, so
   the two faces that share an edge agree on it to round-off and g(s(p)) stays continuous.

s depends on the geometry and its parameters only (not on the mesh's dims), so a network trained
on g(s(p)) meshes any dims with the same layout. ``smoothed(geometry)`` returns a ``Geometry``
whose boundary map is g(s(p)): TFI, the elliptic solver and the neural method take it unchanged.
For a flat face the surface grid is the 2D elliptic mesh of that face (tested on the semicylinder's
cap against the semidisk).
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from meshgen import __version__
from meshgen.anderson import ANDERSON_DEPTH, AndersonMixing
from meshgen.atomic import atomic_path
from meshgen.cube import edges, faces
from meshgen.errors import GeometryError
from meshgen.winslow import stencils, winslow_operator

__all__ = [
    "ARC_SAMPLES",
    "DEFAULT_LAYOUT",
    "FACE_MAX_ITER",
    "FACE_TOL",
    "LAYOUTS",
    "RELAX_TOL",
    "RESOLUTION",
    "TANGENT_STEP",
    "Layout",
    "cache_path",
    "compute_layout",
    "coons_start",
    "interpolate_1d",
    "interpolate_2d",
    "layout_of",
    "relax_faces",
    "smoothed",
    "surface_grid",
    "trained_layout",
    "unsmoothed",
    "with_layout",
]

LAYOUTS = ("smoothed", "fixed")
DEFAULT_LAYOUT = "smoothed"
RESOLUTION = 64  # fine-grid cells per face side (parametric spacing 1/64)
ARC_SAMPLES = 64  # chords per fine cell when measuring an edge's arc length
FACE_TOL = 1e-11  # stop when the largest parameter update of a face is below this
FACE_MAX_ITER = 200
REFACTOR_RATE = 0.5  # factorise the face operator again when a step shrank by less than this
RELAX_TOL = 1e-9  # the same at the mesh's resolution (relax_faces): far below the volume solver's 1e-6
TANGENT_STEP = 1e-6  # parametric step of the central differences that give the surface's tangents


# ---------------------------------------------------------------------------------------------
# C1 cubic Hermite interpolation on the uniform fine grid


def _hermite_weights(p: np.ndarray, cells: int) -> tuple[np.ndarray, np.ndarray]:
    """Weights of the cubic Hermite interpolant (finite-difference slopes) of values at the
    ``cells + 1`` uniform nodes of [0, 1], at points ``p`` (N,): node indices (N, 4) and weights
    (N, 4), the value being ``sum weights * values[indices]``. At a node the weights are exactly
    (0, 1, 0, 0): the interpolant passes through the data bit for bit."""
    p = np.clip(np.asarray(p, dtype=float), 0.0, 1.0)
    cell = np.clip(np.floor(p * cells).astype(int), 0, cells - 1)
    t = p * cells - cell
    t2, t3 = t * t, t * t * t
    h00, h10, h01, h11 = 2 * t3 - 3 * t2 + 1, t3 - 2 * t2 + t, -2 * t3 + 3 * t2, t3 - t2
    # Slopes times the spacing, as weights on the slots (k-1, k, k+1, k+2) of the cell k:
    # central differences inside, second-order one-sided ones at the ends.
    weights = np.zeros(p.shape + (4,))
    weights[:, 1] += h00
    weights[:, 2] += h01
    first = cell == 0
    last = cell == cells - 1
    # slope at node k (slot 1)
    central = ~first
    weights[central, 0] -= 0.5 * h10[central]
    weights[central, 2] += 0.5 * h10[central]
    weights[first, 1] -= 1.5 * h10[first]
    weights[first, 2] += 2.0 * h10[first]
    weights[first, 3] -= 0.5 * h10[first]
    # slope at node k + 1 (slot 2)
    central = ~last
    weights[central, 1] -= 0.5 * h11[central]
    weights[central, 3] += 0.5 * h11[central]
    weights[last, 2] += 1.5 * h11[last]
    weights[last, 1] -= 2.0 * h11[last]
    weights[last, 0] += 0.5 * h11[last]
    indices = np.clip(cell[:, None] + np.arange(-1, 3), 0, cells)
    return indices, weights


def interpolate_1d(values: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The Hermite interpolant of ``values`` (cells + 1, ...) at points ``p`` (N,): (N, ...)."""
    indices, weights = _hermite_weights(p, len(values) - 1)
    return np.einsum("nk,nk...->n...", weights, values[indices])


def interpolate_2d(values: np.ndarray, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The tensor-product Hermite interpolant of ``values`` (cells + 1, cells + 1, ...) at the
    points (p, q), each (N,): (N, ...). On q = 0 (or 1) it is ``interpolate_1d(values[:, 0], p)``."""
    ip, wp = _hermite_weights(p, values.shape[0] - 1)
    iq, wq = _hermite_weights(q, values.shape[1] - 1)
    along_q = np.einsum("nl,nkl...->nk...", wq, values[ip[:, :, None], iq[:, None, :]])
    return np.einsum("nk,nk...->n...", wp, along_q)


# ---------------------------------------------------------------------------------------------
# the reparametrisation


@dataclass(frozen=True)
class Layout:
    """The boundary reparametrisation s of the unit cube (square) of dimension ``dim``.

    ``edge_values[(axes, sides)]``: (RESOLUTION + 1,) the edge's free parameter at the uniform fine
    nodes (3D: the 12 edges; 2D: the 4 sides, keyed by ``((axis,), (side,))``).
    ``face_values[(axis, side)]`` (3D): (RESOLUTION + 1, RESOLUTION + 1, 2), the face parameters
    (along its two tangent axes, increasing order) at the fine nodes.
    ``face_info``: per face name, the Picard iterations and final update of its surface solve.
    """

    dim: int
    edge_values: dict
    face_values: dict
    face_info: dict

    def apply(self, points: np.ndarray) -> np.ndarray:
        """s(points): (N, dim) points on the cube's boundary -> (N, dim) points on the same faces
        (exact 0/1 coordinates are kept bit for bit)."""
        points = np.asarray(points, dtype=float)
        out = points.copy()
        on_side = (points == 0.0) | (points == 1.0)
        count = on_side.sum(axis=1)
        if self.dim == 2:
            for (axes, sides), values in self.edge_values.items():
                (axis,), (side,) = axes, sides
                rows = np.flatnonzero((count == 1) & (points[:, axis] == side))
                free = 1 - axis
                out[rows, free] = np.clip(interpolate_1d(values, points[rows, free]), 0.0, 1.0)
            return out
        for (axes, sides), values in self.edge_values.items():
            rows = np.flatnonzero((count == 2) & (points[:, axes[0]] == sides[0]) & (points[:, axes[1]] == sides[1]))
            free = 3 - axes[0] - axes[1]
            out[rows, free] = np.clip(interpolate_1d(values, points[rows, free]), 0.0, 1.0)
        for (axis, side), values in self.face_values.items():
            rows = np.flatnonzero((count == 1) & (points[:, axis] == side))
            a, b = (d for d in range(3) if d != axis)
            mapped = interpolate_2d(values, points[rows, a], points[rows, b])
            out[rows, a] = np.clip(mapped[:, 0], 0.0, 1.0)
            out[rows, b] = np.clip(mapped[:, 1], 0.0, 1.0)
        return out


def _edge_values(boundary, dim: int, axes: tuple, sides: tuple, cells: int) -> np.ndarray:
    """Free parameter of an edge at its ``cells + 1`` uniform fine nodes: the inverse of the
    normalised arc length of the boundary map along the edge (chords of ARC_SAMPLES per cell)."""
    t = np.linspace(0.0, 1.0, cells * ARC_SAMPLES + 1)
    points = np.empty((len(t), dim))
    free = [d for d in range(dim) if d not in axes][0]
    for axis, side in zip(axes, sides):
        points[:, axis] = side
    points[:, free] = t
    images = boundary(points)
    length = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(images, axis=0), axis=1))])
    if not length[-1] > 0:
        raise GeometryError("boundary layout: an edge of the geometry has zero length")
    values = np.interp(np.linspace(0.0, 1.0, cells + 1), length / length[-1], t)
    values[0], values[-1] = 0.0, 1.0
    return values


def _lift(axis: int, side: int, U: np.ndarray) -> np.ndarray:
    """Face parameters U (..., 2) of the face ``t[axis] = side`` -> cube points (..., 3)."""
    a, b = (d for d in range(3) if d != axis)
    points = np.empty(U.shape[:-1] + (3,))
    points[..., axis] = side
    points[..., a], points[..., b] = U[..., 0], U[..., 1]
    return points


def _scalar_operator(c11, c22, c12, grid):
    """Sparse matrix of ``c11 f_pp + c22 f_qq + 2 c12 f_pq`` (the three-point stencils of
    ``grid``, a 2D ``meshgen.winslow.Stencils``; f_pq the product of the first-derivative ones) on
    the interior nodes of the face grid, zero Dirichlet values outside; coefficients (m_p, m_q)."""
    from scipy import sparse

    m_p, m_q = c11.shape
    index = np.arange(m_p * m_q).reshape(m_p, m_q)
    rows, cols, vals = [], [], []
    second_p, second_q = grid.second
    first_p, first_q = grid.first
    for dp in (-1, 0, 1):
        for dq in (-1, 0, 1):
            coefficient = 2.0 * c12 * first_p[dp + 1] * first_q[dq + 1]
            if dq == 0:
                coefficient = coefficient + c11 * second_p[dp + 1]
            if dp == 0:
                coefficient = coefficient + c22 * second_q[dq + 1]
            target = np.full((m_p, m_q), -1)
            i0, i1 = max(0, -dp), m_p - max(0, dp)
            j0, j1 = max(0, -dq), m_q - max(0, dq)
            target[i0:i1, j0:j1] = index[i0 + dp : i1 + dp, j0 + dq : j1 + dq]
            keep = target >= 0
            rows.append(index[keep]), cols.append(target[keep])
            vals.append(np.broadcast_to(coefficient, (m_p, m_q))[keep])
    return sparse.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(m_p * m_q, m_p * m_q))


def coons_start(edge_u: tuple, coords) -> np.ndarray:
    """Face parameters on the face grid of ``coords`` (t_p, t_q): the four sides' values
    ``edge_u`` = (p0, p1, q0, q1) (the parameter along each side, the other being 0 or 1) and
    inside their parameter-space Coons patch, (n_p, n_q, 2)."""
    t_p, t_q = (np.asarray(c, dtype=float) for c in coords)
    p0, p1, q0, q1 = edge_u
    U = np.zeros((len(t_p), len(t_q), 2))
    U[0, :, 0], U[-1, :, 0] = 0.0, 1.0
    U[0, :, 1], U[-1, :, 1] = p0, p1
    U[:, 0, 1], U[:, -1, 1] = 0.0, 1.0
    U[:, 0, 0], U[:, -1, 0] = q0, q1
    s, r = t_p[:, None], t_q[None, :]
    for c in range(2):
        F = U[..., c]
        F[1:-1, 1:-1] = (
            (1 - s) * F[0:1, :]
            + s * F[-1:, :]
            + (1 - r) * F[:, 0:1]
            + r * F[:, -1:]
            - ((1 - s) * (1 - r) * F[0, 0] + s * (1 - r) * F[-1, 0] + (1 - s) * r * F[0, -1] + s * r * F[-1, -1])
        )[1:-1, 1:-1]
    return U


def surface_grid(
    boundary, axis: int, side: int, U: np.ndarray, coords, tol: float = FACE_TOL, max_iter: int = FACE_MAX_ITER, refactor_rate=0.0
):
    """The Winslow surface grid of the face ``t[axis] = side`` on the tensor grid of ``coords``
    (the parametric node coordinates along its two tangent axes, increasing order).

    ``U``: (n_p, n_q, 2) face parameters: the sides' values (kept) and a start inside.
    ``boundary``: the geometry's map. ``refactor_rate``: keep the factorised operator while each
    step is at most this fraction of the one before (0: factorise every step, which the fine grid's
    hard faces need: the flower's caps take 160 steps so, and more than 200 keeping it). Returns the solved face parameters (same shape) and
    ``{"iterations", "final_update"}`` (the largest parameter change of the last step).
    """
    from scipy.sparse.linalg import splu

    U = np.array(U, dtype=float)
    shape = U.shape[:-1]
    grid = stencils(coords)
    mixing = AndersonMixing(ANDERSON_DEPTH)
    update = previous = np.inf
    iterations = 0
    while iterations < max_iter:
        X = boundary(_lift(axis, side, U).reshape(-1, 3)).reshape(shape + (3,))
        residual, axial = winslow_operator(np.ascontiguousarray(np.moveaxis(X, -1, 0)), grid)  # over the trace
        # The surface's tangents g_u, g_v at the interior nodes, by central differences of the map.
        inner = U[1:-1, 1:-1].reshape(-1, 2)
        probes = []
        for d in range(2):
            for sign in (1.0, -1.0):
                moved = inner.copy()
                moved[:, d] = np.clip(moved[:, d] + sign * TANGENT_STEP, 0.0, 1.0)
                probes.append(moved)
        images = boundary(_lift(axis, side, np.concatenate(probes))).reshape(4, -1, 3)
        spans = [probes[2 * d][:, d] - probes[2 * d + 1][:, d] for d in range(2)]
        tu, tv = ((images[2 * d] - images[2 * d + 1]) / spans[d][:, None] for d in range(2))
        # Least-squares pull-back of the physical residual onto the tangent plane: the parameter
        # change whose image best matches it, (T^T T)^-1 T^T r.
        res = np.moveaxis(residual, 0, -1).reshape(-1, 3)
        a11, a12, a22 = (tu * tu).sum(-1), (tu * tv).sum(-1), (tv * tv).sum(-1)
        ru, rv = (tu * res).sum(-1), (tv * res).sum(-1)
        det_t = a11 * a22 - a12**2
        if np.any(det_t <= 0) or not np.all(np.isfinite(det_t)):
            raise GeometryError("boundary layout: the geometry's face map is singular inside a face")
        inner_shape = (shape[0] - 2, shape[1] - 2)
        target = np.stack([(a22 * ru - a12 * rv) / det_t, (a11 * rv - a12 * ru) / det_t], axis=-1).reshape(inner_shape + (2,))
        # The operator's own normalised coefficients: A_aa / trace on the axes, the mixed one
        # (-g12 / trace) from the grid's metric.
        x_p, x_q = ((X[2:, 1:-1] - X[:-2, 1:-1]), (X[1:-1, 2:] - X[1:-1, :-2]))
        g11, g12, g22 = (x_p * x_p).sum(-1), (x_p * x_q).sum(-1), (x_q * x_q).sum(-1)
        if np.any(g11 * g22 - g12**2 <= 0):
            raise GeometryError("boundary layout: a face's surface grid degenerated (zero-area cell)")
        c11, c22 = axial
        # g12 / trace from the raw differences: scale by the first-derivative factors, as axial does
        scale_p = 1.0 / (grid.coords[0][2:] - grid.coords[0][:-2])[:, None]
        scale_q = 1.0 / (grid.coords[1][2:] - grid.coords[1][:-2])[None, :]
        trace = g11 * scale_p**2 + g22 * scale_q**2
        c12 = -g12 * scale_p * scale_q / trace
        if iterations == 0 or update > refactor_rate * previous:
            operator = splu(_scalar_operator(c11, c22, c12, grid), permc_spec="MMD_AT_PLUS_A")
        step = np.stack([operator.solve(-target[..., c].ravel()) for c in range(2)], axis=-1).reshape(inner_shape + (2,))
        iterations += 1
        previous, update = update, float(np.abs(step).max())
        if not np.isfinite(update):
            raise GeometryError("boundary layout: a face's surface grid diverged")
        if update < tol:
            U[1:-1, 1:-1] += step
            break
        if update > previous:
            mixing.restart()
        inner = U[1:-1, 1:-1]
        U[1:-1, 1:-1] = np.clip(mixing.next_iterate(inner.copy(), inner + step), 0.0, 1.0)
    np.clip(U, 0.0, 1.0, out=U)
    return U, {"iterations": iterations, "final_update": update}


def compute_layout(geometry, cells: int = RESOLUTION) -> Layout:
    """The smoothed layout of ``geometry`` (a Geometry), on a fine grid of ``cells`` per side."""
    boundary = geometry.boundary
    dim = geometry.dim
    if dim == 2:
        edge_values = {
            ((face.axis,), (face.side,)): _edge_values(boundary, 2, (face.axis,), (face.side,), cells) for face in faces(2)
        }
        return Layout(2, edge_values, {}, {})
    edge_values = {(e.axes, e.sides): _edge_values(boundary, 3, e.axes, e.sides, cells) for e in edges()}
    face_values, face_info = {}, {}
    for face in faces(3):
        a, b = face.tangent_axes

        def side_values(fixed_axis, fixed_side):
            axes = tuple(sorted((face.axis, fixed_axis)))
            sides = (face.side, fixed_side) if axes[0] == face.axis else (fixed_side, face.side)
            return edge_values[(axes, sides)]

        # sides of the face: p = 0, 1 (the tangent axis a fixed) carry the parameter along b, and vice versa
        edge_u = (side_values(a, 0), side_values(a, 1), side_values(b, 0), side_values(b, 1))
        t = np.linspace(0.0, 1.0, cells + 1)
        U, info = surface_grid(boundary, face.axis, face.side, coons_start(edge_u, (t, t)), (t, t))
        face_values[(face.axis, face.side)] = U
        face_info[face.name] = info
    return Layout(3, edge_values, face_values, face_info)


def relax_faces(geometry, coords, X: np.ndarray, tol: float = RELAX_TOL) -> dict:
    """Solve each face's surface grid again on the mesh's own face nodes (in place in ``X``).

    ``geometry``: a smoothed geometry (``smoothed``); ``coords``: the mesh's parametric node
    coordinates per axis; ``X``: its node array (3D), whose face nodes are replaced by the
    discrete Winslow surface grid of the face at the mesh's resolution (edges kept, the smoothed
    layout as the start: the map's own ``layout_at(**values)`` when it has one, as a family
    member's interpolated layout does, else the geometry's solved layout). Why: an elliptic mesh's layers next to a face then solve the same discrete
    equations as the face itself, so an extruded shape gives an exactly extruded mesh (the layout's
    fine-grid interpolant differs from that by the discretisation error, which a flow solver sees
    as skewed cells). Returns the Picard iterations per face name.
    """
    if geometry.dim != 3:
        return {}
    own = getattr(geometry.boundary_map, "layout_at", None)  # a layout given with the map (a family's)
    layout = own(**geometry.values) if own is not None else layout_of(unsmoothed(geometry))
    plain = unsmoothed(geometry).boundary
    iterations = {}
    for face in faces(3):
        a, b = face.tangent_axes
        face_coords = (np.asarray(coords[a], dtype=float), np.asarray(coords[b], dtype=float))
        if min(len(c) for c in face_coords) < 3:
            continue  # no interior nodes on this face
        start = layout.apply(face.points(coords))[:, [a, b]].reshape(len(face_coords[0]), len(face_coords[1]), 2)
        U, info = surface_grid(plain, face.axis, face.side, start, face_coords, tol=tol, refactor_rate=REFACTOR_RATE)
        X[face.node_index] = plain(_lift(face.axis, face.side, U).reshape(-1, 3)).reshape(U.shape[:-1] + (3,))
        iterations[face.name] = info["iterations"]
    return iterations


_LAYOUTS: dict = {}  # (plugin map, parameter values, cells) -> Layout, for this process


def layout_of(geometry, cells: int = RESOLUTION) -> Layout:
    """``compute_layout`` remembered per plugin map, parameter values and resolution: in this
    process, and between runs in the cache folder (``cache_path``), since solving the six face
    grids takes a second or more and every neural mesh of a smoothed-layout model needs them."""
    key = (geometry.boundary_map, tuple(sorted(geometry.values.items())), cells)
    if key not in _LAYOUTS:
        path = cache_path(geometry, cells)
        layout = _read_layout(path) if path is not None else None
        if layout is None:
            layout = compute_layout(geometry, cells)
            if path is not None:
                _write_layout(path, layout)
        _LAYOUTS[key] = layout
    return _LAYOUTS[key]


def cache_path(geometry, cells: int = RESOLUTION):
    """The file that keeps the layout of ``geometry`` between runs: in ``$MESHGEN_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/meshgen``, else ``~/.cache/meshgen``, under ``layouts/``, named by a hash of
    meshgen's version, the plugin's name and source text (a shape file's: the hash of its content
    and options, ``meshgen.shapes.loader.content_hash``), its parameter values and ``cells``.
    None for a plugin whose source file cannot be read (its layout is then computed every run)."""
    content = getattr(geometry.boundary_map, "content_hash", None)  # a shape file: its bytes' hash
    try:
        source = content.encode() if content else Path(geometry.source).read_bytes()
    except (OSError, TypeError, ValueError):
        return None
    identity = json.dumps([__version__, geometry.name, sorted(geometry.values.items()), cells]).encode()
    digest = hashlib.sha256(identity + b"\0" + source).hexdigest()[:32]
    folder = os.environ.get("MESHGEN_CACHE_DIR") or Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "meshgen"
    return Path(folder) / "layouts" / f"{geometry.name}-{digest}.npz"


def _read_layout(path):
    """The Layout stored at ``path``, or None when there is none or it cannot be read (a damaged or
    foreign file is ignored and recomputed; no pickles are loaded)."""
    try:
        with np.load(path, allow_pickle=False) as stored:
            dim = int(stored["dim"])
            edge_values = {
                (tuple(int(a) for a in key[0]), tuple(int(s) for s in key[1])): stored[f"edge{i}"]
                for i, key in enumerate(json.loads(str(stored["edge_keys"])))
            }
            face_values = {tuple(key): stored[f"face{i}"] for i, key in enumerate(json.loads(str(stored["face_keys"])))}
            face_info = json.loads(str(stored["face_info"]))
    except (OSError, KeyError, ValueError, TypeError):
        return None
    return Layout(dim, edge_values, face_values, face_info)


def _write_layout(path, layout: Layout) -> None:
    """Store ``layout`` at ``path`` atomically; a cache that cannot be written is skipped."""
    arrays = {f"edge{i}": values for i, values in enumerate(layout.edge_values.values())}
    arrays.update({f"face{i}": values for i, values in enumerate(layout.face_values.values())})
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(path) as temporary:
            with open(temporary, "wb") as file:
                np.savez(
                    file,
                    dim=layout.dim,
                    edge_keys=json.dumps(list(layout.edge_values)),
                    face_keys=json.dumps(list(layout.face_values)),
                    face_info=json.dumps(layout.face_info),
                    **arrays,
                )
    except OSError:
        pass


def smoothed(geometry, cells: int = RESOLUTION):
    """``geometry`` with the smoothed boundary layout: a Geometry whose boundary map is g(s(p))
    (same name, parameters and surface). Parameters rebound with ``with_params`` get their own
    layout. Idempotent: a geometry already smoothed is returned as it is."""
    if getattr(geometry.boundary_map, "smoothed_from", None) is not None:
        return geometry
    base_map = geometry.boundary_map
    base = geometry

    def boundary_map(points, **values):
        plain = base.with_params(**values)
        return plain.boundary(layout_of(plain, cells).apply(points))

    boundary_map.smoothed_from = base_map
    return replace(geometry, boundary_map=boundary_map)


def with_layout(geometry, layout: str):
    """``geometry`` with the boundary layout named ``layout`` ("smoothed" or "fixed")."""
    if layout == "smoothed":
        return smoothed(geometry)
    if layout == "fixed":
        return unsmoothed(geometry)
    raise GeometryError(f"unknown boundary layout '{layout}' (layouts: {', '.join(LAYOUTS)})")


def trained_layout(checkpoint: dict) -> str:
    """The boundary layout a network was trained on: its configuration's ``boundary_layout``;
    checkpoints from before the key existed were trained on the fixed layout."""
    return (checkpoint.get("config") or {}).get("boundary_layout", "fixed")


def unsmoothed(geometry):
    """The geometry with its own boundary map (the fixed layout)."""
    base_map = getattr(geometry.boundary_map, "smoothed_from", None)
    return geometry if base_map is None else replace(geometry, boundary_map=base_map)

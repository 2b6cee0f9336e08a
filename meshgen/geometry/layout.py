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
   same discrete operator as ``meshgen.methods.winslow``, on the surface's physical points) is zero. The
   normal part is the surface's curvature and is left alone, so the nodes stay exactly on the
   surface. Solved by Newton's method on the residual's components along the surface's tangents
   g_u, g_v (central differences of the map), with the Jacobian by colour-grouped forward
   differences and a backtracking line search. A frozen-coefficient (Picard) step, which solves
   the scalar Winslow operator for the pulled-back residual, leaves out the change of the tangents
   along the surface; on a strongly twisted face that term, the surface's curvature times the
   residual's normal part, makes the smoothest error mode grow, and on a nearly degenerate face
   map (the flower's caps at large amplitude) the pulled-back residual is no step to take
   unchecked. A face that does not converge raises a one-line GeometryError: an unconverged
   layout is never returned;
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
import warnings
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from meshgen import __version__
from meshgen.errors import GeometryError, MeshgenWarning
from meshgen.geometry.cube import edges, faces
from meshgen.geometry.layout_start import harmonic_start, lift
from meshgen.methods.winslow import stencils, winslow_operator
from meshgen.run.atomic import atomic_path

__all__ = [
    "ARC_SAMPLES",
    "DEFAULT_LAYOUT",
    "FACE_MAX_ITER",
    "FACE_TOL",
    "LAYOUTS",
    "LINE_SEARCH_HALVINGS",
    "NEWTON_STEP",
    "RELAX_TOL",
    "RESOLUTION",
    "SOLVER_VERSION",
    "STEP_CELLS",
    "TANGENT_STEP",
    "Layout",
    "LayoutWarning",
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
FACE_TOL = 1e-8  # converged when the largest parameter change of a full Newton step is below this
FACE_MAX_ITER = 30  # Newton steps per face: quadratic convergence takes 5 to 10
LINE_SEARCH_HALVINGS = 12  # a Newton step is halved at most this often before the solve counts as stalled
STEP_CELLS = 1.0  # no node moves further than this many (smallest) cells in one Newton step
NEWTON_STEP = 1e-7  # parametric step of the forward differences that give the Newton Jacobian
RELAX_TOL = 1e-8  # the same at the mesh's resolution (relax_faces): far below the volume solver's 1e-6
SOLVER_VERSION = 2  # part of the cache key: layouts cached by another face solver are solved again
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
    ``face_info``: per face name, the Newton steps, final update and convergence of its surface solve.
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


def _tangents(boundary, axis: int, side: int, U: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The surface's tangents g_u, g_v (N, 3) at face parameters U (N, 2), by central differences
    of the map (steps of TANGENT_STEP, one-sided where the parameter is 0 or 1)."""
    probes = []
    for d in range(2):
        for sign in (1.0, -1.0):
            moved = U.copy()
            moved[:, d] = np.clip(moved[:, d] + sign * TANGENT_STEP, 0.0, 1.0)
            probes.append(moved)
    images = boundary(lift(axis, side, np.concatenate(probes))).reshape(4, -1, 3)
    return tuple((images[2 * d] - images[2 * d + 1]) / (probes[2 * d][:, d] - probes[2 * d + 1][:, d])[:, None] for d in range(2))


def _tangential_residual(X: np.ndarray, tu: np.ndarray, tv: np.ndarray, grid) -> np.ndarray:
    """The Winslow residual of the surface grid X (n_p, n_q, 3) projected on the tangents (the
    interior nodes' tu, tv, each (m_p * m_q, 3)): (m_p, m_q, 2), zero where the grid is solved. NaN
    where a cell has zero area."""
    with np.errstate(divide="ignore", invalid="ignore"):
        residual, _ = winslow_operator(np.ascontiguousarray(np.moveaxis(X, -1, 0)), grid)
    res = np.moveaxis(residual, 0, -1).reshape(-1, 3)
    return np.stack([(tu * res).sum(-1), (tv * res).sum(-1)], axis=-1).reshape(residual.shape[1:] + (2,))


def _jacobian(evaluate, U: np.ndarray, state, F: np.ndarray):
    """Sparse Jacobian (2 m, 2 m) of the tangential residual F (m_p, m_q, 2) by the interior face
    parameters, by forward differences (step NEWTON_STEP) in nine colours: a node's residual
    depends on its 3 x 3 neighbours only, so the nodes with the same (i mod 3, j mod 3) are moved
    together, and only they are mapped again. ``evaluate(U, state, moved)`` gives F after moving
    the nodes of the boolean mask ``moved``."""
    from scipy import sparse

    m_p, m_q = F.shape[:2]
    index = np.arange(m_p * m_q).reshape(m_p, m_q)
    ip, iq = np.meshgrid(np.arange(m_p), np.arange(m_q), indexing="ij")
    rows, cols, vals = [], [], []
    for cp in range(3):
        for cq in range(3):
            owner_p, owner_q = ip + (cp - ip + 1) % 3 - 1, iq + (cq - iq + 1) % 3 - 1  # the moved neighbour
            valid = (owner_p < m_p) & (owner_q < m_q) & (owner_p >= 0) & (owner_q >= 0)
            moved = np.zeros((m_p, m_q), dtype=bool)
            moved[cp::3, cq::3] = True
            for d in range(2):
                trial = U.copy()
                trial[1:-1, 1:-1][moved, d] += NEWTON_STEP
                change = (evaluate(trial, state, moved) - F) / NEWTON_STEP
                for e in range(2):
                    rows.append(2 * index[valid] + e)
                    cols.append(2 * index[owner_p[valid], owner_q[valid]] + d)
                    vals.append(change[..., e][valid])
    size = 2 * m_p * m_q
    return sparse.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(size, size))


@np.errstate(all="ignore")  # a diverging trial step gives inf/NaN, which the solve checks for itself
def surface_grid(boundary, axis: int, side: int, U: np.ndarray, coords, tol: float = FACE_TOL, max_iter: int = FACE_MAX_ITER):
    """The Winslow surface grid of the face ``t[axis] = side`` on the tensor grid of ``coords``
    (the parametric node coordinates along its two tangent axes, increasing order).

    ``U``: (n_p, n_q, 2) face parameters: the sides' values (kept) and a start inside.
    ``boundary``: the geometry's map. Newton's method on the tangential residual (``_jacobian``),
    with a backtracking line search on its 2-norm that also rejects a step folding the grid.
    Returns the solved face parameters (same shape) and ``{"iterations", "final_update",
    "converged"}``: ``final_update`` is the largest parameter change of the last full Newton step,
    and ``converged`` says it fell below ``tol``; it is False when ``max_iter`` steps did not get
    there or the line search found no decrease. The caller decides what an unconverged grid means.
    """
    from scipy.sparse.linalg import splu

    U = np.array(U, dtype=float)
    shape = U.shape[:-1]
    grid = stencils(coords)

    def state_of(U):
        X = boundary(lift(axis, side, U).reshape(-1, 3)).reshape(shape + (3,))
        return X, _tangents(boundary, axis, side, U[1:-1, 1:-1].reshape(-1, 2))

    def evaluate(U, state, moved):
        X, (tu, tv) = state
        X, tu, tv = X.copy(), tu.copy(), tv.copy()
        points = U[1:-1, 1:-1][moved]
        X[1:-1, 1:-1][moved] = boundary(lift(axis, side, points))
        flat = moved.ravel()
        tu[flat], tv[flat] = _tangents(boundary, axis, side, points)
        return _tangential_residual(X, tu, tv, grid)

    state = state_of(U)
    F = _tangential_residual(state[0], *state[1], grid)
    if not np.all(np.isfinite(F)):
        raise GeometryError("boundary layout: the start of a face's surface grid has a zero-area cell")
    norm = float(np.linalg.norm(F))
    update, iterations, converged = np.inf, 0, False
    while iterations < max_iter:
        try:
            step = splu(_jacobian(evaluate, U, state, F), permc_spec="MMD_AT_PLUS_A").solve(-F.ravel()).reshape(F.shape)
        except RuntimeError:  # a singular Jacobian: the face map is degenerate inside the face
            break
        iterations += 1
        update = float(np.abs(step).max())
        if not np.isfinite(update):
            break
        if update < tol:
            U[1:-1, 1:-1] = np.clip(U[1:-1, 1:-1] + step, 0.0, 1.0)
            converged = True
            break
        longest = STEP_CELLS * min(float(np.diff(c).min()) for c in grid.coords)  # the trust region
        for halving in range(LINE_SEARCH_HALVINGS + 1):
            alpha = min(1.0, longest / update) * 0.5**halving
            trial = U.copy()
            trial[1:-1, 1:-1] = np.clip(U[1:-1, 1:-1] + alpha * step, 0.0, 1.0)
            trial_state = state_of(trial)
            trial_F = _tangential_residual(trial_state[0], *trial_state[1], grid)
            trial_norm = float(np.linalg.norm(trial_F))
            if np.isfinite(trial_norm) and trial_norm <= (1.0 - 1e-4 * alpha) * norm:
                break
        else:
            break  # no decrease along the Newton direction: stalled
        U, state, F, norm = trial, trial_state, trial_F, trial_norm
    return U, {"iterations": iterations, "final_update": update, "converged": converged}


class LayoutWarning(MeshgenWarning):
    """A face of the smoothed layout was not solved again at the mesh's resolution (the command
    line prints it as one warning line)."""


def _require_converged(geometry, face_name: str, info: dict, where: str) -> None:
    """Raise a one-line GeometryError when the surface grid of ``face_name`` did not converge."""
    if info["converged"]:
        return
    values = ", ".join(f"{k}={v:g}" for k, v in sorted(geometry.values.items()))
    raise GeometryError(
        f"the smoothed boundary layout of '{geometry.name}' ({values}) does not converge{where}: face {face_name} "
        f"stopped at a parameter update of {info['final_update']:.1e} after {info['iterations']} Newton steps; "
        "mesh it with --boundary-layout fixed (training: --set boundary_layout=fixed)"
    )


def compute_layout(geometry, cells: int = RESOLUTION, max_iter: int = FACE_MAX_ITER) -> Layout:
    """The smoothed layout of ``geometry`` (a Geometry), on a fine grid of ``cells`` per side.
    Raises GeometryError naming the geometry, the face and its last update when a face's surface
    grid does not converge within ``max_iter`` Newton steps: an unconverged layout is never
    returned."""
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
        start = harmonic_start(boundary, face.axis, face.side, coons_start(edge_u, (t, t)), (t, t))
        U, info = surface_grid(boundary, face.axis, face.side, start, (t, t), max_iter=max_iter)
        _require_converged(geometry, face.name, info, "")
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
    as skewed cells). Returns the Newton steps per face name. A face whose grid does not converge
    at this resolution keeps the layout's interpolated nodes (the layout itself is converged:
    ``compute_layout`` raises otherwise), with a LayoutWarning that names it.
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
        U, info = surface_grid(plain, face.axis, face.side, start, face_coords, tol=tol)
        iterations[face.name] = info["iterations"]
        if not info["converged"]:  # keep the solved layout's own nodes on this face, and say so
            warnings.warn(
                f"boundary layout of '{geometry.name}': face {face.name} was not solved again at the mesh's resolution "
                f"(update {info['final_update']:.1e} after {info['iterations']} Newton steps); it keeps the smoothed "
                "layout's interpolated nodes",
                LayoutWarning,
                stacklevel=2,
            )
            continue
        X[face.node_index] = plain(lift(face.axis, face.side, U).reshape(-1, 3)).reshape(U.shape[:-1] + (3,))
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
    meshgen's version, ``SOLVER_VERSION``, the plugin's name and source text (a shape file's: the hash of its content
    and options, ``meshgen.geometry.shapes.loader.content_hash``), its parameter values and ``cells``.
    None for a plugin whose source file cannot be read (its layout is then computed every run)."""
    content = getattr(geometry.boundary_map, "content_hash", None)  # a shape file: its bytes' hash
    try:
        source = content.encode() if content else Path(geometry.source).read_bytes()
    except (OSError, TypeError, ValueError):
        return None
    identity = json.dumps([__version__, SOLVER_VERSION, geometry.name, sorted(geometry.values.items()), cells]).encode()
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

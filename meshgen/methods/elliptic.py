"""Elliptic (Winslow) meshes: the entry points of the one elliptic solver, for a geometry (one
block: ``build_elliptic``, ``elliptic``) and for a block set (``elliptic_blocks``), starting from TFI.

- One block: the discrete Winslow equations of ``meshgen.methods.winslow`` solved for the interior
  nodes by nonlinear multigrid (``meshgen.methods.multigrid``: FAS V-cycles, line-ADI relaxation,
  full-multigrid start, Anderson mixing), boundary nodes fixed on the exact boundary.
- A block set: the same multigrid run on every block at every level, interface nodes solved as
  interior nodes of the whole mesh through a halo layer (``meshgen.methods.multigrid_set``,
  ``meshgen.methods.interfaces``), nodes on flat patches sliding (``meshgen.methods.sliding``).
  A set of one block with nothing to slide is the one-block solve itself.
"""

from __future__ import annotations

import functools
import time
import warnings

import numpy as np

from meshgen.errors import MeshgenWarning, ParameterError
from meshgen.geometry.block_nodes import global_numbering
from meshgen.geometry.blocks import tfi_blocks
from meshgen.geometry.extrusion import extrude, extrusion_of, section_of, sweep_frame
from meshgen.geometry.layout import DEFAULT_LAYOUT, relax_faces, with_layout
from meshgen.methods.face_angles import polish_block_set
from meshgen.methods.multigrid import DEFAULT_MAX_ITER, DEFAULT_TOL, Level, jacobi_residual, solve_winslow, uses_kernels
from meshgen.methods.multigrid_set import solve_set
from meshgen.methods.orthogonal import inner_block, parse_walls, straighten_first_layer
from meshgen.methods.sliding import local_cell_sizes, planar_sliding
from meshgen.methods.surface_sliding import SURFACE_ROUNDS, SURFACE_TOL, slide_on_surfaces, surface_sliding
from meshgen.methods.tfi import check_axes, parametric_grid, tfi
from meshgen.methods.winslow import component_array

__all__ = [
    "DEFAULT_MAX_ITER",
    "DEFAULT_TOL",
    "MAX_CYCLES",
    "ConvergenceWarning",
    "build_elliptic",
    "elliptic",
    "elliptic_blocks",
]


EXTRUSION_TOL = 1e-9  # relative to the characteristic length: a start mesh this close to an extrusion is one


def extruded_solve(X0: np.ndarray, coords, tol: float, max_iter: int, length: float, progress=None, solve=solve_winslow):
    """The Winslow mesh of a one-block start ``X0`` (n1+1, n2+1, n3+1, 3) whose boundary is an
    extrusion along zeta and whose caps are flat, each cap's interior the section's 2D Winslow
    grid (the smoothed boundary layout's): the extrusion of the section's 2D solve; None when the
    start is not such an extrusion.

    An extrusion (to ``EXTRUSION_TOL`` times ``length``): the zeta = 1 cap is the zeta = 0 cap
    moved by one sweep v square to it, and the four side faces are their zeta = 0 edge plus zeta v
    at the parametric zeta nodes (their Winslow grid: a ruled face is developable). Winslow's
    equations keep such a mesh an extrusion (z linear in zeta, every layer the section's 2D
    solution: the 3D operator is |v|^2 times the 2D one, design notes §20), so the mesh is the 2D
    solve of the zeta = 0 cap with its edges fixed, extruded, caps included (they are flat: their
    nodes stay on them). ``solve``: the 2D solver (``solve_winslow``'s arguments). Returns ``(X, info)``
    as ``solve_winslow``'s, with ``extruded`` True."""
    if X0.ndim != 4 or X0.shape[-1] != 3 or min(X0.shape[:3]) < 3:
        return None
    bound = EXTRUSION_TOL * length
    sweep = X0[0, 0, -1] - X0[0, 0, 0]
    height = float(np.linalg.norm(sweep))
    if not height > bound or np.abs(X0[:, :, -1] - X0[:, :, 0] - sweep).max() > bound:
        return None
    unit = sweep / height
    cap = X0[:, :, 0]
    if np.abs((cap - cap[0, 0]) @ unit).max() > bound:  # the cap flat and square to the sweep
        return None
    zeta = np.asarray(coords[2], dtype=float)
    zeta = (zeta - zeta[0]) / (zeta[-1] - zeta[0])
    straight = X0[:, :, :1] + zeta[None, None, :, None] * sweep
    for side in (np.s_[0], np.s_[-1], np.s_[:, 0], np.s_[:, -1]):
        if np.abs(X0[side] - straight[side]).max() > bound:
            return None
    frame = sweep_frame(sweep)  # (2, 3): the coordinate axes themselves for a sweep along one
    section = (cap - cap[0, 0]) @ frame.T
    solved, info = solve(section, coords[:2], tol=tol, max_iter=max_iter, length=length, progress=progress)
    plane = cap[0, 0] + solved @ frame
    X = plane[:, :, None, :] + zeta[None, None, :, None] * sweep
    for side in (np.s_[0], np.s_[-1], np.s_[:, 0], np.s_[:, -1]):  # the side faces as the start holds them
        X[side] = X0[side]
    residual = jacobi_residual(Level(coords, compiled=uses_kernels(coords)), component_array(X), length)  # of the 3D equations
    solver = f"the section's 2D solve, extruded ({info['solver']})"
    return X, {**info, "final_residual": residual, "extruded": True, "solver": solver}


class ConvergenceWarning(MeshgenWarning):
    """The elliptic solver stopped before its tolerance was met."""


def _check_options(tol, max_iter):
    if not (isinstance(tol, (int, float)) and np.isfinite(tol) and tol > 0):
        raise ParameterError("tol", f"{{name}} must be a positive number, got {tol}")
    if isinstance(max_iter, bool) or not isinstance(max_iter, (int, np.integer)) or max_iter < 1:
        raise ParameterError("max_iter", f"{{name}} must be a positive integer, got {max_iter}")


def build_elliptic(
    geometry,
    coords,
    tol: float | None = None,
    max_iter: int | None = None,
    progress=None,
    boundary_layout: str | None = None,
    orthogonal=(),
    device: str | None = None,
):
    """Method ``elliptic`` (meshgen.methods.registry): Winslow mesh of ``geometry`` at parametric node
    coordinates ``coords`` (1D arrays per axis), starting from TFI, whose boundary nodes are the
    geometry's boundary map at the parametric boundary points and stay there.

    ``boundary_layout``: "smoothed" (default) first moves the boundary points within their faces
    (``meshgen.geometry.layout``: arc length on the edges, the surface's 2D Winslow grid on each face,
    solved again at the mesh's resolution by ``relax_faces``);
    "fixed" keeps the geometry's own boundary map (the faces' Coons layout).
    ``orthogonal``: names of walls (``eta0`` ...) that the first cell layer meets at right angles
    (``meshgen.methods.orthogonal``).
    ``device``: "cpu" or None (NumPy/numba, the default), "cuda" (the same multigrid as torch tensor
    operations on the GPU, ``meshgen.methods.multigrid_torch``) or "auto" (cuda when torch sees one).
    Returns ``(X, info)``, X of shape (n1+1, n2+1[, n3+1], dim); ``info`` as ``solve_winslow``'s,
    plus ``boundary_layout`` and ``warnings`` (a list of lines) when the solver did not converge.
    """
    tol = DEFAULT_TOL if tol is None else tol
    max_iter = DEFAULT_MAX_ITER if max_iter is None else max_iter
    _check_options(tol, max_iter)
    walls = parse_walls(orthogonal or (), geometry.dim)
    boundary_layout = DEFAULT_LAYOUT if boundary_layout is None else boundary_layout
    geometry = with_layout(geometry, boundary_layout)
    solve = _solver(device)
    X0 = tfi(geometry, None, coords)
    solved = None
    if boundary_layout == "smoothed":  # an extrusion: its section's 2D solve (extruded_solve)
        solved = extruded_solve(X0, coords, tol, max_iter, geometry.characteristic_length, progress, solve)
    if solved is None and boundary_layout == "smoothed":
        relax_faces(geometry, coords, X0)  # the faces' own discrete Winslow grids (see there)
    if min(len(t) for t in coords) < 3:  # one cell across an axis: every node is a boundary node
        return X0, {
            "iterations": 0,
            "final_update": 0.0,
            "final_residual": 0.0,
            "tol": float(tol),
            "converged": True,
            "seconds": 0.0,
            "boundary_layout": boundary_layout,
            "note": "no interior nodes: the TFI mesh is the mesh",
        }
    if solved is None:
        solved = solve(X0, coords, tol=tol, max_iter=max_iter, length=geometry.characteristic_length, progress=progress)
    X, info = solved
    info["boundary_layout"] = boundary_layout
    if walls:
        block = inner_block(walls, geometry.dim)
        sub_coords = [np.asarray(t, dtype=float)[block[a]] for a, t in enumerate(coords)]
        if min(len(t) for t in sub_coords) < 3:
            raise ParameterError("orthogonal", "{name} needs at least 3 cells across each orthogonal wall's axis")
        for face in walls:
            straighten_first_layer(X, face)
        X[block], second = solve(X[block], sub_coords, tol=tol, max_iter=max_iter, length=geometry.characteristic_length)
        info["orthogonal"] = [face.name for face in walls]
        info["iterations"] += second["iterations"]
        for key in ("final_update", "final_residual", "converged"):
            info[key] = second[key]
        info["seconds"] += second["seconds"]
    return X, _warned(info, tol)


def _solver(device: str | None):
    """The one-grid solver for ``device``: ``solve_winslow`` (NumPy/numba) for None and "cpu", else
    ``solve_winslow_torch`` on that torch device ("cuda", "cuda:1"; imports torch). The caller
    resolves "auto" (``meshgen.neural.device.inference_device``)."""
    if device in (None, "cpu"):
        return solve_winslow
    if not (isinstance(device, str) and device.split(":")[0] == "cuda"):
        raise ParameterError("device", f"{{name}} must be cpu or cuda for the elliptic method, got {device!r}")
    from meshgen.methods.multigrid_torch import solve_winslow_torch

    return functools.partial(solve_winslow_torch, device=device)


def _warned(info: dict, tol: float) -> dict:
    if not info["converged"]:
        info["warnings"] = [
            f"elliptic solver did not converge: after {info['iterations']} cycle(s) the largest node update is "
            f"{info['final_update']:.3g} of the characteristic length (tolerance {tol:g}), residual "
            f"{info['final_residual']:.3g}; raise the iteration limit or the tolerance"
        ]
    return info


def elliptic(
    geometry,
    dims=None,
    coords=None,
    *,
    tol: float = DEFAULT_TOL,
    max_iter: int = DEFAULT_MAX_ITER,
    progress=None,
    boundary_layout: str | None = None,
    orthogonal=(),
    device: str | None = None,
):
    """Elliptic (Winslow) mesh of ``geometry``: the Python entry point.

    ``dims``: cells per axis (n1, n2[, n3]); ``coords``: optional 1D parametric node positions per
    axis instead (e.g. clustered towards a wall). ``tol``, ``max_iter``, ``progress``: see
    ``solve_winslow``; ``boundary_layout``, ``orthogonal``, ``device``: see ``build_elliptic``.
    Returns ``(X, info)``; warns (ConvergenceWarning) when not converged.
    """
    if coords is None:
        coords = parametric_grid(dims)
    check_axes(geometry, coords)
    X, info = build_elliptic(
        geometry,
        coords,
        tol=tol,
        max_iter=max_iter,
        progress=progress,
        boundary_layout=boundary_layout,
        orthogonal=orthogonal,
        device=device,
    )
    for line in info.get("warnings", []):
        warnings.warn(line, ConvergenceWarning, stacklevel=2)
    return X, info


MAX_CYCLES = 200  # V-cycles of a block set's solve


def elliptic_blocks(
    block_set,
    tol: float | None = None,
    max_iter: int | None = None,
    progress=None,
    slide: bool = True,
    initial=None,
    as_extrusion: bool = True,
    slide_section: bool = True,
    orthogonality: bool = True,
):
    """Winslow mesh of the block set ``block_set`` (``meshgen.geometry.blocks.BlockSet``): (list of
    node arrays, one per block, interface nodes identical in every block; info dict as
    ``solve_winslow``'s, with ``sweeps``, the V-cycles).

    ``tol``: stop when a V-cycle moves no node by more than ``tol`` times its local cell size
    (``meshgen.methods.sliding.local_cell_sizes``: its shortest grid edge in the start mesh; the
    measure a flow solver feels, so a straight extrusion is one to that relative accuracy at every
    resolution; ``final_update`` is in that unit); ``max_iter``: most V-cycles. ``slide`` (default
    on): nodes on flat patches (a pipe's inlet, a channel's straight walls) slide in their plane,
    or along the line where two meet, so that grid lines meet them at right angles
    (``meshgen.methods.sliding.planar_sliding``), else every boundary node stays where the TFI put
    it. ``initial``: the node arrays to start from (conforming, on the boundary: a network's
    corrected mesh; copied), else the TFI.

    A set of one block with no interface and nothing to slide is the one-block solve
    (``solve_winslow``, its stopping rule relative to the block set's length): the same mesh.
    ``as_extrusion`` (default on): an extruded set (``meshgen.geometry.extrusion``) started from
    its TFI with its flat caps sliding is solved as its 2D section and extruded, the fixed point
    of its 3D equations (design notes §20); off, the 3D equations are solved. ``slide_section``
    (default on): that section's flat sides slide too; off, its boundary nodes stay (a swept CAD
    cap whose straight side joins an arc smoothly: sliding would carry nodes past the joint).
    ``orthogonality`` (default on): where the Winslow mesh is less orthogonal than its start (its
    largest checkMesh non-orthogonality of internal or of boundary faces is larger), its interior
    nodes are polished (``meshgen.methods.face_angles.polish_block_set``; ``info["orthogonality"]``)."""
    tol = DEFAULT_TOL if tol is None else tol
    max_cycles = MAX_CYCLES if max_iter is None else max_iter
    start = time.perf_counter()
    extrusion = extrusion_of(block_set) if as_extrusion and slide and initial is None and block_set.dim == 3 else None
    if extrusion is not None:
        section = section_of(block_set, extrusion)
        planes, info = elliptic_blocks(
            section, tol=tol, max_iter=max_iter, progress=progress, slide=slide_section, orthogonality=orthogonality
        )
        Xs = extrude(extrusion, planes, block_set.coords[0][2])
        solver = info.get("solver", "the one-block solve")
        info = {**info, "solver": f"the 2D section's elliptic mesh, extruded ({solver})", "extruded": True}
        return Xs, {**info, "seconds": time.perf_counter() - start}
    Xs = tfi_blocks(block_set) if initial is None else [np.array(X, dtype=float) for X in initial]
    start_mesh = Xs  # the solves below make new arrays: the polish's reference needs no copy
    if min(min(shape) for shape in block_set.node_shapes) < 3:
        return Xs, {"sweeps": 0, "converged": True, "note": "a block has one cell across an axis: the TFI mesh is the mesh"}
    numbering, count = global_numbering(block_set)
    sliding = planar_sliding(block_set, Xs, numbering, count) if slide else None
    on_surfaces = surface_sliding(block_set, numbering, count, sliding) if slide else []
    if len(Xs) == 1 and not block_set.interfaces and sliding is None and not on_surfaces:
        X, info = solve_winslow(
            Xs[0], block_set.coords[0], tol=tol, max_iter=max_cycles, length=block_set.length, progress=progress
        )
        Xs, polished = polish_block_set(block_set, [X], start_mesh) if orthogonality else ([X], None)
        info = {**info, "sweeps": info["iterations"], "orthogonality": polished}
        return Xs, {**info, "seconds": time.perf_counter() - start}
    values, cycles, update, levels = solve_set(block_set, Xs, tol, max_cycles, slide, progress)
    rounds, sizes = 0, local_cell_sizes(block_set, Xs, numbering, count) if on_surfaces else None
    while on_surfaces and rounds < SURFACE_ROUNDS:  # nodes on sliding projected faces move on their surface
        rounds += 1
        moved = slide_on_surfaces(on_surfaces, values, sizes)
        values, more, update, levels = solve_set(block_set, [values[ids] for ids in numbering], tol, max_cycles, slide)
        cycles += more
        if moved < SURFACE_TOL:
            break
    Xs = [values[ids] for ids in numbering]
    Xs, polished = polish_block_set(block_set, Xs, start_mesh) if orthogonality else (Xs, None)
    info = {
        "solver": "nonlinear multigrid over the block set (FAS V(2,2) cycles on every block, halo layers at the "
        "interfaces, sliding nodes and junctions relaxed on every level, Anderson mixing)",
        "sweeps": cycles,
        "iterations": cycles,
        "final_update": float(update),
        "final_residual": None,
        "tol": float(tol),
        "converged": bool(update < tol),
        "seconds": time.perf_counter() - start,
        "levels": levels,
        "surface_rounds": rounds,
        "orthogonality": polished,
    }
    if not info["converged"]:
        info["warnings"] = [
            f"multi-block elliptic solver did not converge: after {cycles} cycle(s) the largest node update is "
            f"{update:.3g} of the local cell size (tolerance {tol:g}); raise --max-iter or --tol"
        ]
    return Xs, info

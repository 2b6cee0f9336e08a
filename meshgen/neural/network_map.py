"""The map of a trained network on a tensor grid: ``mesh_from_model`` (the node array of a model,
soft or exact boundary), ``model_boundary_errors`` (its boundary error from the grid's faces alone)
and ``evaluate_network``, the forward pass on the device asked for.

On a CPU the forward pass is ``meshgen.neural.mlp_numpy``'s (a numba kernel of fixed-order
float32 arithmetic per node on large grids; BLAS on small grids, always evaluated whole: either way
a mesh made block by block equals the whole-grid one bit for bit), so meshing with a trained model
imports no torch; torch (``meshgen.neural.gpu_forward``) runs it on a GPU only: ``--device cuda``, or
``auto`` where ``meshgen.neural.device`` finds one.

A section model (``model["extruded"]``: the 2D network of an extruded one-block geometry's
section, ``meshgen.geometry.extrusion``) maps the section once, on the grid's first two axes (its
base is the laid-out zeta = 0 cap itself, not the TFI of the cap's edges), and its mesh is that
plane swept along zeta: an exact extrusion at every --dims.
"""

from __future__ import annotations

import threading

import numpy as np

from meshgen.errors import MeshgenError
from meshgen.geometry import cube
from meshgen.geometry.extrusion import extrusion_from, geometry_extrusion
from meshgen.geometry.layout import unsmoothed
from meshgen.methods.tfi import add_face_terms, boundary_faces, face_terms, face_values, tfi
from meshgen.neural.checkpoint_data import CheckpointError, check_network
from meshgen.neural.device import inference_device
from meshgen.neural.mlp_numpy import CHUNK_NODES, compiled_for, finite_output, forward_on_grid

__all__ = [
    "SMALL_GRIDS_KEPT",
    "small_grid_network",
    "CHUNK_NODES",
    "bubble_on_grid",
    "evaluate_network",
    "exact_boundary_terms",
    "is_section_model",
    "map_on_block",
    "mesh_from_model",
    "model_boundary_errors",
    "section_plane",
    "spans_cube",
]

SMALL_GRIDS_KEPT = 2  # small grids whose network values are remembered (a mesh and its faces, per request)


def evaluate_network(
    model: dict, coords, out=None, chunk: int = CHUNK_NODES, workers=None, device: str = "cpu", compiled=None
) -> np.ndarray:
    """The network N(xi) of ``model`` (a ``checkpoint["model"]`` description, weights as NumPy
    arrays or tensors) at the tensor grid of the 1D parametric coordinates ``coords``: (n1 * n2
    [* n3], d) float64, nodes in C order, written into ``out`` when given. ``device``: "cpu",
    "cuda" or "auto" (``inference_device``); only cuda imports torch. ``compiled``: on a CPU, the
    numba kernel or NumPy (the same bits; default by this grid's size: ``compiled_for``)."""
    if inference_device(device) == "cuda":
        from meshgen.neural.gpu_forward import evaluate_on_grid  # torch

        return evaluate_on_grid(model, coords, out=out, device="cuda")
    check_network(model)
    return finite_output(forward_on_grid(model, coords, out=out, chunk=chunk, workers=workers, compiled=compiled))


def bubble_on_grid(coords) -> np.ndarray:
    """b(xi) = 4^d prod_i xi_i (1 - xi_i) on the tensor grid of ``coords``: (n1, n2 [, n3])."""
    dim = len(coords)
    result = np.ones([1] * dim)
    for axis, c in enumerate(coords):
        c = np.asarray(c, dtype=float)
        result = result * (4.0 * c * (1.0 - c)).reshape([-1 if d == axis else 1 for d in range(dim)])
    return result


def spans_cube(coords) -> bool:
    """Whether the 1D coordinates ``coords`` run from 0 to 1 on every axis (a whole grid)."""
    return bool(coords) and all(c[0] == 0.0 and c[-1] == 1.0 for c in coords)


def is_section_model(model: dict, coords) -> bool:
    """Whether ``model`` is the 2D section network of an extruded one-block geometry
    (``model["extruded"]``, ``meshgen.geometry.extrusion``) asked for on the 3D grid ``coords``: its
    mesh is the section's extruded (a block set's section networks are asked for on 2D grids)."""
    return "extruded" in model and len(coords) == int(model["dim"]) + 1


def section_plane(model: dict, geometry, coords, device: str = "cpu") -> np.ndarray:
    """The section network's map on the grid of ``coords[:2]`` in the zeta = 0 plane: (n1, n2, 3)
    float64, C(xi, eta) + scale b(xi, eta) (N1 e1 + N2 e2), C the laid-out 3D ``geometry``'s zeta = 0 cap (the section's base in place of TFI,
    ``meshgen.neural.problem.Problem.interior_map``), N the 2D network in the frame's coordinates."""
    if geometry is None:
        raise MeshgenError("an exact-boundary model needs its geometry to be evaluated")
    extrusion = extrusion_from(model["extruded"])
    own = geometry_extrusion(unsmoothed(geometry))  # tested on the geometry's own boundary map
    if own is None or not own.matches(model["extruded"], geometry.characteristic_length):
        raise CheckpointError(
            f"the model maps the section of an extruded geometry, and '{geometry.name}' with these parameters is not "
            "that extrusion (design notes §20)"
        )
    plane = [np.asarray(c, dtype=float) for c in coords[:2]]
    shape = tuple(len(c) for c in plane)
    grid = np.stack(np.meshgrid(*plane, indexing="ij"), axis=-1).reshape(-1, 2)
    cap = geometry.boundary(np.column_stack([grid, np.zeros(len(grid))])).reshape(*shape, 3)
    N = evaluate_network(model, plane, device=device).reshape(*shape, 2)
    N *= (float(model["scale"]) * bubble_on_grid(plane))[..., None]
    return cap + N @ extrusion.frame


def exact_boundary_terms(model: dict, geometry, coords, values=None, device: str = "cpu"):
    """What :func:`map_on_block` adds to the network of ``model`` on the grid of ``coords`` (spanning
    the cube): the TFI face terms (``meshgen.methods.tfi.face_terms``, face-sized; ``values`` the
    boundary map at the face nodes when the caller has them) of an exact-boundary model, the
    :func:`section_plane` of a section model, None for a soft-boundary model."""
    if is_section_model(model, coords):
        return section_plane(model, geometry, coords, device)
    if not model["exact_boundary"]:
        return None
    if geometry is None:
        raise MeshgenError("an exact-boundary model needs its geometry to be evaluated")
    return face_terms(face_values(geometry.boundary, coords) if values is None else values, coords)


def extruded_block(model: dict, plane: np.ndarray, coords, block) -> np.ndarray:
    """The nodes ``block`` of a section model's mesh: plane + zeta direction, (m1, m2, m3, 3) float64
    (``plane`` from :func:`section_plane` on the whole grid, so any block has the whole mesh's bits)."""
    direction = np.asarray(model["extruded"]["direction"], dtype=float)
    zeta = np.asarray(coords[2], dtype=float)[block[2]]
    return plane[block[0], block[1]][:, :, None, :] + zeta[None, None, :, None] * direction


_SMALL_GRIDS: list = []  # [(model, coordinate bytes, network values)]: the last few small grids evaluated
_SMALL_GRIDS_LOCK = threading.Lock()


def small_grid_network(model: dict, coords, workers=None) -> np.ndarray:
    """N(xi) of ``model`` on the whole tensor grid of ``coords`` (m1, .., d) float64, by BLAS
    products in the one partition of ``forward_on_grid`` (so the same bits on every call, whatever
    the thread count), remembered for the last few grids: the blocks and faces of a small mesh made
    block by block (the chunked path, a boundary-error pass) take their values from it."""
    key = tuple(np.asarray(c, dtype=float).tobytes() for c in coords)
    with _SMALL_GRIDS_LOCK:
        for known, known_key, values in _SMALL_GRIDS:
            if known is model and known_key == key:
                return values
        shape = tuple(len(c) for c in coords)
        values = evaluate_network(model, coords, workers=workers, compiled=False).reshape(*shape, len(coords))
        values.setflags(write=False)
        _SMALL_GRIDS.insert(0, (model, key, values))
        del _SMALL_GRIDS[SMALL_GRIDS_KEPT:]
        return values


def map_on_block(model: dict, coords, block=None, tfi_terms=None, workers=None, device: str = "cpu") -> np.ndarray:
    """The physical map of ``model`` on the nodes ``block`` (one slice per axis, default all) of the
    tensor grid of ``coords``: (m1, .., d) float64. Soft boundary: center + scale N(xi); exact:
    scale b(xi) N(xi) + TFI(xi), the TFI from ``tfi_terms`` (:func:`exact_boundary_terms`, made on
    the whole grid). A node's value is the same sequence of operations in any block (the network's
    per-node arithmetic is fixed: ``meshgen.neural.mlp_numpy.forward_tile``), so a mesh made block
    by block equals the whole-grid one bit for bit. The compiled kernel or BLAS is chosen by the
    whole grid's size, so every block of a mesh takes the whole mesh's path; on BLAS (small grids)
    the block is cut from the whole grid's values (:func:`small_grid_network`)."""
    dim = len(coords)
    block = tuple(block) if block is not None else (slice(None),) * dim
    if is_section_model(model, coords):
        return extruded_block(model, tfi_terms, coords, block)
    sub_coords = [c[b] for c, b in zip(coords, block)]
    shape = tuple(len(c) for c in sub_coords)
    compiled = compiled_for(model, int(np.prod([len(c) for c in coords])))  # by the whole grid: one path per mesh
    if compiled or inference_device(device) == "cuda":
        X = evaluate_network(model, sub_coords, workers=workers, device=device, compiled=compiled).reshape(*shape, dim)
    else:  # a small grid on BLAS: its nodes' bits depend on the partition, so always the whole grid's
        X = small_grid_network(model, coords, workers)[block].copy()
    scale = float(model["scale"])
    if not model["exact_boundary"]:
        X *= scale
        X += np.asarray(model["center"], dtype=float)
        return X
    X *= (scale * bubble_on_grid(sub_coords))[..., None]
    return add_face_terms(tfi_terms, coords, X, block)


def mesh_from_model(
    model: dict, coords, geometry=None, chunk: int = CHUNK_NODES, workers=None, device: str = "cpu"
) -> np.ndarray:
    """The physical map of ``model`` (a ``checkpoint["model"]`` description) on the tensor grid of
    ``coords``: the node array X, shape (len(coords[0]), ..., d), float64.

    Soft boundary: X = center + scale N(xi). Exact boundary: X = TFI(xi) + scale b(xi) N(xi), which
    needs ``geometry`` (the bound Geometry the model was trained on). Section model: the section's
    map extruded (:func:`section_plane`, :func:`extruded_block`). ``chunk`` is kept for
    callers of 0.2; the result does not depend on it.
    """
    coords = [np.asarray(c, dtype=float) for c in coords]
    if is_section_model(model, coords) or not model["exact_boundary"] or spans_cube(coords):
        terms = exact_boundary_terms(model, geometry, coords, device=device)
        return map_on_block(model, coords, None, terms, workers, device)
    if geometry is None:
        raise MeshgenError("an exact-boundary model needs its geometry to be evaluated")
    # a grid that does not span the cube: the direct form
    shape = tuple(len(c) for c in coords)
    X = evaluate_network(model, coords, workers=workers, device=device).reshape(*shape, len(coords))
    X *= (float(model["scale"]) * bubble_on_grid(coords))[..., None]
    X += tfi(geometry, None, coords)
    return X


def model_boundary_errors(model: dict, geometry, coords, device: str = "cpu", values=None, terms=None) -> list[np.ndarray]:
    """:func:`boundary_errors` of the map of ``model`` (a ``checkpoint["model"]`` description) on
    the tensor grid of ``coords``, for a caller that never holds the whole node array: the map is
    evaluated on each face of the grid alone (face-sized work) by :func:`map_on_block`, the same
    bits as in the whole grid. ``values``: the boundary map at the face nodes
    (``meshgen.methods.tfi.face_values``), ``terms``: :func:`exact_boundary_terms`, when the
    caller has them (at 1000^3 each is seconds of work on 6e6 face nodes)."""
    coords = [np.asarray(c, dtype=float) for c in coords]
    if not spans_cube(coords):  # the direct form's map, face by face
        errors = []
        for index, points in boundary_faces(coords):
            axis = next(d for d, i in enumerate(index) if not isinstance(i, slice))
            face_coords = list(coords)
            face_coords[axis] = coords[axis][[index[axis]]]
            on_face = np.take(mesh_from_model(model, face_coords, geometry, device=device), 0, axis=axis)
            errors.append(geometry.boundary(points).reshape(on_face.shape) - on_face)
        return errors
    values = face_values(geometry.boundary, coords) if values is None else values
    terms = exact_boundary_terms(model, geometry, coords, values=values) if terms is None else terms
    errors = []
    for face, g in zip(cube.faces(len(coords)), values):
        end = len(coords[face.axis]) - 1 if face.side else 0
        block = tuple(slice(end, end + 1) if d == face.axis else slice(None) for d in range(len(coords)))
        errors.append(g - np.take(map_on_block(model, coords, block, terms, device=device), 0, axis=face.axis))
    return errors

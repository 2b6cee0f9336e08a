"""Boundary correction of a mapped grid (NumPy only): X = N + TFI[g - N].

The boundary nodes of a structured grid sit at known parametric points, where the exact boundary
is the geometry's boundary map g. A map N that misses it (a trained network's) becomes
X = N + TFI[g - N]: the error g - N at the face nodes, interpolated into the volume by the same
Gordon-Hall sum as TFI. Exact on the boundary, smooth inside; the face terms are made once, and
any block of the grid can be corrected from them (``correction_terms``, ``add_correction_terms``;
the errors from the grid's faces alone: ``meshgen.neural.network_map.model_boundary_errors``), which
is how the chunked path (``meshgen.run.chunked``) corrects a mesh larger than memory.
"""

from __future__ import annotations

import numpy as np

from meshgen.geometry import cube
from meshgen.methods.tfi import add_face_terms, blending, boundary_faces, face_terms, face_values
from meshgen.quality.structured import cell_metrics

__all__ = [
    "CORRECTION_POWER",
    "ERROR_DEFINITION",
    "add_boundary_correction",
    "add_correction_terms",
    "boundary_errors",
    "correct_boundary",
    "correction_terms",
    "error_figures",
    "inverted_cells",
    "multilinear",
    "snap_to_boundary",
]

CORRECTION_POWER = 8  # blending (1 - t)^p, t^p of the boundary correction (meshgen.methods.tfi.blending)


def boundary_errors(X: np.ndarray, geometry, coords, values=None) -> list[np.ndarray]:
    """The boundary error field g - X at the face nodes of the tensor grid of ``coords`` (1D
    parametric node coordinates per axis, from 0 to 1): per face, in ``meshgen.geometry.cube`` order, an
    array (face nodes..., d), g the geometry's boundary map at the nodes' parametric points
    (``values``: g as ``meshgen.methods.tfi.face_values`` gives it, when the caller has it).

    ``X`` (n1+1, .., d) need only hold the face nodes (a block-wise caller may fill just those)."""
    values = face_values(geometry.boundary, coords) if values is None else values
    return [g - X[index] for g, (index, _) in zip(values, boundary_faces(coords))]


def snap_to_boundary(out: np.ndarray, values, coords, block=None) -> np.ndarray:
    """Set the face nodes of the node array ``out`` to the boundary map's ``values``
    (``meshgen.methods.tfi.face_values`` on the grid of ``coords``) exactly: the whole grid, or
    with ``block`` (one slice per axis) the face nodes inside that block, ``out`` of its shape.
    X + (g - X) is g only to round-off; after this the boundary nodes are g's bits. Returns ``out``."""
    dim = len(coords)
    block = tuple(block) if block is not None else (slice(None),) * dim
    for face, g in zip(cube.faces(dim), values):
        end = len(coords[face.axis]) - 1 if face.side else 0
        first, last, _ = block[face.axis].indices(len(coords[face.axis]))
        if first <= end < last:
            index = tuple(end - first if d == face.axis else slice(None) for d in range(dim))
            out[index] = g[tuple(b for d, b in enumerate(block) if d != face.axis)]
    return out


def error_figures(errors, geometry) -> dict:
    """Max and mean of |g(xi) - X(xi)| over the boundary nodes of :func:`boundary_errors`: the
    distance of each boundary node from the geometry's boundary map at the node's own parametric
    point (an upper bound of its distance from the surface). JSON-ready."""
    dim = len(errors) // 2
    largest, total, count = 0.0, 0.0, 0
    for number, error in enumerate(errors):
        distance = np.linalg.norm(error, axis=-1)
        largest = max(largest, float(distance.max()))
        # For the mean, each node once: edges shared with the faces of an earlier axis are theirs.
        axis = number // 2
        fresh = tuple(slice(1, -1) if d < axis else slice(None) for d in range(dim) if d != axis)
        total += float(distance[fresh].sum())
        count += distance[fresh].size
    length = float(geometry.characteristic_length)
    return {
        "max": largest,
        "mean": total / count,
        "max_rel": largest / length,
        "characteristic_length": length,
        "definition": ERROR_DEFINITION,
    }


ERROR_DEFINITION = "distance of each boundary node from the geometry's boundary map at the node's parametric point"


def multilinear(corner_values: np.ndarray, coords, block=None) -> np.ndarray:
    """The multilinear interpolant of values at the 2^d corners of the cube (``corner_values``
    (2^d, c), in ``meshgen.geometry.cube.corners`` order) on the tensor grid of ``coords``, or on its
    ``block`` (one slice per axis): (n1, .., c)."""
    dim = len(coords)
    block = tuple(block) if block is not None else (slice(None),) * dim
    axes = [np.asarray(c, dtype=float)[b] for c, b in zip(coords, block)]
    # Axis by axis, last first: the corner values (2, .., 2, c) become (2, .., n_d, .., n_last, c),
    # each step one blend of two arrays, so only the last step (axis 0) is of the grid's size. Every
    # node's value is the same sequence of operations on the 1D blending values of its own
    # coordinates, whatever the block.
    values = np.asarray(corner_values, dtype=float).reshape((2,) * dim + corner_values.shape[1:])
    for axis in reversed(range(dim)):
        shape = (-1,) + (1,) * (dim - axis)  # along the grid axis, broadcast over the later axes and the components
        low, high = (blending(axes[axis], side).reshape(shape) for side in (0, 1))
        before = (slice(None),) * axis
        values = low * values[before + (0, None)] + high * values[before + (1, None)]
    return values


def correction_terms(errors, coords) -> tuple:
    """What the boundary correction of the error field ``errors`` (from :func:`boundary_errors`, on
    the grid of ``coords``) needs for any block of the grid, made once (face-sized): the errors at
    the 2^d corners, and the face terms (``meshgen.methods.tfi.face_terms``, blending power
    ``CORRECTION_POWER``) of the rest, the error minus the corners' multilinear interpolant."""
    dim = len(coords)
    corner_points = cube.corners(dim)
    corner_values = np.empty((len(corner_points), errors[0].shape[-1]))
    for number, corner in enumerate(corner_points):  # each corner from the face xi = its first coordinate
        face = errors[int(corner[0])]
        corner_values[number] = face[tuple(-1 if c else 0 for c in corner[1:])]
    rest = []
    for face, error in zip(cube.faces(dim), errors):
        face_coords = [c if d != face.axis else np.array([float(face.side)]) for d, c in enumerate(coords)]
        on_face = np.take(multilinear(corner_values, face_coords), 0, axis=face.axis)
        rest.append(error - on_face)
    return corner_values, face_terms(rest, coords, CORRECTION_POWER)


def add_correction_terms(terms, coords, out: np.ndarray, block=None) -> np.ndarray:
    """Add the correction of :func:`correction_terms` ``terms`` to ``out`` in place: the whole node
    array, or with ``block`` (one slice per axis) the nodes ``X[block]``. Returns ``out``."""
    corner_values, rest = terms
    out += multilinear(corner_values, coords, block)
    return add_face_terms(rest, coords, out, block, CORRECTION_POWER)


def add_boundary_correction(out: np.ndarray, errors, coords, block=None) -> np.ndarray:
    """Add the correction of the boundary error field ``errors`` (from :func:`boundary_errors`, on
    the grid of ``coords``) to ``out`` in place: the whole node array (n1+1, .., d), or with
    ``block`` (one slice per axis) the nodes ``X[block]`` of a block of the grid, ``out`` then of
    that block's shape. Returns ``out``.

    The correction is the multilinear interpolant of the errors at the cube's corners, plus the
    transfinite interpolation of the rest of the error, blended with (1 - t)^p and t^p
    (p = ``CORRECTION_POWER``) instead of TFI's 1 - t and t. It equals the error on the boundary,
    so the corrected nodes lie on the geometry's boundary map to round-off. Inside, the corners'
    part moves the whole volume (a network shifted as a whole is shifted back as a whole), and
    the rest fades smoothly to zero within a layer about 1/p of each axis deep: it repairs the
    outer layers where the network missed the boundary and leaves the interior, where the Winslow
    loss made the network good, as it was. (Linear blending spreads every wrinkle of the error
    through the whole volume: measured, 0.6 to 1.9 degrees of mean min angle lost on topcurve and
    canal.)"""
    return add_correction_terms(correction_terms(errors, coords), coords, out, block)


def correct_boundary(X: np.ndarray, geometry, coords, count_inverted: bool = False) -> dict:
    """Correct node array ``X`` (n1+1, .., d) of the tensor grid ``coords`` in place to
    X + TFI[g - X] (:func:`add_boundary_correction`), the boundary nodes then exactly g
    (:func:`snap_to_boundary`: what a block-wise caller does, ``meshgen.run.chunked``). Returns what it did, JSON-ready:
    ``error_before`` (:func:`error_figures` of the uncorrected nodes); with ``count_inverted``
    also ``inverted_before`` / ``inverted_after`` / ``inverted_by_correction``: inverted cells of
    the whole mesh (two quality passes over it)."""
    values = face_values(geometry.boundary, coords)
    errors = boundary_errors(X, geometry, coords, values)
    before = inverted_cells(X) if count_inverted else None
    snap_to_boundary(add_boundary_correction(X, errors, coords), values, coords)
    info = {"corrected": True, "error_before": error_figures(errors, geometry)}
    if count_inverted:
        after = inverted_cells(X)
        info.update(
            inverted_before=int(np.count_nonzero(before)),
            inverted_after=int(np.count_nonzero(after)),
            inverted_by_correction=int(np.count_nonzero(after & ~before)),
        )
    return info


def inverted_cells(X: np.ndarray) -> np.ndarray:
    """Per cell (n1, n2 [, n3]) of node array ``X``: inverted as ``meshgen.quality`` counts it
    (scaled Jacobian <= 0 at a corner, or degenerate; 2D against the mesh's orientation)."""
    return cell_metrics(X)["scaled_jacobian"].reshape(tuple(n - 1 for n in X.shape[:-1])) <= 0

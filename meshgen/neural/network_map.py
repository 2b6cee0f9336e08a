"""The map of a trained network on a tensor grid: ``mesh_from_model`` (the node array of a model,
soft or exact boundary), ``model_boundary_errors`` (its boundary error from the grid's faces alone)
and ``evaluate_network``, the forward pass on the device asked for.

On a CPU the forward pass is NumPy's (``meshgen.neural.mlp_numpy``: a tanh MLP is a few float32 matrix
products), so meshing with a trained model imports no torch; torch (``meshgen.neural.gpu_forward``)
runs it on a GPU only: ``--device cuda``, or ``auto`` where ``meshgen.neural.device`` finds one.
"""

from __future__ import annotations

import numpy as np

from meshgen.errors import MeshgenError
from meshgen.methods.tfi import boundary_faces, tfi, transfinite_on_grid
from meshgen.neural.checkpoint_data import check_network
from meshgen.neural.device import inference_device
from meshgen.neural.mlp_numpy import CHUNK_NODES, finite_output, forward_on_grid

__all__ = ["CHUNK_NODES", "bubble_on_grid", "evaluate_network", "mesh_from_model", "model_boundary_errors"]


def evaluate_network(model: dict, coords, out=None, chunk: int = CHUNK_NODES, workers=None, device: str = "cpu") -> np.ndarray:
    """The network N(xi) of ``model`` (a ``checkpoint["model"]`` description, weights as NumPy
    arrays or tensors) at the tensor grid of the 1D parametric coordinates ``coords``: (n1 * n2
    [* n3], d) float64, nodes in C order, written into ``out`` when given. ``device``: "cpu",
    "cuda" or "auto" (``inference_device``); only cuda imports torch."""
    if inference_device(device) == "cuda":
        from meshgen.neural.gpu_forward import evaluate_on_grid  # torch

        return evaluate_on_grid(model, coords, out=out, device="cuda")
    check_network(model)
    return finite_output(forward_on_grid(model, coords, out=out, chunk=chunk, workers=workers))


def bubble_on_grid(coords) -> np.ndarray:
    """b(xi) = 4^d prod_i xi_i (1 - xi_i) on the tensor grid of ``coords``: (n1, n2 [, n3])."""
    dim = len(coords)
    result = np.ones([1] * dim)
    for axis, c in enumerate(coords):
        c = np.asarray(c, dtype=float)
        result = result * (4.0 * c * (1.0 - c)).reshape([-1 if d == axis else 1 for d in range(dim)])
    return result


def mesh_from_model(
    model: dict, coords, geometry=None, chunk: int = CHUNK_NODES, workers=None, device: str = "cpu"
) -> np.ndarray:
    """The physical map of ``model`` (a ``checkpoint["model"]`` description) on the tensor grid of
    ``coords``: the node array X, shape (len(coords[0]), ..., d), float64.

    Soft boundary: X = center + scale N(xi). Exact boundary: X = TFI(xi) + scale b(xi) N(xi), which
    needs ``geometry`` (the bound Geometry the model was trained on).
    """
    coords = [np.asarray(c, dtype=float) for c in coords]
    shape = tuple(len(c) for c in coords)
    dim = len(coords)
    X = evaluate_network(model, coords, chunk=chunk, workers=workers, device=device).reshape(*shape, dim)
    scale = float(model["scale"])
    if not model["exact_boundary"]:
        X *= scale
        X += np.asarray(model["center"], dtype=float)
        return X
    if geometry is None:
        raise MeshgenError("an exact-boundary model needs its geometry to be evaluated")
    X *= (scale * bubble_on_grid(coords))[..., None]
    if coords and all(c[0] == 0.0 and c[-1] == 1.0 for c in coords):
        transfinite_on_grid(geometry.boundary, coords, out=X)
    else:  # a grid that does not span the cube: the direct form
        X += tfi(geometry, None, coords)
    return X


def model_boundary_errors(model: dict, geometry, coords, device: str = "cpu") -> list[np.ndarray]:
    """:func:`boundary_errors` of the map of ``model`` (a ``checkpoint["model"]`` description) on
    the tensor grid of ``coords``, for a caller that never holds the whole node array: the map is
    evaluated on each face of the grid alone (face-sized work), as :func:`mesh_from_model` would
    evaluate those nodes in the whole grid."""
    errors = []
    for index, points in boundary_faces(coords):
        axis = next(d for d, i in enumerate(index) if not isinstance(i, slice))
        face_coords = [np.asarray(c, dtype=float) for c in coords]
        face_coords[axis] = face_coords[axis][[index[axis]]]
        values = np.take(mesh_from_model(model, face_coords, geometry, device=device), 0, axis=axis)
        errors.append(geometry.boundary(points).reshape(values.shape) - values)
    return errors

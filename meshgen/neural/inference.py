"""Evaluation of a trained network on a tensor grid of any size (torch kernels, CPU threads or a GPU).

``evaluate_on_grid`` and ``mesh_from_model``. A [85]*4 network on 101^3 nodes is about
4.6e10 flop, nearly all in the three 85 x 85 products. Three things keep it near the matrix-product
bound on a small CPU:

- no autograd (``torch.inference_mode``), ``addmm`` into buffers allocated once, ``tanh_`` in place;
- chunks of ``CHUNK_NODES`` nodes, so a chunk's activations (8192 x 85 float32, 2.8 MB) stay in
  cache between layers (chunks of 131072 measured twice as slow);
- one single-threaded torch per worker thread, the workers taking chunks in turn (torch releases
  the GIL): measured 0.34 s for 101^3 nodes on 2 cores, against 0.44 s for torch's own 2 threads
  on each product, which are too small for it to split well.

The network's inputs are made per chunk from the 1D coordinates, so no (N, d) grid of parametric
points exists at any time; the only full-size array is the node array itself.

The boundary correction of the evaluated map is ``meshgen.correction`` (NumPy only); the choice of
the model is ``meshgen.neural.models``.
"""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import torch

from meshgen.errors import MeshgenError, ParameterError
from meshgen.neural.checkpoint import CheckpointError
from meshgen.tfi import boundary_faces, tfi, transfinite_on_grid

__all__ = [
    "CHUNK_NODES",
    "GPU_CHUNK_NODES",
    "bubble_on_grid",
    "evaluate_on_grid",
    "inference_device",
    "mesh_from_model",
    "model_boundary_errors",
    "network_layers",
]

CHUNK_NODES = 8192
GPU_CHUNK_NODES = 1 << 20  # 85-wide float32 activations: 350 MB per layer


def network_layers(model: dict):
    """The MLP of a ``checkpoint["model"]`` description as [(W^T (in, out), b (out,)), ...], float32
    torch tensors, checked against its ``dim`` and ``widths`` (a foreign description raises)."""
    try:
        dim, widths = int(model["dim"]), [int(w) for w in model["widths"]]
        state = model["state_dict"]
        sizes = [dim, *widths, dim]
        layers = []
        for index, (fan_in, fan_out) in enumerate(zip(sizes[:-1], sizes[1:])):
            weight, bias = state[f"layers.{index}.weight"], state[f"layers.{index}.bias"]
            if tuple(weight.shape) != (fan_out, fan_in) or tuple(bias.shape) != (fan_out,):
                raise ValueError(f"layer {index} has shape {tuple(weight.shape)}, expected {(fan_out, fan_in)}")
            # The transposed view, as torch.nn.Linear multiplies: the same kernel, the same rounding.
            layers.append((weight.detach().float().t(), bias.detach().float()))
        if len(state) != 2 * len(layers):
            raise ValueError("extra weights")
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise CheckpointError(f"the checkpoint's model description is not a meshgen network ({exc})") from None
    if model.get("activation", "tanh") != "tanh" or model.get("input", "2*xi-1") != "2*xi-1":
        raise CheckpointError(
            f"the checkpoint's network uses activation {model.get('activation')!r} and input "
            f"{model.get('input')!r}; this meshgen evaluates tanh networks of 2*xi-1"
        )
    # A file is data: weights, scale and centre that are not finite numbers would make an all-NaN mesh.
    finite = all(bool(torch.isfinite(weight).all() and torch.isfinite(bias).all()) for weight, bias in layers)
    try:
        finite = finite and all(np.isfinite(np.asarray(model.get(key, 1.0), dtype=float)).all() for key in ("scale", "center"))
    except (TypeError, ValueError):
        finite = False
    if not finite:
        raise CheckpointError("the checkpoint's network holds non-finite numbers (NaN or infinity): the file is damaged")
    return layers


def _grid_inputs(axes, start: int, stop: int):
    """Network inputs u = 2 xi - 1 of the nodes ``start .. stop-1`` of the C-order tensor grid of
    ``axes`` (1D float32 tensors of u per axis): (stop - start, d) float32."""
    flat = torch.arange(start, stop, device=axes[0].device)
    columns = []
    for axis in reversed(axes):  # the last axis varies fastest
        columns.append(axis[flat % len(axis)])
        flat = flat // len(axis)
    return torch.stack(columns[::-1], dim=1)


def inference_device(device: str = "auto") -> str:
    """``"cpu"`` or ``"cuda"``: ``auto`` picks cuda when torch sees a GPU; cuda without one raises."""
    if device not in ("auto", "cpu", "cuda"):
        raise ParameterError("device", f"unknown {{name}} {device!r}: pick auto, cpu or cuda")
    if device == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    if device == "cuda" and not torch.cuda.is_available():
        raise ParameterError("device", "{name} cuda: no CUDA device is available to torch here; use cpu")
    return device


def evaluate_on_grid(
    model: dict, coords, out: np.ndarray | None = None, chunk: int = CHUNK_NODES, workers=None, device: str = "cpu"
) -> np.ndarray:
    """The network N(xi) of ``model`` (normalised units) at the tensor grid of the 1D parametric
    coordinates ``coords`` (one array per axis, values in [0, 1]).

    Returns (or fills ``out`` with) an array of shape (n1 * n2 [* n3], d), float64, nodes in C order.
    ``workers``: threads taking the chunks in turn, each running a single-threaded torch
    (default: torch's thread count). ``device``: "cpu", "cuda" or "auto" (:func:`inference_device`);
    on a GPU the grid goes through in chunks of ``GPU_CHUNK_NODES``.
    """
    layers = network_layers(model)
    dim = int(model["dim"])
    if len(coords) != dim:
        raise MeshgenError(f"the network maps {dim}D points: {len(coords)} coordinate axes given")
    # u = 2 xi - 1 in float32, as the network computes it in training
    axes = [2.0 * torch.from_numpy(np.asarray(c, dtype=np.float64)).float() - 1.0 for c in coords]
    count = int(np.prod([len(c) for c in coords]))
    if out is None:
        out = np.empty((count, dim))
    if inference_device(device) == "cuda":
        return _finite_output(_evaluate_on_gpu(layers, axes, count, out))
    widths = [bias.shape[0] for _, bias in layers]
    local = threading.local()

    def run(start):
        stop = min(count, start + chunk)
        if not hasattr(local, "buffers"):
            local.buffers = [torch.empty(chunk, width) for width in widths]
        with torch.inference_mode():
            hidden = _grid_inputs(axes, start, stop)
            for index, ((weight, bias), buffer) in enumerate(zip(layers, local.buffers)):
                result = buffer[: stop - start]
                torch.addmm(bias, hidden, weight, out=result)
                if index < len(layers) - 1:
                    result.tanh_()
                hidden = result
            out[start:stop] = hidden.numpy()

    workers = workers or torch.get_num_threads()
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # parallel over chunks instead: each product is too small to split
    try:
        with ThreadPoolExecutor(max_workers=workers) as pool:
            for _ in pool.map(run, range(0, count, chunk)):
                pass
    finally:
        torch.set_num_threads(threads)
    return _finite_output(out)


def _finite_output(out: np.ndarray) -> np.ndarray:
    """``out`` when every value the network gave is finite, else MeshgenError (never a NaN mesh)."""
    bad = out.size - int(np.count_nonzero(np.isfinite(out)))
    if bad:
        raise MeshgenError(f"the network's output is non-finite (NaN or infinity) at {bad} of {out.size} values: no mesh written")
    return out


def _evaluate_on_gpu(layers, axes, count: int, out: np.ndarray) -> np.ndarray:
    """:func:`evaluate_on_grid` on the GPU: large chunks (a GPU needs many rows per product to be
    busy), each copied back into ``out`` as it is done."""
    device = torch.device("cuda")
    layers = [(weight.to(device), bias.to(device)) for weight, bias in layers]
    axes = [axis.to(device) for axis in axes]
    target = torch.from_numpy(out)  # the copies land in ``out`` itself, with no host array between
    with torch.inference_mode():
        for start in range(0, count, GPU_CHUNK_NODES):
            stop = min(count, start + GPU_CHUNK_NODES)
            hidden = _grid_inputs(axes, start, stop)
            for index, (weight, bias) in enumerate(layers):
                hidden = torch.addmm(bias, hidden, weight)
                if index < len(layers) - 1:
                    hidden = torch.tanh(hidden)
            target[start:stop].copy_(hidden.double())
    return out


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
    X = evaluate_on_grid(model, coords, chunk=chunk, workers=workers, device=device).reshape(*shape, dim)
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

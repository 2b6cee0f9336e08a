"""Evaluation of a trained network on a tensor grid of any size with torch (CPU threads or a GPU).

``evaluate_on_grid``: what ``meshgen mesh --device cuda`` runs (a CPU run takes the NumPy forward
pass of ``meshgen.neural.mlp_numpy`` through ``meshgen.neural.network_map``, which needs no torch). A [85]*4 network on 101^3 nodes is about
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

The map of a model on a grid (``mesh_from_model``) is ``meshgen.neural.network_map``; the boundary
correction ``meshgen.methods.correction``; the choice of the model ``meshgen.neural.models``.
"""

from __future__ import annotations

import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import torch

from meshgen.errors import MeshgenError
from meshgen.neural.checkpoint_data import check_network
from meshgen.neural.device import inference_device
from meshgen.neural.mlp_numpy import finite_output

__all__ = [
    "CHUNK_NODES",
    "GPU_CHUNK_NODES",
    "evaluate_on_grid",
    "network_layers",
    "network_on_planes",
]

CHUNK_NODES = 8192
GPU_CHUNK_NODES = 1 << 20  # 85-wide float32 activations: 350 MB per layer


def network_layers(model: dict):
    """The MLP of a ``checkpoint["model"]`` description as [(W^T (in, out), b (out,)), ...], float32
    torch tensors, checked by ``meshgen.neural.checkpoint_data.check_network`` (a foreign
    description raises CheckpointError)."""
    check_network(model)
    state = model["state_dict"]
    layers = []
    for index in range(len(model["widths"]) + 1):
        weight = torch.as_tensor(state[f"layers.{index}.weight"]).detach().float()
        bias = torch.as_tensor(state[f"layers.{index}.bias"]).detach().float()
        # The transposed view, as torch.nn.Linear multiplies: the same kernel, the same rounding.
        layers.append((weight.t(), bias))
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
        return finite_output(_evaluate_on_gpu(layers, axes, count, out))
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
    return finite_output(out)


def _forward(layers, hidden):
    """The MLP of ``layers`` on the rows of ``hidden`` (a new tensor per layer: a GPU's products)."""
    for index, (weight, bias) in enumerate(layers):
        hidden = torch.addmm(bias, hidden, weight)
        if index < len(layers) - 1:
            hidden = torch.tanh(hidden)
    return hidden


def network_on_planes(layers, axes, i0: int, i1: int, chunk: int = GPU_CHUNK_NODES):
    """The network of ``layers`` (:func:`network_layers`, on the device) at the node planes
    i0 <= i < i1 of the tensor grid of ``axes`` (1D float32 tensors of u = 2 xi - 1 per axis, on the
    device): (planes x the other axes' nodes, d) float32 on the device, C order, in chunks of
    ``chunk`` nodes."""
    per_plane = int(np.prod([len(axis) for axis in axes[1:]]))
    start, stop = i0 * per_plane, i1 * per_plane
    result = torch.empty((stop - start, layers[-1][1].shape[0]), device=axes[0].device)
    with torch.inference_mode():
        for first in range(start, stop, chunk):
            last = min(stop, first + chunk)
            result[first - start : last - start] = _forward(layers, _grid_inputs(axes, first, last))
    return result


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
            target[start:stop].copy_(_forward(layers, _grid_inputs(axes, start, stop)).double())
    return out

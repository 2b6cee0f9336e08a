"""The trained network's forward pass without torch: a small tanh MLP, each layer a compiled
fixed-order float32 kernel (``dense_kernel``), so meshing with a trained model needs no torch.

``forward_on_grid(model, coords)`` is ``meshgen.neural.gpu_forward.evaluate_on_grid`` without torch:
the same inputs u = 2 xi - 1 in float32, the same layers (W h + b, tanh between), float32
throughout, the result as float64. It agrees with torch's forward to float32 round-off (tested).
Unlike a BLAS product, whose rounding of a node depends on the node's row in the product (the
batch's shape, OpenBLAS's kernel for the CPU), a node's value here is the same bits in any grid,
block, batch or thread count: a chunked mesh equals the in-memory one bit for bit.

The grid goes through in chunks of ``CHUNK_NODES`` nodes (worker threads take chunks in turn:
the kernel and ``tanh`` release the GIL), each in tiles of ``TILE_ROWS`` nodes whose activations
stay in cache from layer to layer. No (N, d) array of parametric points is made: each chunk's
inputs come from the 1D coordinates.

``read_checkpoint(path)`` reads a meshgen checkpoint (torch's zip format of plain data) into
dicts, lists, numbers and NumPy arrays without torch: a restricted unpickler that knows only
tensors, their storages and ordered dicts, so reading never runs foreign code.
"""

from __future__ import annotations

import contextlib
import ctypes
import functools
import os
import pickle
import re
import threading
import zipfile
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from meshgen.errors import MeshgenError

__all__ = [
    "CHUNK_NODES",
    "TILE_ROWS",
    "finite_output",
    "forward_on_grid",
    "dense_kernel",
    "forward_tile",
    "network_arrays",
    "openblas_thread_functions",
    "read_checkpoint",
]

CHUNK_NODES = 8192
TILE_ROWS = 1024  # nodes per tile of the compiled forward pass (its activations: 1024 x 85 float32, 350 kB)


@functools.lru_cache(maxsize=1)
def dense_kernel():
    """The compiled layer ``out = W h + b`` on a tile (numba, loaded on first use): ``h`` (fan_in,
    nodes), ``W`` (fan_out, fan_in), ``b`` (fan_out,), ``out`` (fan_out, nodes), float32.

    Each output is (((W_0 h_0 + W_1 h_1) + W_2 h_2) + ...) + b, products and sums rounded one by one
    (no fused multiply-add, no reordering: ``fastmath`` off), vectorised across the nodes. So a
    node's value is the same bits in any grid, block, batch or thread, on any CPU: IEEE float32
    arithmetic in a fixed order, where a BLAS product's rounding depends on the node's row in it
    (OpenBLAS's AVX2 kernel treats rows by their index modulo 6)."""
    from numba import njit

    @njit(cache=True, fastmath=False, nogil=True, error_model="numpy")
    def dense(h, weight, bias, out):
        fan_in, nodes = h.shape
        for j in range(weight.shape[0]):
            for r in range(nodes):
                out[j, r] = 0.0
            for k in range(fan_in):
                w = weight[j, k]
                for r in range(nodes):
                    out[j, r] += w * h[k, r]
            for r in range(nodes):
                out[j, r] += bias[j]

    return dense


def _tile_buffers(layers, dim: int) -> list[np.ndarray]:
    """A tile's float32 buffers: its inputs (dim, ``TILE_ROWS``), then one (width, ``TILE_ROWS``)
    per layer."""
    return [np.zeros((dim, TILE_ROWS), dtype=np.float32)] + [
        np.empty((b.shape[0], TILE_ROWS), dtype=np.float32) for _, b in layers
    ]


def forward_tile(layers, inputs: np.ndarray, buffers: list[np.ndarray]) -> np.ndarray:
    """The network of ``layers`` (:func:`network_arrays`) at up to ``TILE_ROWS`` float32 input rows
    ``inputs`` (rows, d): the first ``rows`` columns of the returned (d, ``TILE_ROWS``) float32
    buffer. Every layer is :func:`dense_kernel` (fixed-order arithmetic per node), then ``tanh``
    (elementwise); a short tile is padded with zeros. ``buffers``: :func:`_tile_buffers`."""
    dense = dense_kernel()
    hidden = buffers[0]
    hidden[:, : len(inputs)] = inputs.T
    hidden[:, len(inputs) :] = 0.0
    for index, ((weight, bias), result) in enumerate(zip(layers, buffers[1:])):
        dense(hidden, weight, bias, result)
        if index < len(layers) - 1:
            np.tanh(result, out=result)
        hidden = result
    return hidden


def network_arrays(model: dict) -> list[tuple[np.ndarray, np.ndarray]]:
    """The layers of a ``checkpoint["model"]`` description as [(W (out, in), b (out,)), ...],
    float32 C-contiguous arrays (the state dict may hold NumPy arrays or CPU tensors)."""
    dim, widths = int(model["dim"]), [int(w) for w in model["widths"]]
    state = model["state_dict"]
    sizes = [dim, *widths, dim]
    layers = []
    for index, (fan_in, fan_out) in enumerate(zip(sizes[:-1], sizes[1:])):
        weight = np.asarray(state[f"layers.{index}.weight"], dtype=np.float32)
        bias = np.asarray(state[f"layers.{index}.bias"], dtype=np.float32)
        if weight.shape != (fan_out, fan_in) or bias.shape != (fan_out,):
            raise MeshgenError(f"the network's layer {index} has shape {weight.shape}, expected {(fan_out, fan_in)}")
        layers.append((np.ascontiguousarray(weight), bias))
    return layers


@functools.lru_cache(maxsize=1)
def openblas_thread_functions():
    """(get, set) of the number of threads of the OpenBLAS that NumPy loaded, or None where there
    is none to be found (another BLAS, no /proc): then the products run as the BLAS decides."""
    try:
        with open("/proc/self/maps") as handle:
            libraries = sorted(set(re.findall(r"(/\S*openblas\S*\.so\S*)", handle.read())))
    except OSError:
        return None
    for path in libraries:
        try:
            library = ctypes.CDLL(path)
        except OSError:
            continue
        for prefix, suffix in (("scipy_openblas", "64_"), ("scipy_openblas", ""), ("openblas", "64_"), ("openblas", "")):
            get = getattr(library, f"{prefix}_get_num_threads{suffix}", None)
            set_ = getattr(library, f"{prefix}_set_num_threads{suffix}", None)
            if get is not None and set_ is not None:
                return get, set_
    return None


_BLAS_LOCK = threading.Lock()
_BLAS_USERS = [0, None]  # forward passes running now, the thread count to restore after the last


@contextlib.contextmanager
def _one_blas_thread():
    """OpenBLAS on one thread while any forward pass runs (passes may run at once on Dask's
    threads: the first sets it, the last restores it)."""
    functions = openblas_thread_functions()
    if functions is None:
        yield
        return
    get, set_ = functions
    with _BLAS_LOCK:
        if _BLAS_USERS[0] == 0:
            _BLAS_USERS[1] = get()
            set_(1)
        _BLAS_USERS[0] += 1
    try:
        yield
    finally:
        with _BLAS_LOCK:
            _BLAS_USERS[0] -= 1
            if _BLAS_USERS[0] == 0:
                set_(_BLAS_USERS[1])


def _grid_inputs(axes, start: int, stop: int) -> np.ndarray:
    """Inputs u of the nodes start .. stop-1 of the C-order tensor grid of ``axes`` (1D float32
    arrays of u per axis): (stop - start, d) float32."""
    flat = np.arange(start, stop)
    inputs = np.empty((stop - start, len(axes)), dtype=np.float32)
    for d in range(len(axes) - 1, -1, -1):  # the last axis varies fastest
        flat, index = np.divmod(flat, len(axes[d]))
        inputs[:, d] = axes[d][index]
    return inputs


def forward_on_grid(model: dict, coords, out: np.ndarray | None = None, chunk: int = CHUNK_NODES, workers: int | None = None):
    """The network N(xi) of ``model`` (a ``checkpoint["model"]`` description) at the tensor grid of
    the 1D parametric coordinates ``coords`` (values in [0, 1]): (n1 * n2 [* n3], d) float64, nodes
    in C order, written into ``out`` when given. ``workers``: threads over chunks (default: the
    CPUs this process may use)."""
    layers = network_arrays(model)
    dim = int(model["dim"])
    if len(coords) != dim:
        raise MeshgenError(f"the network maps {dim}D points: {len(coords)} coordinate axes given")
    two, one = np.float32(2.0), np.float32(1.0)
    axes = [two * np.asarray(c, dtype=np.float64).astype(np.float32) - one for c in coords]
    count = int(np.prod([len(c) for c in coords]))
    if out is None:
        out = np.empty((count, dim))

    def run(first: int) -> None:
        # each task owns its buffers: chunks run on any worker thread
        buffers = _tile_buffers(layers, dim)
        for start in range(first, min(count, first + span), chunk):
            stop = min(count, start + chunk)
            inputs = _grid_inputs(axes, start, stop)
            for tile in range(0, stop - start, TILE_ROWS):
                rows = min(TILE_ROWS, stop - start - tile)
                result = forward_tile(layers, inputs[tile : tile + rows], buffers)
                out[start + tile : start + tile + rows] = result[:, :rows].T

    if workers is None:
        workers = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    span = chunk * max(1, -(-count // (chunk * workers * 4)))  # about four tasks per worker
    with _one_blas_thread():
        if workers == 1 or count <= span:
            for first in range(0, count, span):
                run(first)
        else:
            with ThreadPoolExecutor(max_workers=workers) as pool:
                list(pool.map(run, range(0, count, span)))
    return out


def finite_output(out: np.ndarray) -> np.ndarray:
    """``out`` when every value the network gave is finite, else MeshgenError (never a NaN mesh)."""
    bad = out.size - int(np.count_nonzero(np.isfinite(out)))
    if bad:
        raise MeshgenError(f"the network's output is non-finite (NaN or infinity) at {bad} of {out.size} values: no mesh written")
    return out


# ---------------------------------------------------------------------------------------------
# checkpoints without torch

_STORAGE_DTYPES = {
    "FloatStorage": np.float32,
    "DoubleStorage": np.float64,
    "HalfStorage": np.float16,
    "LongStorage": np.int64,
    "IntStorage": np.int32,
    "ShortStorage": np.int16,
    "CharStorage": np.int8,
    "ByteStorage": np.uint8,
    "BoolStorage": np.bool_,
}


def _rebuild_tensor(storage, offset, size, stride, *_):
    """A tensor as a NumPy array: ``storage`` (flat array) viewed at ``offset`` with ``size`` and
    ``stride`` (in elements), copied so it owns its memory."""
    if not size:
        return storage[offset].copy()
    strides = tuple(s * storage.itemsize for s in stride)
    view = np.lib.stride_tricks.as_strided(storage[offset:], shape=tuple(size), strides=strides)
    return np.array(view)


class _Unpickler(pickle.Unpickler):
    def __init__(self, handle, archive: zipfile.ZipFile, prefix: str, byteorder: str):
        super().__init__(handle)
        self._archive, self._prefix, self._byteorder = archive, prefix, byteorder
        self._storages = {}

    def find_class(self, module, name):
        if (module, name) == ("torch._utils", "_rebuild_tensor_v2"):
            return _rebuild_tensor
        if module == "torch" and name in _STORAGE_DTYPES:
            return _STORAGE_DTYPES[name]
        if (module, name) == ("collections", "OrderedDict"):
            return dict
        raise pickle.UnpicklingError(f"{module}.{name} is not plain checkpoint data")

    def persistent_load(self, saved_id):
        kind, dtype, key = saved_id[0], saved_id[1], str(saved_id[2])
        if kind != "storage" or not isinstance(dtype, type):
            raise pickle.UnpicklingError(f"unknown persistent record {kind!r}")
        if key not in self._storages:
            raw = self._archive.read(f"{self._prefix}data/{key}")
            array = np.frombuffer(raw, dtype=np.dtype(dtype).newbyteorder("<" if self._byteorder == "little" else ">"))
            self._storages[key] = array.astype(np.dtype(dtype).newbyteorder("="), copy=False)
        return self._storages[key]


def read_checkpoint(path) -> dict:
    """A checkpoint written by ``meshgen.neural.checkpoint.save_checkpoint`` as plain data, its
    tensors as NumPy arrays, read without torch. MeshgenError for a file that is not one."""
    try:
        with zipfile.ZipFile(path) as archive:
            names = archive.namelist()
            pickled = next(name for name in names if name.endswith("data.pkl"))
            prefix = pickled[: -len("data.pkl")]
            byteorder = archive.read(prefix + "byteorder").decode().strip() if prefix + "byteorder" in names else "little"
            with archive.open(pickled) as handle:
                data = _Unpickler(handle, archive, prefix, byteorder).load()
    except (OSError, zipfile.BadZipFile, StopIteration, pickle.UnpicklingError, KeyError, ValueError, EOFError) as exc:
        raise MeshgenError(f"could not read checkpoint {path}: {exc}") from None
    if not isinstance(data, dict):
        raise MeshgenError(f"could not read checkpoint {path}: not a checkpoint")
    return data

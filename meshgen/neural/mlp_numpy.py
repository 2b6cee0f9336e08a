"""The trained network's forward pass without torch: a small tanh MLP, so meshing with a trained
model needs no torch. On grids from ``NUMPY_WORK`` multiply-adds up each layer is a compiled kernel
(``dense_kernel``, numba) of fixed-order float32 arithmetic per node: a node's value is the same
bits in any grid, block, batch or thread count, on any CPU, so a chunked mesh equals the in-memory
one bit for bit. Below it (a fresh process then never imports numba, about a second) each layer
is a BLAS product, whose rounding of a node depends on its column in the product (OpenBLAS's AVX2
kernel: the column index modulo 6), so such a grid is always evaluated whole, in the one fixed
partition below (``meshgen.neural.network_map.small_grid_network``). The path is chosen by size alone
(``compiled_for``).

``forward_on_grid(model, coords)`` is ``meshgen.neural.gpu_forward.evaluate_on_grid`` without torch:
the same inputs u = 2 xi - 1 in float32, the same layers (W h + b, tanh between), float32
throughout, the result as float64. It agrees with torch's forward to float32 round-off (tested).

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
    "KERNEL_NODES",
    "NUMPY_WORK",
    "TILE_ROWS",
    "compiled_for",
    "dense_kernel",
    "finite_output",
    "forward_on_grid",
    "forward_tile",
    "multiply_adds",
    "network_arrays",
    "openblas_thread_functions",
    "read_checkpoint",
]

CHUNK_NODES = 8192
TILE_ROWS = 1024  # nodes per tile of the forward pass (its activations: 1024 x 85 float32, 350 kB)
KERNEL_NODES = 256  # nodes per run inside the compiled kernel (a 48-wide layer's inputs: 48 kB)
NUMPY_WORK = (
    1_000_000_000  # multiply-adds below which the pass is NumPy (2e5 nodes of [48]*3: break-even with a fresh numba import)
)


@functools.lru_cache(maxsize=1)
def dense_kernel():
    """The compiled layer ``out = W h + b`` on a tile (numba, loaded on first use): ``h`` (fan_in,
    nodes), ``W`` (fan_out, fan_in), ``b`` (fan_out,), ``out`` (fan_out, nodes), float32.

    Each output is (((0 + W_0 h_0) + W_1 h_1) + ...) + b, products and sums rounded one by one (no
    fused multiply-add, no reordering: ``fastmath`` off), vectorised across the nodes. So a node's
    value is the same bits in any grid, block, batch or thread, on any CPU: IEEE float32 arithmetic
    in a fixed order, where a BLAS product's rounding depends on the node's row in it (OpenBLAS's
    AVX2 kernel treats rows by their index modulo 6).

    For speed (not for the result): nodes in runs of ``KERNEL_NODES`` (the run's inputs stay in L1
    across the outputs), eight outputs at once over two inputs k per pass (their sums in a small
    accumulator array: fewer loads and stores per multiply-add, eight independent chains of adds),
    the last fan_out % 8 outputs one at a time over four inputs per pass; the node loops in vectors
    of 16 floats (one AVX-512 register, two AVX2 ones: about a third faster than LLVM's choice of 8
    here), for this function's compilation only (under numba's compiler lock, so no other function
    compiles meanwhile). Compiled for C-contiguous float32 arrays, the only ones it accepts."""
    import llvmlite.binding as llvm
    from numba import njit
    from numba.core.compiler_lock import global_compiler_lock

    import meshgen.run.jit  # noqa: F401 - numba with its BLAS probe deferred (design notes §21)

    # Raised as meshgen.quality.compiled does: the loop reads 10 rows and writes 8, more overlap
    # checks than LLVM's default limits allow, without which it would not vectorise. It changes
    # what loops may be vectorised, never the arithmetic of one.
    llvm.set_option("", "-runtime-memory-check-threshold=1024")
    llvm.set_option("", "-vectorize-memory-check-threshold=1024")
    run = KERNEL_NODES

    @njit(cache=True, fastmath=False, nogil=True, error_model="numpy", boundscheck=False)
    def dense(h, weight, bias, out):
        fan_in, nodes = h.shape
        fan_out = weight.shape[0]
        acc = np.empty((8, run), dtype=np.float32)
        for r0 in range(0, nodes, run):
            n = min(run, nodes - r0)
            for j in range(0, fan_out - 7, 8):  # outputs j .. j+7
                a0, a1, a2, a3 = acc[0, :n], acc[1, :n], acc[2, :n], acc[3, :n]
                a4, a5, a6, a7 = acc[4, :n], acc[5, :n], acc[6, :n], acc[7, :n]
                acc[:, :n] = 0.0
                for k in range(0, fan_in - 1, 2):  # a = (a + w_k h_k) + w_k+1 h_k+1, rounded one by one
                    h0, h1 = h[k, r0 : r0 + n], h[k + 1, r0 : r0 + n]
                    u0, u1, u2, u3 = weight[j, k], weight[j + 1, k], weight[j + 2, k], weight[j + 3, k]
                    u4, u5, u6, u7 = weight[j + 4, k], weight[j + 5, k], weight[j + 6, k], weight[j + 7, k]
                    v0, v1, v2, v3 = weight[j, k + 1], weight[j + 1, k + 1], weight[j + 2, k + 1], weight[j + 3, k + 1]
                    v4, v5, v6, v7 = weight[j + 4, k + 1], weight[j + 5, k + 1], weight[j + 6, k + 1], weight[j + 7, k + 1]
                    for r in range(n):
                        x, y = h0[r], h1[r]
                        a0[r] = (a0[r] + u0 * x) + v0 * y
                        a1[r] = (a1[r] + u1 * x) + v1 * y
                        a2[r] = (a2[r] + u2 * x) + v2 * y
                        a3[r] = (a3[r] + u3 * x) + v3 * y
                        a4[r] = (a4[r] + u4 * x) + v4 * y
                        a5[r] = (a5[r] + u5 * x) + v5 * y
                        a6[r] = (a6[r] + u6 * x) + v6 * y
                        a7[r] = (a7[r] + u7 * x) + v7 * y
                if fan_in % 2:  # the last of an odd number of inputs
                    k = fan_in - 1
                    h0 = h[k, r0 : r0 + n]
                    u0, u1, u2, u3 = weight[j, k], weight[j + 1, k], weight[j + 2, k], weight[j + 3, k]
                    u4, u5, u6, u7 = weight[j + 4, k], weight[j + 5, k], weight[j + 6, k], weight[j + 7, k]
                    for r in range(n):
                        x = h0[r]
                        a0[r] = a0[r] + u0 * x
                        a1[r] = a1[r] + u1 * x
                        a2[r] = a2[r] + u2 * x
                        a3[r] = a3[r] + u3 * x
                        a4[r] = a4[r] + u4 * x
                        a5[r] = a5[r] + u5 * x
                        a6[r] = a6[r] + u6 * x
                        a7[r] = a7[r] + u7 * x
                for row in range(8):
                    b, o, a = bias[j + row], out[j + row, r0 : r0 + n], acc[row, :n]
                    for r in range(n):
                        o[r] = a[r] + b
            for j in range(fan_out - fan_out % 8, fan_out):  # the last fan_out % 8 outputs, one by one
                a = acc[0, :n]
                a[:] = 0.0
                for k in range(0, fan_in - 3, 4):  # four inputs per pass, added in order
                    h0, h1, h2, h3 = h[k, r0 : r0 + n], h[k + 1, r0 : r0 + n], h[k + 2, r0 : r0 + n], h[k + 3, r0 : r0 + n]
                    u0, u1, u2, u3 = weight[j, k], weight[j, k + 1], weight[j, k + 2], weight[j, k + 3]
                    for r in range(n):
                        a[r] = (((a[r] + u0 * h0[r]) + u1 * h1[r]) + u2 * h2[r]) + u3 * h3[r]
                for k in range(fan_in - fan_in % 4, fan_in):
                    h0, u0 = h[k, r0 : r0 + n], weight[j, k]
                    for r in range(n):
                        a[r] = a[r] + u0 * h0[r]
                b, o = bias[j], out[j, r0 : r0 + n]
                for r in range(n):
                    o[r] = a[r] + b

    with global_compiler_lock:
        llvm.set_option("", "-force-vector-width=16")
        try:
            dense.compile("(float32[:, ::1], float32[:, ::1], float32[::1], float32[:, ::1])")
        finally:
            llvm.set_option("", "-force-vector-width=0")  # LLVM's default: its own choice
    dense.disable_compile()
    return dense


def multiply_adds(model: dict) -> int:
    """Multiply-adds per node of the network of ``model`` (a ``checkpoint["model"]`` description)."""
    sizes = [int(model["dim"]), *(int(w) for w in model["widths"]), int(model["dim"])]
    return sum(a * b for a, b in zip(sizes[:-1], sizes[1:]))


def compiled_for(model: dict, nodes: int) -> bool:
    """Whether a forward pass of ``model`` over ``nodes`` nodes takes the compiled fixed-order kernel
    (from ``NUMPY_WORK`` multiply-adds up) rather than BLAS products (no numba import, about a
    second in a fresh process, and ten times faster than the kernel's order in NumPy on small grids). By
    size alone, so a request always takes the same path (a chunked mesh: give the whole grid's
    nodes). BLAS rounds a node by its position in the product, so a grid below the threshold is
    evaluated whole, in one fixed partition (``meshgen.neural.network_map.map_on_block``)."""
    return nodes * multiply_adds(model) >= NUMPY_WORK


def _tile_buffers(layers, dim: int) -> list[np.ndarray]:
    """A tile's float32 buffers: its inputs (dim, ``TILE_ROWS``), then one (width, ``TILE_ROWS``)
    per layer."""
    return [np.zeros((dim, TILE_ROWS), dtype=np.float32)] + [
        np.empty((b.shape[0], TILE_ROWS), dtype=np.float32) for _, b in layers
    ]


def forward_tile(layers, inputs: np.ndarray, buffers: list[np.ndarray], compiled: bool = True) -> np.ndarray:
    """The network of ``layers`` (:func:`network_arrays`) at up to ``TILE_ROWS`` float32 input rows
    ``inputs`` (rows, d): the first ``rows`` columns of the returned (d, ``TILE_ROWS``) float32
    buffer. Every layer is :func:`dense_kernel` (``compiled``) or a BLAS product (whose rounding
    of a node depends on its column), then ``tanh`` (elementwise, NumPy's in both); a short tile is padded with zeros.
    ``buffers``: :func:`_tile_buffers`."""
    dense = dense_kernel() if compiled else None
    hidden = buffers[0]
    hidden[:, : len(inputs)] = inputs.T
    hidden[:, len(inputs) :] = 0.0
    for index, ((weight, bias), result) in enumerate(zip(layers, buffers[1:])):
        if compiled:
            dense(hidden, weight, bias, result)
        else:  # BLAS: fast, but its rounding of a node depends on the node's column in the product
            np.matmul(weight, hidden, out=result)
            np.add(result, bias[:, None], out=result)
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
        layers.append((np.ascontiguousarray(weight), np.ascontiguousarray(bias)))
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


def forward_on_grid(
    model: dict,
    coords,
    out: np.ndarray | None = None,
    chunk: int = CHUNK_NODES,
    workers: int | None = None,
    compiled: bool | None = None,
):
    """The network N(xi) of ``model`` (a ``checkpoint["model"]`` description) at the tensor grid of
    the 1D parametric coordinates ``coords`` (values in [0, 1]): (n1 * n2 [* n3], d) float64, nodes
    in C order, written into ``out`` when given. ``workers``: threads over chunks (default: the
    CPUs this process may use). ``compiled``: the numba kernel or BLAS products (default
    :func:`compiled_for` this grid's size)."""
    layers = network_arrays(model)
    dim = int(model["dim"])
    if len(coords) != dim:
        raise MeshgenError(f"the network maps {dim}D points: {len(coords)} coordinate axes given")
    two, one = np.float32(2.0), np.float32(1.0)
    axes = [two * np.asarray(c, dtype=np.float64).astype(np.float32) - one for c in coords]
    count = int(np.prod([len(c) for c in coords]))
    if out is None:
        out = np.empty((count, dim))
    if compiled is None:
        compiled = compiled_for(model, count)

    def run(first: int) -> None:
        # each task owns its buffers: chunks run on any worker thread
        buffers = _tile_buffers(layers, dim)
        for start in range(first, min(count, first + span), chunk):
            stop = min(count, start + chunk)
            inputs = _grid_inputs(axes, start, stop)
            for tile in range(0, stop - start, TILE_ROWS):
                rows = min(TILE_ROWS, stop - start - tile)
                result = forward_tile(layers, inputs[tile : tile + rows], buffers, compiled)
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

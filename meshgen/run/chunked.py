"""Meshes larger than memory: the node array as a ``dask.array`` of blocks, streamed into a file.

A TFI or neural mesh is a map evaluated node by node, so it can be computed block by block:

- TFI: the six face terms D_as of the axis-by-axis Boolean sum (``meshgen.methods.tfi.face_terms``,
  O(n^2) memory) are computed once; a block is then their blend on the block's nodes
  (``add_face_terms``), bit for bit the in-memory mesh.
- neural: the network on the block's parametric coordinates (``map_on_block``), the exact-
  boundary form's TFI from the precomputed face terms; every matrix product of the forward pass
  has one shape (``meshgen.neural.mlp_numpy.forward_tile``), so this too is the in-memory mesh
  bit for bit, at any block size. The boundary is corrected as
  X = M + TFI[g - M] (M the network's map, g the geometry's boundary map): the six face error
  arrays g - M are O(n^2) and computed up front, their TFI on a block is block-local. It moves the
  boundary nodes exactly onto g and the interior smoothly with them.

Blocks are slabs along the last index axis (k in 3D), which are contiguous hyperslabs of a CGNS
coordinate array (stored k slowest); a plane too large for one block is split along the first axis
as well. Blocks of at most ``BLOCK_NODES`` nodes (fewer where memory is short:
``mesh_block_nodes``) keep a block's coordinates near 25 MB, so the peak memory is a few blocks
per worker thread, whatever the mesh size.

``meshgen mesh`` takes this path (``meshgen.run.resources.needs_chunking``) when the in-memory path's
estimated peak (``IN_MEMORY_BYTES_PER_NODE``) exceeds half of the memory available now, with ``--chunked``, or with
``--scheduler``. CGNS takes the blocks as they complete; OpenFOAM, .vts, Plot3D, .su2 and .msh take
them through a scratch CGNS file read back in their node order (``meshgen.formats.streamed``); the
others (.vtu, .vtk, .xdmf) refuse.
"""

from __future__ import annotations

import contextlib
import importlib
import itertools
import os
import time
from pathlib import Path

import numpy as np

from meshgen.errors import MeshgenError
from meshgen.formats import check_output_path, check_patches, format_named, streaming_writer
from meshgen.formats.streamed import NodeFile, write_streamed
from meshgen.geometry.grid import BLOCK_NODES, block_slices
from meshgen.geometry.patches import geometry_patches
from meshgen.methods.correction import add_correction_terms, correction_terms, error_figures, snap_to_boundary
from meshgen.methods.tfi import add_face_terms, face_terms, face_values
from meshgen.neural.network_map import exact_boundary_terms, map_on_block, model_boundary_errors
from meshgen.quality.chunked import chunked_report
from meshgen.quality.files import sidecar_path, write_json
from meshgen.run.atomic import atomic_path
from meshgen.run.publish import publishing, reason, remove_path, temporary_path
from meshgen.run.resources import available_memory, blocks_in_flight, check_free_space
from meshgen.run.scheduler import compute_in_order_of_completion

__all__ = [
    "CHUNKED_METHODS",
    "MESH_BYTES_PER_BLOCK_NODE",
    "mesh_block_nodes",
    "neural_array",
    "run_fraction",
    "scratch_path",
    "single_threaded_torch",
    "tfi_array",
    "write_chunked_mesh",
]

MIN_BLOCK_NODES = 1 << 14
MESH_BYTES_PER_BLOCK_NODE = 200  # measured order: a neural block's map, TFI, correction and result
CHUNKED_METHODS = ("tfi", "neural")
# An output's size over its coordinates' (8 bytes each), about, in the formats a chunked mesh is
# written in through the scratch node file (an ASCII OpenFOAM case: 2.5 times the binary one).
OUTPUT_SIZE = {"openfoam": 4.6, "su2": 7.0, "gmsh": 7.0, "plot3d-ascii": 3.2}


def mesh_block_nodes() -> int:
    """Nodes per block of a mesh computed in blocks, for the memory available now: the blocks in
    flight (two per worker thread, as ``meshgen.run.scheduler`` computes them) take at most a quarter
    of it; at most ``BLOCK_NODES`` (larger blocks gain no speed and cost memory)."""
    fitting = available_memory() // (4 * blocks_in_flight() * MESH_BYTES_PER_BLOCK_NODE)
    return int(max(MIN_BLOCK_NODES, min(BLOCK_NODES, fitting)))


def run_fraction(done: int, total: int, phase: str, evaluate: bool) -> float:
    """The fraction of a chunked run done after ``done`` of ``total`` blocks of ``phase`` (as
    ``write_chunked_mesh``'s progress reports them): the mesh pass is one of two passes over the
    blocks when the quality is evaluated (the quality reads each block once: design notes §21),
    else the whole run. It only grows and reaches 1 at the very end: a progress bar that reached its
    end after the mesh pass would stop its clock for the whole quality phase. (The rare second
    quality pass, ``meshgen.quality.chunked.SECOND_PASS``, goes over the second half again.)"""
    if phase == "mesh":
        return done / (2 * total) if evaluate else done / total
    return (total + done) / (2 * total)


def _node_array(block_function, shared, node_shape, dim: int, block_nodes: int | None):
    """A dask array of shape node_shape + (dim,) whose block at slices ``b`` is
    ``block_function(shared, b)``; ``shared`` goes into the graph once."""
    import dask
    import dask.array as da

    per_axis = block_slices(node_shape, block_nodes or mesh_block_nodes())
    shared = dask.delayed(shared, pure=True, traverse=False)
    function = dask.delayed(block_function, pure=True)
    grid = np.empty([len(s) for s in per_axis], dtype=object)
    for position in itertools.product(*(range(len(s)) for s in per_axis)):
        block = tuple(per_axis[axis][i] for axis, i in enumerate(position))
        shape = tuple(s.stop - s.start for s in block) + (dim,)
        grid[position] = da.from_delayed(function(shared, block), shape=shape, dtype=float)

    def nest(array):
        return [nest(a) for a in array] if array.ndim > 1 else [[piece] for piece in array]

    return da.block(nest(grid))


def _tfi_block(shared, block):
    coords, terms = shared
    return add_face_terms(terms, coords, block=block)


def tfi_array(geometry, coords, block_nodes: int | None = None):
    """The TFI mesh of ``geometry`` on the tensor grid of ``coords`` (1D arrays from 0 to 1) as a
    dask array (n1+1, n2+1[, n3+1], dim), blocks of about ``block_nodes`` nodes (default
    ``mesh_block_nodes()``)."""
    coords = [np.asarray(c, dtype=float) for c in coords]
    terms = face_terms(face_values(geometry.boundary, coords), coords)
    shape = tuple(len(c) for c in coords)
    return _node_array(_tfi_block, (coords, terms), shape, len(coords), block_nodes)


def _neural_block(shared, block):
    model, coords, tfi_terms, error_terms, boundary_values, device = shared
    X = map_on_block(model, coords, block, tfi_terms, workers=1, device=device)
    if error_terms:
        add_correction_terms(error_terms, coords, X, block)  # X + TFI[g - M] on the block
        snap_to_boundary(X, boundary_values, coords, block)  # the boundary nodes exactly g, as in memory
    return X


def neural_array(
    model: dict, geometry, coords, correct_boundary: bool = True, block_nodes: int | None = None, device: str = "cpu"
):
    """The mesh of a trained network (``checkpoint["model"]``) on the tensor grid of ``coords`` as
    a dask array, and what the boundary correction did (JSON-ready). On a CPU bit for bit the
    in-memory mesh (``meshgen.neural.network_map.mesh_from_model``, then
    ``meshgen.methods.correction.correct_boundary``) at any block size: every node sees the same
    arithmetic in any block (``map_on_block``). ``device`` "cuda": the network's forward pass of
    each block on the GPU (cuBLAS picks its kernels by the block's size, so the nodes equal the
    in-memory GPU mesh's to float32 rounding, not bit for bit); the rest stays on the CPU.

    ``correct_boundary``: X = M + TFI[g - M] (``meshgen.methods.correction.add_boundary_correction``
    block by block, the face errors computed once on the faces alone); else the network's map M.
    """
    coords = [np.asarray(c, dtype=float) for c in coords]
    boundary_values = face_values(geometry.boundary, coords)
    tfi_terms = exact_boundary_terms(model, geometry, coords, values=boundary_values)  # or a section model's plane
    info = {"corrected": False}
    error_terms = None
    if correct_boundary:
        errors = model_boundary_errors(model, geometry, coords, device=device, values=boundary_values, terms=tfi_terms)
        info = {"corrected": True, "error_before": error_figures(errors, geometry)}
        error_terms = correction_terms(errors, coords)
    shape = tuple(len(c) for c in coords)
    shared = (model, coords, tfi_terms, error_terms, boundary_values, device)
    return _node_array(_neural_block, shared, shape, len(coords), block_nodes), info


@contextlib.contextmanager
def single_threaded_torch(enabled: bool = True):
    """torch with one thread while the blocks run: Dask's threads parallelise over blocks."""
    if not enabled:
        yield
        return
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        yield
    finally:
        torch.set_num_threads(threads)


def write_chunked_mesh(
    path,
    X,
    geometry=None,
    metadata: dict | None = None,
    client=None,
    progress=None,
    evaluate: bool = True,
    patches=None,
    format: str | None = None,
    block_nodes: int | None = None,
    **options,
) -> tuple[dict | None, dict]:
    """Compute the dask node array ``X`` block by block and write it to ``path`` (in the format
    ``format`` names, default the extension's), atomically; then, unless ``evaluate`` is False,
    its quality report computed block-wise from the written nodes (``meshgen.quality.chunked``)
    before the file takes its name, written to ``<path>.quality.json``. No per-cell quality arrays
    are stored (at 1e9 cells they would be 56 GB; ``meshgen evaluate`` computes them block-wise).

    CGNS takes the blocks as they complete (hyperslab writes). The formats that list the nodes in
    one order (OpenFOAM, .vts, Plot3D, .su2, .msh) take them through a scratch CGNS file beside the
    output, read back slab by slab in their order (``meshgen.formats.streamed``) and removed
    afterwards. ``options``: the format's (OpenFOAM: ``binary``).

    ``patches``: the boundary patches (``meshgen.geometry.patches.Patch``; default the ``geometry``'s, else
    one per face). ``progress(done, total, phase)`` hears about every block. ``block_nodes``: nodes per
    slab read back and per quality block (default from the available memory). Returns (the report or None,
    {"write_seconds", "quality_seconds"}).
    """
    fmt = streaming_writer(path, format, X.shape[:-1])
    path = check_output_path(path, format, X.shape[-1])
    if patches is None and geometry is not None:
        patches = geometry_patches(geometry)
    patches = check_patches(patches, X.shape[-1], path, fmt.name)
    node_shape = X.shape[:-1]
    coordinate_bytes = int(np.prod(node_shape)) * X.shape[-1] * 8
    if fmt.streams:
        check_free_space(path, coordinate_bytes)
    else:  # the scratch node file, then the output beside it
        ratio = OUTPUT_SIZE.get(fmt.name, 1.1) * (2.5 if options.get("binary") is False else 1.0)
        check_free_space(path, int(coordinate_bytes * (1.0 + ratio)))
    timings = {}
    try:
        with publishing(path) as publication:  # the mesh and its sidecar together, or neither
            if fmt.streams:
                with atomic_path(path) as temporary:
                    report = _stream_and_evaluate(
                        temporary, X, geometry, metadata, patches, client, progress, evaluate, timings, block_nodes
                    )
            else:
                with scratch_path(path) as scratch:
                    report = _stream_and_evaluate(scratch, X, geometry, {}, (), client, progress, evaluate, timings, block_nodes)
                    start = time.perf_counter()
                    nodes = NodeFile(scratch, tuple(int(n) for n in node_shape), block_nodes or mesh_block_nodes())
                    if fmt.folder:
                        write_streamed(path, nodes, fmt.name, metadata or {}, patches, **options)
                    else:
                        with atomic_path(path) as temporary:
                            write_streamed(temporary, nodes, fmt.name, metadata or {}, patches, **options)
                    timings["write_seconds"] += time.perf_counter() - start
            if report is not None:
                write_json(sidecar_path(path), {"mesh": os.path.basename(path), **(metadata or {}), **report})
            else:
                publication.remove(sidecar_path(path))  # a previous mesh's sidecar describes another mesh
    except (OSError, RuntimeError) as exc:  # h5py reports a full disk as either
        raise MeshgenError(f"could not write {path}: {reason(exc)}") from exc
    return report, timings


@contextlib.contextmanager
def scratch_path(path):
    """A scratch CGNS file's name beside ``path`` (a temporary name of this process, which the next
    run removes if this one is killed), removed when the block ends, however it ends."""
    scratch = temporary_path(Path(path).with_name(Path(path).name + "-nodes.cgns"))
    try:
        yield scratch
    finally:
        remove_path(scratch)


def _stream_and_evaluate(target, X, geometry, metadata, patches, client, progress, evaluate, timings, block_nodes) -> dict | None:
    """Stream the blocks of ``X`` into the CGNS file ``target`` as they complete; its quality
    report read back from it block-wise (None unless ``evaluate``); ``timings`` filled."""
    from dask.array.core import slices_from_chunks

    writer = importlib.import_module(format_named("cgns").module)
    blocks = list(X.to_delayed().ravel())
    slices = [s[:-1] for s in slices_from_chunks(X.chunks)]
    start = time.perf_counter()
    with writer.stream(target, X.shape[:-1], X.shape[-1], metadata or {}, patches=patches) as zone:
        for done, (index, block) in enumerate(compute_in_order_of_completion(blocks, client), start=1):
            writer.write_node_block(zone, block, slices[index])
            del block
            if progress is not None:
                progress(done, len(blocks), "mesh")
    timings["write_seconds"] = time.perf_counter() - start
    if not evaluate:
        return None
    start = time.perf_counter()
    report = chunked_report(target, geometry, client=client, progress=progress, block_nodes=block_nodes)
    timings["quality_seconds"] = report["quality_seconds"] = time.perf_counter() - start
    return report

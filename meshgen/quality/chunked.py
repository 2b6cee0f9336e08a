"""The quality report of a mesh larger than memory, block by block on Dask.

The node array (a CGNS file read by hyperslabs, or any NumPy or dask array) is cut into the blocks
of ``meshgen.grid.block_slices``. Two passes over the blocks:

1. the bounding box and the non-finite nodes (and in 2D the total signed area): the degenerate-edge
   tolerance and the orientation depend on the whole mesh;
2. the per-cell metrics of each block's cells, computed by the structured path on the block with
   a one-cell overlap on every side (non-orthogonality needs the centroid of the cell across each
   face), with the whole mesh's tolerance and orientation: every cell gets the value the whole-mesh
   path gives it, bit for bit. Each block returns counts, sums, minima, maxima and a quantile
   sketch (``meshgen.quality.sketch``) of each metric, and its share of the boundary nodes.

Merging is exact for the counts, min and max, exact up to the order of floating-point addition for
the means, and within the sketch's relative accuracy (1e-4) for the percentiles p01 and p99. The
boundary deviation is measured on each block's boundary nodes as its summary arrives (the mean of
the distances up to the order of addition). Memory is a few blocks per worker.

A 3D CGNS file on the local threads is read by component in the file's own order (i fastest) into
buffers that the blocks reuse, and evaluated in that order (``structured_hex_file_order``: each
cell's values are the same; design notes §21).
"""

from __future__ import annotations

import os
import queue

import numpy as np

from meshgen.deviation import deviation_figures, distance_to_boundary
from meshgen.errors import MeshgenError
from meshgen.formats import read_header, read_node_block, read_node_components
from meshgen.grid import block_slices
from meshgen.quality import sketch as sketches
from meshgen.quality.kernels import DEGENERATE_TOLERANCE, METRICS
from meshgen.quality.report import assemble_report
from meshgen.quality.structured import apply_degenerate, structured_metrics
from meshgen.resources import available_memory, blocks_in_flight, check_block_nodes
from meshgen.scheduler import compute_in_order_of_completion

# Block size of evaluation in nodes, at most: a block's nodes, centroids, seven metrics and the
# sketch's temporaries take about EVALUATE_BYTES_PER_BLOCK_NODE bytes per node.
__all__ = ["EVALUATE_BLOCK_NODES", "chunked_report", "evaluate_block_nodes", "evaluation_slices"]

EVALUATE_BLOCK_NODES = 1 << 20
EVALUATE_BYTES_PER_BLOCK_NODE = 160
MIN_BLOCK_NODES = 1 << 16


def evaluate_block_nodes() -> int:
    """Nodes per block for the available memory: the blocks in flight (two per worker thread) take
    at most a quarter of it, and a block has at most ``EVALUATE_BLOCK_NODES`` nodes."""
    fitting = available_memory() // (4 * blocks_in_flight() * EVALUATE_BYTES_PER_BLOCK_NODE)
    return int(max(MIN_BLOCK_NODES, min(EVALUATE_BLOCK_NODES, fitting)))


def _reader(source):
    """(node shape, dim, read(block) -> delayed or array of the nodes ``block``) of ``source``."""
    import dask

    if isinstance(source, (str, os.PathLike)):
        node_shape, _ = read_header(source)
        read = dask.delayed(read_node_block, pure=False)
        return node_shape, len(node_shape), lambda block: read(str(source), block)
    shape = tuple(source.shape)
    return shape[:-1], shape[-1], lambda block: source[block + (slice(None),)]


READ_HALO = 3  # node planes a block reads beyond its own: one before, two after (``_grown(block, ..., 1, 2)``)


def evaluation_slices(node_shape, block_nodes: int) -> list[list[slice]]:
    """``meshgen.grid.block_slices`` for evaluation, with the halo counted: a block and the
    ``READ_HALO`` planes it reads around it hold about ``block_nodes`` nodes. Slabs of the last
    axis while a slab of 1 + READ_HALO planes fits; beyond that (planes of about 2.6e5 nodes and
    more at the default size), split along the first axis too, else a 1000^2 plane would be read as
    four planes of 1e6 nodes each, four such blocks in flight."""
    plane = int(np.prod(node_shape[:-1]))
    if plane * (1 + READ_HALO) <= block_nodes:
        return block_slices(node_shape, block_nodes - READ_HALO * plane)
    return block_slices(node_shape, block_nodes // (1 + READ_HALO))


def _grown(block, node_shape, before: int, after: int):
    return tuple(slice(max(s.start - before, 0), min(s.stop + after, n)) for s, n in zip(block, node_shape))


def _extent_of_block(nodes, block, read_block, node_shape):
    """Pass 1 of one block: per component (min, max) of the finite owned nodes, non-finite owned
    nodes, and in 2D the signed area (diagonal cross products) of the owned cells."""
    from meshgen.quality.compiled import finite_extent

    dim = nodes.shape[-1]
    owned = tuple(slice(s.start - r.start, s.stop - r.start) for s, r in zip(block, read_block))
    mine = nodes[owned]
    block_low, block_high, nonfinite = finite_extent(np.ascontiguousarray(mine).reshape(-1, dim))
    low, high = [float(v) for v in block_low], [float(v) for v in block_high]
    area = 0.0
    if dim == 2:
        cells = tuple(slice(o.start, min(o.stop, n - 1 - r.start)) for o, r, n in zip(owned, read_block, node_shape))
        x, y = nodes[..., 0], nodes[..., 1]
        i, j = cells

        def shifted(a, di, dj):
            return a[i.start + di : i.stop + di, j.start + dj : j.stop + dj]

        d1 = (shifted(x, 1, 1) - shifted(x, 0, 0), shifted(y, 1, 1) - shifted(y, 0, 0))
        d2 = (shifted(x, 0, 1) - shifted(x, 1, 0), shifted(y, 0, 1) - shifted(y, 1, 0))
        area = float(np.nansum(d1[0] * d2[1] - d1[1] * d2[0]))
    return low, high, int(nonfinite), area


def _summary_of_cells(values: dict, degenerate: np.ndarray) -> dict:
    """A block's counts and per-metric summaries of its cells' ``values`` (name -> (m,)) and
    ``degenerate`` mask (m,); degenerate cells are counted, not summarised."""
    from meshgen.quality.summary import block_summaries  # numba: only where blocks are evaluated

    summary = {"cells": int(degenerate.size), "degenerate": int(np.count_nonzero(degenerate))}
    summary["inverted"] = int(np.count_nonzero(degenerate | ~(values["scaled_jacobian"] > 0.0)))
    summary["metrics"] = block_summaries({name: values[name] for name in METRICS}, ~degenerate if summary["degenerate"] else None)
    return summary


def _owned_boundary(block, node_shape) -> tuple:
    """Index arrays (one per axis, relative to ``block``) of the mesh's boundary nodes in ``block``,
    each node once, as ``meshgen.deviation.grid_boundary_nodes``."""
    dim = len(node_shape)
    on_boundary = np.zeros(tuple(s.stop - s.start for s in block), dtype=bool)
    for axis in range(dim):
        for end in (0, node_shape[axis] - 1):
            position = end - block[axis].start
            if 0 <= position < on_boundary.shape[axis]:
                index = [slice(None)] * dim
                index[axis] = position
                on_boundary[tuple(index)] = True
    return np.nonzero(on_boundary)


def _positions(local, block, node_shape) -> np.ndarray:
    """Parametric positions (m, dim) of the nodes ``local`` (index arrays relative to ``block``)."""
    return np.stack([(i + s.start) / (n - 1) for i, s, n in zip(local, block, node_shape)], axis=1)


def _quality_of_block(nodes, block, read_block, node_shape, tolerance, orientation):
    """Pass 2 of one block: the summaries of its owned cells (those whose first node is in
    ``block``) and its owned boundary nodes with their parametric positions."""
    owned_cells = tuple(slice(s.start, min(s.stop, n - 1)) for s, n in zip(block, node_shape))
    summary = {"cells": 0, "inverted": 0, "degenerate": 0, "metrics": {}}
    if all(s.stop > s.start for s in owned_cells):
        mine = tuple(slice(s.start - r.start, s.stop - r.start) for s, r in zip(owned_cells, read_block))
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            values, degenerate, _ = structured_metrics(nodes, tolerance=tolerance, orientation=orientation, cells=mine)
        summary = _summary_of_cells(values, degenerate)
    owned = tuple(slice(s.start - r.start, s.stop - r.start) for s, r in zip(block, read_block))
    local = _owned_boundary(block, node_shape)
    summary["boundary"] = (nodes[owned][local], _positions(local, block, node_shape))
    return summary


# --- 3D CGNS files on the local threads: nodes by component, in the file's order -------------


def _reused(buffers: dict, name: str, shape, dtype=float) -> np.ndarray:
    """A C-contiguous array of ``shape`` on the buffer ``name`` of ``buffers``, grown when too small."""
    size = int(np.prod(shape))
    flat = buffers.get(name)
    if flat is None or flat.size < size or flat.dtype != dtype:
        buffers[name] = flat = np.empty(size, dtype=dtype)
    return flat[:size].reshape(shape)


def _file_block(path, block, spare: queue.SimpleQueue):
    """(buffers, nodes) of ``block`` of the CGNS file ``path``: a set of buffers taken from
    ``spare`` (the caller gives it back), nodes by component in the file's order read into one."""
    try:
        buffers = spare.get_nowait()
    except queue.Empty:
        buffers = {}
    shape = (len(block),) + tuple(s.stop - s.start for s in block[::-1])
    return buffers, read_node_components(path, block, _reused(buffers, "nodes", shape))


def _file_extent_of_block(path, block, spare):
    """``_extent_of_block`` of a 3D file's block, read by component (the block alone: no overlap)."""
    from meshgen.quality.compiled import finite_extent

    buffers, nodes = _file_block(path, block, spare)
    try:
        block_low, block_high, nonfinite = finite_extent(nodes.reshape(len(block), -1).T)
    finally:
        spare.put(buffers)
    return [float(v) for v in block_low], [float(v) for v in block_high], int(nonfinite), 0.0


def _file_quality_of_block(path, block, read_block, node_shape, tolerance, spare):
    """``_quality_of_block`` of a 3D file's block: the nodes by component in the file's order
    (``read_node_components``: no transpose), the metrics in that order
    (``structured_hex_file_order``: the same values), buffers reused from block to block."""
    from meshgen.quality.compiled import structured_hex_file_order

    owned_cells = tuple(slice(s.start, min(s.stop, n - 1)) for s, n in zip(block, node_shape))
    summary = {"cells": 0, "inverted": 0, "degenerate": 0, "metrics": {}}
    buffers, nodes = _file_block(path, read_block, spare)
    try:
        if all(s.stop > s.start for s in owned_cells):
            first = tuple(s.start - r.start for s, r in zip(owned_cells, read_block))
            last = tuple(s.stop - r.start for s, r in zip(owned_cells, read_block))
            cells = int(np.prod([b - a for a, b in zip(first, last)]))
            out = _reused(buffers, "metrics", (len(METRICS), cells))
            degenerate = _reused(buffers, "degenerate", (cells,), bool)
            with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
                structured_hex_file_order(nodes, first, last, float(tolerance), out, degenerate)
                values = dict(zip(METRICS, out))
                apply_degenerate(values, degenerate)
            summary = _summary_of_cells(values, degenerate)
        local = _owned_boundary(block, node_shape)
        offset = [s.start - r.start for s, r in zip(block, read_block)]
        points = np.ascontiguousarray(nodes[(slice(None),) + tuple(i + o for i, o in zip(local[::-1], offset[::-1]))].T)
        summary["boundary"] = (points, _positions(local, block, node_shape))
    finally:
        spare.put(buffers)
    return summary


def _merge_metric(a: dict | None, b: dict) -> dict:
    if a is None:
        return b
    return {
        "count": a["count"] + b["count"],
        "sum": a["sum"] + b["sum"],
        "min": min(a["min"], b["min"]),
        "max": max(a["max"], b["max"]),
        "sketch": sketches.merge(a["sketch"], b["sketch"]),
    }


def chunked_report(source, geometry=None, client=None, progress=None, block_nodes: int | None = None) -> dict:
    """The quality report (``meshgen.quality.quality_report``'s schema) of ``source``: a CGNS file
    path, or a node array (NumPy or dask) of shape (n1+1, n2+1[, n3+1], dim), computed block by
    block on Dask's threaded scheduler, or on the cluster of ``client`` (a ``distributed.Client``;
    a file must then be readable by the workers under the same path).

    ``progress(done, total, phase)`` hears about every block. Adds ``"percentiles"``: how p01 and
    p99 were computed. ``block_nodes``: nodes per block (default ``evaluate_block_nodes()``).
    """
    import itertools

    import dask

    node_shape, dim, read = _reader(source)
    if dim not in (2, 3) or len(node_shape) != dim or min(node_shape) < 2:
        raise MeshgenError(
            f"node array must have shape (n1+1, n2+1[, n3+1], dim) with >= 2 nodes per axis, got {node_shape + (dim,)}"
        )
    check_block_nodes(block_nodes, int(np.prod(node_shape)), EVALUATE_BYTES_PER_BLOCK_NODE)
    per_axis = evaluation_slices(node_shape, block_nodes or evaluate_block_nodes())
    blocks = [tuple(p) for p in itertools.product(*per_axis)]
    total = 2 * len(blocks)
    done = 0

    # A 3D file on the local threads: each task reads its block by component into buffers that
    # the next task reuses (``spare``), and the kernels take the file's order as it is.
    by_component = client is None and dim == 3 and isinstance(source, (str, os.PathLike))
    spare = queue.SimpleQueue()
    extent_tasks = []
    for block in blocks:
        if by_component:
            extent_tasks.append(dask.delayed(_file_extent_of_block, pure=False)(str(source), block, spare))
            continue
        read_block = _grown(block, node_shape, 0, 1)
        extent_tasks.append(dask.delayed(_extent_of_block, pure=False)(read(read_block), block, read_block, node_shape))
    low, high = [np.inf] * dim, [-np.inf] * dim
    nonfinite, area = 0, 0.0
    for _, (block_low, block_high, block_nonfinite, block_area) in compute_in_order_of_completion(extent_tasks, client):
        low = [min(a, b) for a, b in zip(low, block_low)]
        high = [max(a, b) for a, b in zip(high, block_high)]
        nonfinite += block_nonfinite
        area += block_area
        done += 1
        if progress is not None:
            progress(done, total, "quality")
    finite = all(np.isfinite(v) for v in low)
    extent = float(np.sqrt(sum((b - a) ** 2 for a, b in zip(low, high)))) if finite else 0.0
    tolerance = DEGENERATE_TOLERANCE * extent
    orientation = (1.0 if area >= 0.0 else -1.0) if dim == 2 else 1.0

    quality_tasks = []
    for block in blocks:
        read_block = _grown(block, node_shape, 1, 2)
        if by_component:
            quality = dask.delayed(_file_quality_of_block, pure=False)
            quality_tasks.append(quality(str(source), block, read_block, node_shape, tolerance, spare))
            continue
        quality_tasks.append(
            dask.delayed(_quality_of_block, pure=False)(read(read_block), block, read_block, node_shape, tolerance, orientation)
        )
    counts = {"cells": 0, "inverted": 0, "degenerate": 0}
    merged = {name: None for name in METRICS}
    if geometry is not None and geometry.dim != dim:
        raise MeshgenError(
            f"geometry '{geometry.name}' is {geometry.dim}D but the mesh is {dim}D: "
            "boundary deviation needs a geometry of the mesh's dimension"
        )
    # Boundary deviation block by block, as each block's summary arrives: memory stays a block's
    # boundary, not the whole mesh's (O(n^2) nodes).
    deviation = {"nodes": 0, "total": 0.0, "largest": None, "nonfinite": 0}
    for _, summary in compute_in_order_of_completion(quality_tasks, client):
        for key in counts:
            counts[key] += summary[key]
        for name, part in summary["metrics"].items():
            merged[name] = _merge_metric(merged[name], part)
        points, positions = summary.pop("boundary")
        if geometry is not None and len(points):
            distance = distance_to_boundary(points, geometry, positions)
            finite = distance[~np.isnan(distance)]
            deviation["nodes"] += len(distance)
            deviation["nonfinite"] += len(distance) - len(finite)
            deviation["total"] += float(finite.sum())
            if len(finite):
                largest = float(finite.max())
                deviation["largest"] = largest if deviation["largest"] is None else max(deviation["largest"], largest)
        del points, positions
        done += 1
        if progress is not None:
            progress(done, total, "quality")
    if counts["degenerate"] == counts["cells"]:
        raise MeshgenError(
            f"nothing to evaluate: all {counts['cells']} cells are degenerate (zero-length edges or non-finite coordinates)"
        )
    summaries = {}
    for name in METRICS:
        part = merged[name]
        summaries[name] = {
            "mean": part["sum"] / part["count"],
            "min": part["min"],
            "max": part["max"],
            "p01": sketches.quantile(part["sketch"], 0.01, part["min"], part["max"]),
            "p99": sketches.quantile(part["sketch"], 0.99, part["min"], part["max"]),
        }
    info = {"dim": dim, "nonfinite_nodes": nonfinite}
    if geometry is not None:
        info["boundary_deviation"] = deviation_figures(
            deviation["nodes"], deviation["total"], deviation["largest"], deviation["nonfinite"], geometry
        )
    report = assemble_report(summaries, counts, info, geometry)
    report["percentiles"] = (
        f"p01 and p99 from a mergeable quantile sketch (DDSketch), relative accuracy {sketches.RELATIVE_ACCURACY:g}; "
        "mean, min and max exact; computed block by block"
    )
    return report

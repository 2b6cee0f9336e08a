"""The quality report of a mesh larger than memory, block by block on Dask.

The node array (a CGNS file read by hyperslabs, or any NumPy or dask array) is cut into the blocks
of ``meshgen.geometry.grid.block_slices``. Each block is read once, with a one-cell overlap on every side
(non-orthogonality needs the centroid of the cell across each face), and gives:

- the bounding box and the non-finite nodes of the nodes it owns (and in 2D the signed area of its
  cells): the degenerate-edge tolerance and the orientation depend on the whole mesh;
- the per-cell metrics of the cells it owns, computed by the structured path with a provisional
  tolerance and orientation: those of the block itself. The block's bounding box lies in the
  mesh's, so its tolerance is at most the mesh's; a cell is classified differently by the two
  only if one of its edges is longer than the block's tolerance and at most the mesh's, so the
  block also returns its cells' shortest edge longer than its own tolerance. Each block returns
  counts, sums, minima, maxima and a quantile sketch (``meshgen.quality.sketch``) of each metric,
  and its share of the boundary nodes.

When every block's shortest such edge is longer than the mesh's tolerance and every block's own
orientation is the mesh's (any mesh without edges within 1e-12 of its diagonal, nor folded in 2D),
the blocks' values are those of the whole-mesh path, bit for bit; otherwise a second pass
evaluates every block again with the mesh's tolerance and orientation (design notes §21, "One
pass over a file's blocks").

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

from meshgen.errors import MeshgenError
from meshgen.formats import read_header, read_node_block, read_node_components
from meshgen.geometry.grid import block_slices
from meshgen.quality import sketch as sketches
from meshgen.quality.deviation import deviation_figures, distance_to_boundary
from meshgen.quality.kernels import METRICS
from meshgen.quality.report import assemble_report
from meshgen.quality.structured import apply_degenerate, box_tolerance, signed_area_2d, structured_metrics
from meshgen.run.resources import available_memory, blocks_in_flight, check_block_nodes
from meshgen.run.scheduler import compute_in_order_of_completion

# Block size of evaluation in nodes, at most: a block's nodes, centroids, seven metrics and the
# sketch's temporaries take about EVALUATE_BYTES_PER_BLOCK_NODE bytes per node.
__all__ = ["EVALUATE_BLOCK_NODES", "chunked_report", "evaluate_block_nodes", "evaluation_slices"]

EVALUATE_BLOCK_NODES = 1 << 20
EVALUATE_BYTES_PER_BLOCK_NODE = 160
MIN_BLOCK_NODES = 1 << 16
SECOND_PASS = "quality, second pass"  # the phase ``progress`` hears in the rare second pass


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
    """``meshgen.geometry.grid.block_slices`` for evaluation, with the halo counted: a block and the
    ``READ_HALO`` planes it reads around it hold about ``block_nodes`` nodes. Slabs of the last
    axis while a slab of 1 + READ_HALO planes fits; beyond that (planes of about 2.6e5 nodes and
    more at the default size), split along the first axis too, else a 1000^2 plane would be read as
    four planes of 1e6 nodes each, four such blocks in flight. The slabs are then made equal (to
    a plane) in as many: 101 planes in 2^20-node blocks are 51 + 50 planes, not 99 + 2, so the two
    blocks of the 1e6-cell benchmark run side by side on two threads."""
    plane = int(np.prod(node_shape[:-1]))
    if plane * (1 + READ_HALO) <= block_nodes:
        per_axis = block_slices(node_shape, block_nodes - READ_HALO * plane)
    else:
        per_axis = block_slices(node_shape, block_nodes // (1 + READ_HALO))
    n, count = node_shape[-1], len(per_axis[-1])
    per_axis[-1] = [slice(n * b // count, n * (b + 1) // count) for b in range(count)]
    return per_axis


def _grown(block, node_shape, before: int, after: int):
    return tuple(slice(max(s.start - before, 0), min(s.stop + after, n)) for s, n in zip(block, node_shape))


def _orientation(area: float, dim: int) -> float:
    return (1.0 if area >= 0.0 else -1.0) if dim == 2 else 1.0


def _owned_cells(block, node_shape) -> tuple:
    """The cells whose first node is in ``block`` (mesh indices, a slice per axis; empty on an axis
    where the block holds only the mesh's last node)."""
    return tuple(slice(s.start, min(s.stop, n - 1)) for s, n in zip(block, node_shape))


def _finite_box(F, lo, own):
    """(low, high, nonfinite) of the nodes ``lo <= (i, j, k) < own`` of ``F`` (dim, nk, nj, ni): per
    component min and max of the finite nodes ((inf, -inf) when none), the nodes with a non-finite
    coordinate. NumPy's extremes when all are finite, else the compiled pass over the rows."""
    nodes = F[:, lo[2] : own[2], lo[1] : own[1], lo[0] : own[0]]
    low, high = [float(c.min()) for c in nodes], [float(c.max()) for c in nodes]
    if np.all(np.isfinite(low + high)):
        return low, high, 0
    from meshgen.quality.compiled import finite_extent

    low, high, nonfinite = finite_extent(nodes.reshape(len(nodes), -1).T)
    return [float(v) for v in low], [float(v) for v in high], int(nonfinite)


def _block_figures(F, block, read_block, node_shape, has_cells: bool):
    """(low, high, nonfinite, tolerance, shortest) of a block from its nodes by component ``F``
    (dim, [nk,] nj, ni), read at ``read_block``: per component min and max of its finite owned
    nodes, its owned nodes with a non-finite coordinate, its own tolerance (that of its bounding
    box: a provisional one, at most the mesh's) and the shortest edge of its owned cells longer than
    that (inf when none): the mesh's tolerance classifies them as the block's does unless it is at
    least that edge."""
    from meshgen.quality.edges_compiled import shortest_edge_above

    if len(block) == 2:
        F = F[:, None]
    lo = [s.start - r.start for s, r in zip(block, read_block)] + [0] * (3 - len(block))
    own = [s.stop - r.start for s, r in zip(block, read_block)] + [1] * (3 - len(block))
    low, high, nonfinite = _finite_box(F, lo, own)
    tolerance = box_tolerance(low, high)
    shortest = np.inf
    if has_cells:  # the edges of their nodes
        box = [min(s.stop + 1, n) - r.start for s, r, n in zip(block, read_block, node_shape)] + [1] * (3 - len(block))
        shortest = shortest_edge_above(F, lo, box)
        if shortest <= tolerance:  # a positive edge at most the block's tolerance: the shortest one above it
            shortest = shortest_edge_above(F, lo, box, tolerance)
    return low, high, nonfinite, tolerance, shortest


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
    each node once, as ``meshgen.quality.deviation.grid_boundary_nodes``."""
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


def _quality_of_block(nodes, block, read_block, node_shape, tolerance, orientation, boundary: bool):
    """The summaries of a block's owned cells (those whose first node is in ``block``) and, if
    ``boundary``, its owned boundary nodes with their parametric positions. ``tolerance`` None: the
    first pass, with the block's own tolerance and orientation, its figures under ``"figures"``:
    (low, high, nonfinite, area, tolerance, orientation, shortest) (``_block_figures``)."""
    figures = None
    owned_cells = _owned_cells(block, node_shape)
    mine = tuple(slice(s.start - r.start, s.stop - r.start) for s, r in zip(owned_cells, read_block))
    has_cells = all(s.stop > s.start for s in owned_cells)
    if tolerance is None:
        dim = nodes.shape[-1]
        low, high, nonfinite, tolerance, shortest = _block_figures(
            nodes.transpose((dim,) + tuple(range(dim - 1, -1, -1))), block, read_block, node_shape, has_cells
        )
        area = signed_area_2d(nodes[mine[0].start : mine[0].stop + 1, mine[1].start : mine[1].stop + 1]) if dim == 2 else 0.0
        orientation = _orientation(area, dim)
        # a block without cells orients none: it agrees with any orientation of the mesh
        figures = (low, high, nonfinite, area, tolerance, orientation if has_cells else None, shortest)
    summary = {"cells": 0, "inverted": 0, "degenerate": 0, "metrics": {}}
    if has_cells:
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            values, degenerate, _ = structured_metrics(nodes, tolerance=tolerance, orientation=orientation, cells=mine)
        summary = _summary_of_cells(values, degenerate)
    if boundary:
        owned = tuple(slice(s.start - r.start, s.stop - r.start) for s, r in zip(block, read_block))
        local = _owned_boundary(block, node_shape)
        summary["boundary"] = (nodes[owned][local], _positions(local, block, node_shape))
    summary["figures"] = figures
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


def _file_quality_of_block(path, block, read_block, node_shape, tolerance, spare, boundary: bool):
    """``_quality_of_block`` of a 3D file's block: the nodes by component in the file's order
    (``read_node_components``: no transpose), the metrics in that order
    (``structured_hex_file_order``: the same values), buffers reused from block to block."""
    from meshgen.quality.compiled import structured_hex_file_order

    owned_cells = _owned_cells(block, node_shape)
    has_cells = all(s.stop > s.start for s in owned_cells)
    summary = {"cells": 0, "inverted": 0, "degenerate": 0, "metrics": {}}
    buffers, nodes = _file_block(path, read_block, spare)
    try:
        figures = None
        if tolerance is None:
            low, high, nonfinite, tolerance, shortest = _block_figures(nodes, block, read_block, node_shape, has_cells)
            figures = (low, high, nonfinite, 0.0, tolerance, 1.0, shortest)
        if has_cells:
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
        if boundary:
            local = _owned_boundary(block, node_shape)
            offset = [s.start - r.start for s, r in zip(block, read_block)]
            points = np.ascontiguousarray(nodes[(slice(None),) + tuple(i + o for i, o in zip(local[::-1], offset[::-1]))].T)
            summary["boundary"] = (points, _positions(local, block, node_shape))
        summary["figures"] = figures
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

    ``progress(done, total, phase)`` hears about every block: phase "quality", and in the rare
    second pass ``SECOND_PASS`` (``done`` from 1 again). Adds ``"percentiles"``: how p01 and
    p99 were computed. ``block_nodes``: nodes per block (default ``evaluate_block_nodes()``).
    """
    import itertools

    import dask

    node_shape, dim, read = _reader(source)
    if dim not in (2, 3) or len(node_shape) != dim or min(node_shape) < 2:
        raise MeshgenError(
            f"node array must have shape (n1+1, n2+1[, n3+1], dim) with >= 2 nodes per axis, got {node_shape + (dim,)}"
        )
    if geometry is not None and geometry.dim != dim:
        raise MeshgenError(
            f"geometry '{geometry.name}' is {geometry.dim}D but the mesh is {dim}D: "
            "boundary deviation needs a geometry of the mesh's dimension"
        )
    check_block_nodes(block_nodes, int(np.prod(node_shape)), EVALUATE_BYTES_PER_BLOCK_NODE)
    per_axis = evaluation_slices(node_shape, block_nodes or evaluate_block_nodes())
    blocks = [tuple(p) for p in itertools.product(*per_axis)]

    # A 3D file on the local threads: each task reads its block by component into buffers that
    # the next task reuses (``spare``), and the kernels take the file's order as it is.
    by_component = client is None and dim == 3 and isinstance(source, (str, os.PathLike))
    spare = queue.SimpleQueue()

    def tasks(tolerance, orientation, boundary):
        """One task per block; ``tolerance`` None: the first pass (each block's own tolerance)."""
        for block in blocks:
            read_block = _grown(block, node_shape, 1, 2)
            if by_component:
                quality = dask.delayed(_file_quality_of_block, pure=False)
                yield quality(str(source), block, read_block, node_shape, tolerance, spare, boundary)
            else:
                quality = dask.delayed(_quality_of_block, pure=False)
                yield quality(read(read_block), block, read_block, node_shape, tolerance, orientation, boundary)

    counts = {"cells": 0, "inverted": 0, "degenerate": 0}
    merged = {name: None for name in METRICS}

    def merge(summary):
        for key in counts:
            counts[key] += summary[key]
        for name, part in summary["metrics"].items():
            merged[name] = _merge_metric(merged[name], part)

    # One pass: each block read once, evaluated with its own tolerance and orientation, its bounding
    # box (and 2D area) merged into the mesh's. Boundary deviation block by block, as each block's
    # summary arrives: memory stays a block's boundary, not the whole mesh's (O(n^2) nodes).
    low, high = [np.inf] * dim, [-np.inf] * dim
    nonfinite, area = 0, 0.0
    provisional = []  # (tolerance, orientation, shortest edge above that tolerance) of each block
    deviation = {"nodes": 0, "total": 0.0, "largest": None, "nonfinite": 0}
    for done, (_, summary) in enumerate(compute_in_order_of_completion(list(tasks(None, None, geometry is not None)), client), 1):
        block_low, block_high, block_nonfinite, block_area, *block_provisional = summary.pop("figures")
        low = [min(a, b) for a, b in zip(low, block_low)]
        high = [max(a, b) for a, b in zip(high, block_high)]
        nonfinite += block_nonfinite
        area += block_area
        provisional.append(block_provisional)
        merge(summary)
        if geometry is not None:
            points, positions = summary.pop("boundary")
            if len(points):
                distance = distance_to_boundary(points, geometry, positions)
                finite = distance[~np.isnan(distance)]
                deviation["nodes"] += len(distance)
                deviation["nonfinite"] += len(distance) - len(finite)
                deviation["total"] += float(finite.sum())
                if len(finite):
                    largest = float(finite.max())
                    deviation["largest"] = largest if deviation["largest"] is None else max(deviation["largest"], largest)
            del points, positions
        if progress is not None:
            progress(done, len(blocks), "quality")
    tolerance, orientation = box_tolerance(low, high), _orientation(area, dim)

    # A block whose cells the mesh's tolerance or orientation could classify or orient otherwise
    # than its own (an edge longer than its tolerance, at most the mesh's; a 2D block folded
    # against the mesh): every block again, with the mesh's (design notes §21).
    # (A block's tolerance above the mesh's cannot happen, the formula being monotone; it would be
    # caught all the same, should a libm's ``**`` not be.)
    if any(
        own_tolerance > tolerance or shortest <= tolerance or own not in (None, orientation)
        for own_tolerance, own, shortest in provisional
    ):
        counts.update(dict.fromkeys(counts, 0))
        merged.update(dict.fromkeys(METRICS))
        for done, (_, summary) in enumerate(
            compute_in_order_of_completion(list(tasks(tolerance, orientation, False)), client), 1
        ):
            merge(summary)
            if progress is not None:
                progress(done, len(blocks), SECOND_PASS)
    if counts["degenerate"] == counts["cells"]:
        raise MeshgenError(
            f"nothing to evaluate: all {counts['cells']} cells are degenerate (zero-length edges or non-finite coordinates)"
        )
    summaries = {name: sketches.part_figures(merged[name]) for name in METRICS}
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

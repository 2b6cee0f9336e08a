"""A .vts of a mesh larger than memory: the file of ``meshgen.formats._vts``, byte for byte,
written slab by slab from a node file (``meshgen.formats.streamed.NodeFile``).

VTK's structured order runs i fastest, so a slab of the last axis (k) is a contiguous run of the
points array, and the arrays are compressed in blocks of ``BLOCK_BYTES`` of that run, whatever
the slabs: the blocks are cut from the slabs' bytes as they come (a block may span two slabs) and
compressed on all cores, a few in flight. The XML before the appended data gives each array's
offset, so the small arrays (field data, the patch ids, which compress to a few bytes a block)
are compressed first and kept; the points, last in the appended data, go straight to the file
behind a placeholder for their compression header, which is written once their blocks' sizes are
known (its length, one entry per block, is known in advance).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from meshgen.formats._vts import FILE_TAIL, PATCH_ARRAY, data_array, field_arrays, file_head, patch_ids, whole_extent
from meshgen.formats._vtu import BLOCK_BYTES, HEADER_TYPE, compress_block, compression_header, cpu_count
from meshgen.formats.streamed import NodeFile

__all__ = ["byte_blocks", "write_streamed"]


def byte_blocks(parts, block_bytes: int = BLOCK_BYTES):
    """The consecutive bytes of the arrays ``parts`` (C-contiguous) cut into blocks of
    ``block_bytes`` (the last one shorter), as the blocks of one array would be."""
    carry = b""
    for part in parts:
        view = memoryview(np.ascontiguousarray(part)).cast("B")
        start = 0
        if carry:
            start = block_bytes - len(carry)
            carry += bytes(view[:start])
            if len(carry) < block_bytes:
                continue
            yield carry
            carry = b""
        while start + block_bytes <= len(view):
            yield view[start : start + block_bytes]
            start += block_bytes
        carry = bytes(view[start:])
    if carry:
        yield carry


def _compressed(pool, blocks, in_flight: int):
    """The zlib streams (``compress_block``) of ``blocks`` in order, at most ``in_flight`` pending."""
    pending = []
    for block in blocks:
        pending.append(pool.submit(compress_block, block))
        if len(pending) >= in_flight:
            yield pending.pop(0).result()
    for future in pending:
        yield future.result()


def write_streamed(path, nodes: NodeFile, metadata: dict, patches) -> None:
    """``meshgen.formats._vts.write`` of the mesh in ``nodes`` (no cell data), slab by slab."""
    node_shape, dim = tuple(nodes.node_shape), nodes.dim
    order = tuple(range(dim - 1, -1, -1))  # VTK's i-fastest order
    last = dim - 1
    workers = cpu_count()
    pool = ThreadPoolExecutor(max_workers=workers)
    try:
        small = {"FieldData": [], "PointData": []}
        for name, more, codes in field_arrays(metadata, patches):
            small["FieldData"].append(
                (name, more, codes.dtype, codes.nbytes, list(_compressed(pool, byte_blocks([codes]), workers)))
            )

        def patch_parts():
            for part in nodes.slabs(last):
                block = tuple(part if d == last else slice(0, n) for d, n in enumerate(node_shape))
                yield np.transpose(patch_ids(node_shape, patches, block), order)

        count = int(np.prod(node_shape))
        streams = list(_compressed(pool, byte_blocks(patch_parts()), 2 * workers))
        small["PointData"].append((PATCH_ARRAY, {}, np.dtype("<i4"), 4 * count, streams))

        parts, offset, elements = [], 0, {"CellData": ""}
        for section in ("FieldData", "PointData"):
            lines = []
            for name, more, dtype, nbytes, streams in small[section]:
                header = compression_header(nbytes, BLOCK_BYTES, streams)
                lines.append(data_array(dtype, name, more, offset))
                parts += [header, *streams]
                offset += len(header) + sum(map(len, streams))
            elements[section] = f"<{section}>\n{''.join(lines)}</{section}>\n"
        elements["Points"] = f"<Points>\n{data_array('<f8', 'Points', {'NumberOfComponents': 3}, offset)}</Points>\n"

        def point_parts():
            for part in nodes.slabs(last):
                slab = nodes.read(last, part)
                points = np.zeros(slab.shape[:-1][::-1] + (3,))
                points[..., :dim] = np.transpose(slab, order + (dim,))
                yield points

        nbytes = 24 * count
        block_count = -(-nbytes // BLOCK_BYTES)
        with open(path, "wb") as file:
            file.write(file_head(whole_extent(node_shape), elements))
            for part in parts:
                file.write(part)
            header_at = file.tell()
            file.write(bytes(8 * (3 + block_count)))  # the points' compression header, written below
            sizes = []
            for stream in _compressed(pool, byte_blocks(point_parts()), 2 * workers):
                file.write(stream)
                sizes.append(len(stream))
            file.write(FILE_TAIL)
            file.seek(header_at)
            file.write(np.array([len(sizes), BLOCK_BYTES, nbytes % BLOCK_BYTES, *sizes], dtype=HEADER_TYPE).tobytes())
    finally:
        pool.shutdown(cancel_futures=True)

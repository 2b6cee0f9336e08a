"""A mesh request for a block set (``meshgen.blocks``), as ``meshgen.request.carry_out`` carries
it out for a geometry that declares blocks (design notes §14, §20): the checks of what a block set
takes (before any work), the mesh of every block (``tfi`` per block with shared interface nodes;
``elliptic`` with the interface nodes solved as interior nodes; ``auto`` is ``elliptic``, one note
line saying so), and the write through ``meshgen.formats.multiblock`` with the merged mesh's
quality sidecar. The result is a ``Mesh`` whose ``blocks`` hold the node arrays, ``X`` None.
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

from meshgen.block_grading import first_cell_heights, graded_block_set, parse_first_cell, parse_wall_clusters
from meshgen.blocks import BlockSet, is_multiblock, load_block_set, tfi_blocks
from meshgen.elliptic_blocks import elliptic_blocks
from meshgen.errors import ParameterError
from meshgen.formats.multiblock import check_block_output
from meshgen.geometry import Geometry, available_names, plugin_module
from meshgen.meshing import Mesh

__all__ = ["BLOCK_METHODS", "block_spec", "mesh_block_set"]

BLOCK_METHODS = ("tfi", "elliptic")
AUTO_METHOD = "elliptic"  # what ``auto`` meshes a block set with (no trained model meshes one)

# Request fields that single-block meshes take and block sets do not: (field, parameter named).
_SINGLE_BLOCK_ONLY = (
    ("checkpoint", "checkpoint"),
    ("correct", "correct"),
    ("polish", "polish"),
    ("device", "device"),
    ("boundary_layout", "boundary_layout"),
    ("orthogonal", "orthogonal"),
    ("patches", "patch"),
    ("ascii", "ascii"),
    ("chunked", "chunked"),
    ("scheduler", "scheduler"),
)


def block_spec(geometry) -> str | None:
    """The plugin spec (name or path) of ``geometry`` (a name, a path or a loaded Geometry) when it
    declares blocks, else None."""
    if geometry is None:
        return None
    if isinstance(geometry, Geometry):
        if geometry.name in available_names() and plugin_module(geometry.name)[1] == geometry.source:
            spec = geometry.name
        elif geometry.source and Path(geometry.source).is_file():
            spec = geometry.source
        else:
            return None
    else:
        spec = str(geometry)
    if Path(spec).suffix.lower() not in ("", ".py"):
        return None  # a shape file is one block
    return spec if is_multiblock(spec) else None


def mesh_block_set(request, spec: str, say, progress) -> Mesh:
    """Carry out ``request`` (a ``meshgen.request.MeshRequest``) for the block-set plugin ``spec``.
    ``say``, ``progress``: as ``carry_out`` takes them. Returns the Mesh (``blocks``, the
    BlockSet as ``geometry``, ``notes``)."""
    method, block_set, output, notes = _check(request, spec, say)
    timings = []
    with progress(f"{method} mesh", method == "elliptic") as callback:
        for _ in range(max(1, int(request.timing_repeats))):
            start = time.perf_counter()
            if method == "tfi":
                Xs, info = tfi_blocks(block_set), {}
            else:
                Xs, info = elliptic_blocks(block_set, tol=request.tol, max_iter=request.max_iter, progress=callback)
            timings.append(time.perf_counter() - start)
    if request.first_cell:
        asked = parse_first_cell(request.first_cell, block_set)
        measured = first_cell_heights(block_set, Xs, asked)
        info["first_cell"] = {name: {"asked": asked[name], **measured[name]} for name in asked}
    mesh = Mesh(
        None,
        block_set,
        method,
        tuple(request.dims),
        tuple(request.clusters),
        info,
        statistics.median(timings),
        timings=tuple(timings),
        notes=tuple(notes),
        blocks=Xs,
    )
    if output is None:
        mesh.quality_report = mesh.report() if request.quality else None
        return mesh
    mesh.output = Path(output)
    mesh.write(output, request.format, quality=request.quality)
    return mesh


def _check(request, spec: str, say) -> tuple[str, BlockSet, Path | None, list[str]]:
    """(method, block set, checked output path or None, notes), or the error, before any work."""
    for field_name, parameter in _SINGLE_BLOCK_ONLY:
        if getattr(request, field_name) not in (None, False, (), []):
            raise ParameterError(parameter, f"{{name}}: not available for the multi-block geometry '{spec}'")
    method, notes = request.method, []
    if method == "auto":
        method = AUTO_METHOD
        notes.append(f"note: no trained model meshes the multi-block geometry '{spec}': meshing with {AUTO_METHOD}")
    if method not in BLOCK_METHODS:
        raise ParameterError(
            "method", f"method '{method}' does not mesh multi-block geometries (methods that do: {', '.join(BLOCK_METHODS)})"
        )
    if method == "tfi":
        for name in ("tol", "max_iter"):
            if getattr(request, name) is not None:
                raise ParameterError(name, "{name} applies to the elliptic method, not to 'tfi'")
    params = dict(request.geometry.values) if isinstance(request.geometry, Geometry) else {}
    params.update(request.params or {})
    block_set = load_block_set(spec, params, request.dims)
    if request.first_cell or request.clusters:
        heights = parse_first_cell(request.first_cell, block_set)
        block_set = graded_block_set(block_set, heights, parse_wall_clusters(request.clusters, block_set))
    output = check_block_output(request.output, request.format, block_set) if request.output is not None else None
    for line in notes:
        say(line)
    return method, block_set, output, notes

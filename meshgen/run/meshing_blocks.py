"""A mesh request for a block set (``meshgen.geometry.blocks``), as ``meshgen.run.request.carry_out`` carries
it out for a geometry that declares blocks (design notes §14, §20): the checks of what a block set
takes (before any work), the mesh of every block (``tfi`` per block with shared interface nodes;
``elliptic`` with the interface nodes solved as interior nodes; ``neural`` with the block set's
trained model, ``meshgen.neural.block_inference``; ``auto`` is ``neural`` when a model of the
block set is found, else ``elliptic``, one note line saying so), and the write through ``meshgen.formats.multiblock`` with the merged mesh's
quality sidecar. The result is a ``Mesh`` whose ``blocks`` hold the node arrays, ``X`` None.
"""

from __future__ import annotations

import statistics
import time
from pathlib import Path

from meshgen.errors import MeshgenError, ParameterError
from meshgen.formats.multiblock import check_block_output
from meshgen.geometry.blocks import BlockSet, is_multiblock, load_block_set, tfi_blocks
from meshgen.geometry.grading import first_cell_heights, graded_block_set, parse_first_cell, parse_wall_clusters
from meshgen.geometry.plugins import Geometry, available_names, load_geometry, plugin_module
from meshgen.methods.elliptic import elliptic_blocks
from meshgen.neural.block_inference import is_block_model, neural_blocks
from meshgen.neural.device import inference_device
from meshgen.neural.models import TrainedModel, find_model
from meshgen.run.meshing import Mesh

__all__ = ["BLOCK_METHODS", "block_spec", "checkpoint_block_spec", "mesh_block_set"]

BLOCK_METHODS = ("tfi", "elliptic", "neural")
AUTO_METHOD = "elliptic"  # what ``auto`` meshes a block set with when no trained model of it is found
NEURAL_OPTIONS = ("checkpoint", "correct", "polish", "device")  # request fields only the neural method takes

# Request fields that single-block meshes take and block sets do not: (field, parameter named).
_SINGLE_BLOCK_ONLY = (
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


def checkpoint_block_spec(checkpoint) -> str | None:
    """The block-set spec a checkpoint (a path or a loaded ``TrainedModel``) was trained on, else
    None (a single-shape model, or a file the single-block path will report on)."""
    from meshgen.neural.checkpoint import load_checkpoint  # brings torch: only when a checkpoint is given

    try:
        loaded = checkpoint.checkpoint if hasattr(checkpoint, "checkpoint") else load_checkpoint(checkpoint)
    except MeshgenError:
        return None
    entry = loaded.get("geometry", {})
    return str(entry["spec"]) if "blocks" in entry else None


def _block_model(request, block_set_name: str, params: dict, fallback: bool, warn=None):
    """The block model to mesh with (``meshgen.neural.models.find_model``: the checkpoint given, else
    the newest run of the geometry), or None with ``fallback`` when there is none."""
    checkpoint = request.checkpoint
    try:
        if isinstance(checkpoint, TrainedModel):
            model = checkpoint
        else:
            model = find_model(
                checkpoint, geometry_name=block_set_name, params=params, default_geometry=block_set_name, warn=warn
            )
    except MeshgenError:
        if fallback and checkpoint is None:
            return None
        raise
    if not is_block_model(model.checkpoint["model"]):
        raise ParameterError("checkpoint", f"{{name}} {model.path} holds a one-block model, not one of '{block_set_name}'")
    return model


def mesh_block_set(request, spec: str, say, progress) -> Mesh:
    """Carry out ``request`` (a ``meshgen.run.request.MeshRequest``) for the block-set plugin ``spec``.
    ``say``, ``progress``: as ``carry_out`` takes them. Returns the Mesh (``blocks``, the
    BlockSet as ``geometry``, ``notes``)."""
    method, block_set, output, notes, model = _check(request, spec, say)
    timings = []
    with progress(f"{method} mesh", method != "tfi") as callback:
        for _ in range(max(1, int(request.timing_repeats))):
            start = time.perf_counter()
            if method == "tfi":
                Xs, info = tfi_blocks(block_set), {}
            elif method == "neural":
                Xs, info = _neural(request, block_set, model, callback)
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


def _neural(request, block_set: BlockSet, model, progress=None):
    """The neural mesh of the block set (``meshgen.neural.block_inference.neural_blocks``) and its
    info; with ``polish`` (True only: not by default, unlike one block's) the multi-block elliptic
    solver started from it. The default stays the network's conforming mesh (one forward pass):
    polishing it is an elliptic solve that takes as many sweeps as the one from the TFI (the pipe's
    benchmark model at 8 4 4 and 16 8 4: 30 and 36 sweeps to 0.17 and 0.16 deg of mean min angle
    above the elliptic mesh, whose solve from the TFI takes 21 and 26; design notes §20)."""
    device = inference_device(request.device or "auto")
    correct = request.correct is not False
    Xs, correction = neural_blocks(block_set, model.checkpoint["model"], correct=correct, device=device)
    info = {"model": model.metadata(), "correction": correction}
    if correct and request.polish:
        start = [X.copy() for X in Xs]
        Xs, solved = elliptic_blocks(block_set, tol=request.tol, max_iter=request.max_iter, progress=progress, initial=start)
        moved = max(float(abs(X - S).max()) for X, S in zip(Xs, start)) / block_set.length
        info["polish"] = {
            "polished": True,
            "sweeps": int(solved["sweeps"]),
            "final_update": float(solved.get("final_update", 0.0)),
            "converged": bool(solved["converged"]),
            "largest_move_rel": moved,
        }
        info["warnings"] = solved.get("warnings", [])
    return Xs, info


def _check(request, spec: str, say):
    """(method, block set, checked output path or None, notes, model or None), or the error, before any work."""
    for field_name, parameter in _SINGLE_BLOCK_ONLY:
        if getattr(request, field_name) not in (None, False, (), []):
            raise ParameterError(parameter, f"{{name}}: not available for the multi-block geometry '{spec}'")
    method, notes, model = request.method, [], None
    if method not in BLOCK_METHODS + ("auto",):
        raise ParameterError(
            "method", f"method '{method}' does not mesh multi-block geometries (methods that do: {', '.join(BLOCK_METHODS)})"
        )
    if method not in ("neural", "auto"):
        for name in NEURAL_OPTIONS:
            if getattr(request, name) is not None:
                raise ParameterError(name, f"{{name}} applies to the neural method, not to '{method}'")
    params = dict(request.geometry.values) if isinstance(request.geometry, Geometry) else {}
    params.update(request.params or {})
    if method in ("neural", "auto"):
        name = load_geometry(spec, check=False).name
        model = _block_model(request, name, dict(request.params or {}), fallback=method == "auto")
        if model is None:
            method = AUTO_METHOD
            notes.append(
                f"note: no trained model for the multi-block geometry '{spec}': meshing with {AUTO_METHOD} "
                f"(meshgen train -g {spec} trains one)"
            )
        else:
            method = "neural"
            params = {**dict(model.geometry_entry["params"]), **params}  # the geometry it was trained on
            notes.append(f"model: {model.describe()}")
    if method == "tfi" or (method == "neural" and not (request.polish and request.correct is not False)):
        for name in ("tol", "max_iter"):
            if getattr(request, name) is not None:
                raise ParameterError(
                    name, f"{{name}} applies to the elliptic method (and the neural mesh's polish), not to '{method}'"
                )
    block_set = load_block_set(spec, params, request.dims)
    if request.first_cell or request.clusters:
        heights = parse_first_cell(request.first_cell, block_set)
        block_set = graded_block_set(block_set, heights, parse_wall_clusters(request.clusters, block_set))
    output = check_block_output(request.output, request.format, block_set) if request.output is not None else None
    for line in notes:
        say(line)
    return method, block_set, output, notes, model

"""What a mesh request makes: the ``Mesh`` (node array, how it was made, what it measured), the
one description of a run that every written file records (``run_metadata``), and the mesh of a
block set (``mesh_block_set``).

A block set's mesh (``meshgen.geometry.blocks``) is a Mesh too: ``X`` None, ``blocks`` its node
arrays, ``geometry`` the ``BlockSet``. ``meshgen.run.request.carry_out`` hands a geometry that
declares blocks to ``mesh_block_set`` (design notes §14, §20): the checks of what a block set takes
(before any work), the mesh of every block (``tfi`` per block with shared interface nodes;
``elliptic`` with the interface nodes solved as interior nodes; ``neural`` with the block set's
trained model, ``meshgen.neural.inference``; ``auto`` is ``neural`` when a model of the block
set is found, else ``elliptic``, one note line saying so), and the write through
``meshgen.formats.multiblock`` with the merged mesh's quality sidecar (``meshgen.quality.merged``:
interfaces as interior faces, the block set's boundary deviation).

Two optional plugin hooks: ``mesh_elliptic(block_set, tol, max_iter, progress) -> (Xs, info)``
makes the plugin's ``elliptic`` mesh in place of ``elliptic_blocks`` (the airfoil's: near-wall
layers marched, the rest solved), and ``notes(block_set) -> [lines]`` adds lines said before the
work (the airfoil's wall spacing); a dict ``elliptic_options`` is passed on to the elliptic call
(a swept CAD solid's ``slide_section``), except ``keep_tfi`` (true: the elliptic mesh is the TFI
mesh; the plugin's notes say why).
"""

from __future__ import annotations

import os
import statistics
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from meshgen import __version__
from meshgen.errors import FormatError, MeshgenError, ParameterError
from meshgen.formats.multiblock import check_block_output, write_blocks
from meshgen.geometry.block_nodes import merged_mesh
from meshgen.geometry.blocks import BlockSet, block_spec, load_block_set, tfi_blocks
from meshgen.geometry.grading import first_cell_heights, graded_block_set, parse_first_cell, parse_wall_clusters
from meshgen.geometry.patches import Patch, as_records, geometry_patches
from meshgen.geometry.plugins import Geometry, is_airfoil_file, load_geometry, plugin_module
from meshgen.geometry.topology_file import is_topology_file
from meshgen.methods.elliptic import elliptic_blocks
from meshgen.neural.checkpoint_data import read_plain_checkpoint
from meshgen.neural.device import inference_device
from meshgen.neural.inference import is_block_model, neural_blocks
from meshgen.neural.models import MODELS_DIR, TrainedModel, display_path, find_model, load_model
from meshgen.neural.wall_family import check_member_values, is_wall_family, member_values
from meshgen.quality import (
    cell_metrics,
    cell_metrics_unstructured,
    quality_report,
    sidecar_path,
    write_json,
    write_mesh_alone,
    write_mesh_with_quality,
)
from meshgen.quality.deviation import block_set_deviation
from meshgen.quality.merged import merged_reports
from meshgen.run.publish import publishing
from meshgen.run.trust import recorded_spec

__all__ = ["BLOCK_METHODS", "Mesh", "block_spec", "checkpoint_block_spec", "mesh_block_set", "run_metadata"]


@dataclass
class Mesh:
    """A mesh: node array ``X`` (n1+1, n2+1[, n3+1], dim), float64 (None when the mesh was streamed
    block by block into ``output`` and never held in memory), the geometry and method that made
    it, the cell counts and clustering asked for, the method's ``info``, the meshing time in
    seconds (the median of ``timings``, one per repeat), the quality report when one was
    measured, the file written (or None), its boundary patches, and the lines said about the run
    (the model used, a fall-back to another method). A block set's mesh: ``X`` None, ``blocks``
    one node array per block (interface nodes identical), ``geometry`` the ``meshgen.geometry.blocks.BlockSet``;
    its quality is that of the merged unstructured mesh."""

    X: np.ndarray | None
    geometry: object  # meshgen.geometry.plugins.Geometry
    method: str
    dims: tuple[int, ...]
    cluster: tuple[str, ...] = ()
    info: dict = field(default_factory=dict)
    seconds: float = 0.0
    quality_report: dict | None = None
    output: Path | None = None
    patches: tuple[Patch, ...] = ()
    timings: tuple[float, ...] = ()
    notes: tuple[str, ...] = ()
    blocks: list[np.ndarray] | None = None

    @property
    def quality(self) -> dict[str, np.ndarray]:
        """The seven per-cell metrics, each (n1*n2[*n3],) in C order of the cells (degrees for
        angles and non-orthogonality): ``meshgen.quality.cell_metrics``; of a block set, in the
        merged mesh's cell order (block after block)."""
        if self.blocks is not None:
            return cell_metrics_unstructured(*merged_mesh(self.geometry, self.blocks)[:2])
        return cell_metrics(self.X)

    def report(self) -> dict:
        """The quality report (``meshgen evaluate --json``'s schema), boundary deviation included:
        the one measured when the mesh was made, else measured now."""
        if self.quality_report is None:
            self.quality_report = self._measure()
        return self.quality_report

    def metadata(self) -> dict:
        """What the written files record of how the mesh was made. A block set is recorded as such
        (``block_set``, ``block_dims``, the cells of each block), not as one geometry's grid."""
        recorded = {
            **run_metadata(self.method, self.geometry, self.dims, self.cluster),
            **({"meshing_seconds": self.seconds} if self.X is not None or self.blocks is not None else {}),
            **({"method_info": self.info} if self.info else {}),
            **({"patches": as_records(self.patches)} if self.patches else {}),
        }
        if self.blocks is not None:
            recorded["block_set"] = recorded.pop("geometry")
            source = self.geometry.geometries[0].source
            if is_airfoil_file(source) or is_topology_file(source):  # the file, not a name no lookup finds
                recorded["block_set"] = source
            recorded["block_dims"] = recorded.pop("dims")
            recorded["blocks"] = {
                name: [len(t) - 1 for t in coords] for name, coords in zip(self.geometry.names, self.geometry.coords)
            }
        return recorded

    def write(self, path, format_name: str | None = None, quality: bool = True) -> dict | None:
        """Write the mesh (format from the extension, or ``format_name``) atomically; with
        ``quality`` its per-cell metrics as cell data (structured meshes) and
        ``<path>.quality.json``, the quality report returned; without, the mesh alone (and a
        previous sidecar under that name removed) and None."""
        if self.blocks is None:
            # The patches the mesh was named with, else its geometry's, whether or not the quality
            # is written (without, the file carried one patch per cube face named after it).
            options = {"patches": list(self.patches) or geometry_patches(self.geometry)}
            if format_name:
                options["format"] = format_name
            if quality:
                return write_mesh_with_quality(path, self.X, self.geometry, self.metadata(), **options)
            write_mesh_alone(path, self.X, self.metadata(), **options)
            return None
        report = self._measure() if quality else None
        with publishing(path, FormatError) as publication:  # the mesh and its sidecar take their names together
            written = write_blocks(path, self.geometry, self.blocks, self.metadata(), format_name)
            if report is None:
                publication.remove(sidecar_path(written))
            else:
                write_json(sidecar_path(written), {"mesh": os.path.basename(written), **self.metadata(), **report})
        if report is not None:
            self.quality_report = {"file": str(written), **report}
        return self.quality_report if quality else None

    def _measure(self) -> dict:
        if self.blocks is None:
            return quality_report(self.X, self.geometry)
        # Measured merged, interfaces as interior faces, with the block set's boundary deviation.
        points, cells, owner = merged_mesh(self.geometry, self.blocks)
        shapes = [tuple(n - 1 for n in X.shape[:-1]) for X in self.blocks]
        deviation = block_set_deviation(self.geometry, self.blocks)
        return merged_reports(points, cells, owner, self.geometry.names, shapes, self.geometry, deviation)[0]


def run_metadata(method: str, geometry, dims, cluster=()) -> dict:
    """What every mesh file records of the run that made it: meshgen's version, the method, the
    geometry with its parameters, the cell counts and the clustering asked for."""
    return {
        "meshgen_version": __version__,
        "method": method,
        "geometry": geometry.name,
        "params": geometry.values,
        "dims": list(dims),
        **({"cluster": list(cluster)} if cluster else {}),
    }


# ---------------------------------------------------------------------------------------------
# the mesh of a block set


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


def checkpoint_block_spec(checkpoint) -> str | None:
    """The block-set spec a checkpoint (a path or a loaded ``TrainedModel``) was trained on, else
    None (a single-shape model, or a file the single-block path will report on)."""
    from meshgen.neural.checkpoint import load_checkpoint  # brings torch: only when a checkpoint is given

    try:
        loaded = checkpoint.checkpoint if hasattr(checkpoint, "checkpoint") else load_checkpoint(checkpoint)
    except MeshgenError:
        return None
    entry = loaded.get("geometry", {})
    if "blocks" not in entry:
        return None
    # a name, or a file the user named in this process (a checkpoint never makes meshgen read or run one)
    return recorded_spec(str(entry["spec"]), f"checkpoint {getattr(checkpoint, 'path', checkpoint)}")


def _block_model(request, block_set_name: str, params: dict, fallback: bool, warn=None):
    """The block model to mesh with (``meshgen.neural.models.find_model``: the checkpoint given, else
    the newest run of the geometry), or None with ``fallback`` when there is none."""
    checkpoint = request.checkpoint
    try:
        if isinstance(checkpoint, TrainedModel):
            model = checkpoint
        elif checkpoint is not None and _is_wall_family(checkpoint):  # the member's parameters are checked when meshing
            model = load_model(checkpoint)
            if model.geometry_entry["name"] != block_set_name:
                raise MeshgenError(
                    f"checkpoint {checkpoint} was trained on '{model.geometry_entry['name']}', not on '{block_set_name}'"
                )
            family, defaults = model.checkpoint["model"]["family"], load_geometry(block_set_name, check=False).defaults
            check_member_values(family, member_values(family, defaults, params), f" of {display_path(Path(checkpoint))}")
        else:
            model = find_model(
                checkpoint, geometry_name=block_set_name, params=params, default_geometry=block_set_name, warn=warn
            )
    except MeshgenError:
        if fallback and checkpoint is None:
            return None
        family = _bundled_family(block_set_name, params) if checkpoint is None else None
        if family is None:
            raise
        return family
    if not is_block_model(model.checkpoint["model"]):
        raise ParameterError("checkpoint", f"{{name}} {model.path} holds a one-block model, not one of '{block_set_name}'")
    return model


def _bundled_family(name: str, params: dict):
    """The bundled family of sections round a wall of geometry ``name`` (``meshgen/_models/families/NAME``)
    when ``params`` (the --param values over the geometry's defaults) pick one of its members: what
    ``--method neural`` meshes with when no run of the geometry has those parameters. MeshgenError
    naming the ranges when they pick a section of the family outside them; None when there is no
    such family or the section is not one of it (another ``naca``, ``sharp``, ...)."""
    path = MODELS_DIR / "families" / name / "checkpoint.pt"
    if not path.is_file():
        return None
    model = load_model(path, source="bundled")
    family = model.checkpoint["model"]["family"]
    values = member_values(family, load_geometry(name, check=False).defaults, params)
    try:  # the family's fixed parameters, the varied ones at the family's base
        check_member_values(family, {**values, **{n: float(family["base"][n]) for n in family["ranges"]}})
    except MeshgenError:
        return None
    try:
        check_member_values(family, values, " of the bundled family")
    except MeshgenError as exc:
        wider = {n: (min(lo, float(values[n])), max(hi, float(values[n]))) for n, (lo, hi) in family["ranges"].items()}
        varied = " ".join(f"--vary {n}={lo:g}:{hi:g}" for n, (lo, hi) in wider.items())
        raise MeshgenError(
            f"{exc}; train a family that holds it (`meshgen train -g {name} {varied}`) or pick --method elliptic"
        ) from None
    return model


def _is_wall_family(path) -> bool:
    """Whether the checkpoint at ``path`` holds a family of sections round a wall (``meshgen.neural.wall_family``)."""
    return is_wall_family(read_plain_checkpoint(path).get("model"))


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
                module = plugin_module(spec, request.dims)[0]
                elliptic = getattr(module, "mesh_elliptic", None) or elliptic_blocks
                options = getattr(module, "elliptic_options", {})  # e.g. a swept CAD cap's: slide_section
                if options.get("keep_tfi"):  # the plugin's notes say why (a swept cap's sharp trailing edge)
                    Xs, info = tfi_blocks(block_set), {"solver": "none: the TFI mesh is kept", "converged": True}
                else:
                    Xs, info = elliptic(block_set, tol=request.tol, max_iter=request.max_iter, progress=callback, **options)
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
    """The neural mesh of the block set (``meshgen.neural.inference.neural_blocks``) and its
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
            if "family" in model.checkpoint["model"]:  # a family of sections: the member asked for
                params = member_values(model.checkpoint["model"]["family"], load_geometry(spec, check=False).defaults, params)
            else:
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
    notes.extend(getattr(plugin_module(spec, request.dims)[0], "notes", lambda _: [])(block_set))
    for line in notes:
        say(line)
    return method, block_set, output, notes, model

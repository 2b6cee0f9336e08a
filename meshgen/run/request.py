"""One path from a request to a mesh: ``MeshRequest`` (plain data: what to mesh, how, and where
to write it) and ``carry_out(request) -> Mesh``, which ``meshgen mesh``, every method row of
``meshgen compare`` and ``meshgen.mesh()`` all call (design notes §14).

``carry_out`` loads and checks the geometry, resolves the method (``auto``: a trained model of the
geometry, else ``elliptic`` with a note saying so), decides between the in-memory and the chunked
path, names the boundary patches, records the run (``meshgen.run.meshing.run_metadata``) and writes
the file with its quality sidecar. A geometry that declares blocks goes to
``meshgen.run.meshing.mesh_block_set`` (the Mesh's ``blocks`` hold one node array per block). Bad input raises MeshgenError (ParameterError naming the
parameter) before any work is done or any file is written.
"""

from __future__ import annotations

import contextlib
import statistics
import time
import warnings
from dataclasses import dataclass
from pathlib import Path

from meshgen.errors import MeshgenError, MeshgenWarning, ParameterError
from meshgen.formats import FORMATS, check_output_path, check_patches, format_for, streaming_writer
from meshgen.geometry.layout import trained_layout, with_layout
from meshgen.geometry.patches import geometry_patches, parse_patch_options
from meshgen.geometry.plugins import Geometry, bind, check_boundary, load_geometry, load_recorded_geometry
from meshgen.methods.clustering import node_coordinates
from meshgen.methods.registry import get_method, make_mesh
from meshgen.methods.tfi import check_axes
from meshgen.neural.device import inference_device
from meshgen.neural.models import TrainedModel, find_model
from meshgen.quality import quality_report, write_mesh_alone, write_mesh_with_quality
from meshgen.quality.worker import quality_worker
from meshgen.run.chunked import (
    CHUNKED_METHODS,
    MESH_BYTES_PER_BLOCK_NODE,
    neural_array,
    run_fraction,
    single_threaded_torch,
    tfi_array,
    write_chunked_mesh,
)
from meshgen.run.limits import check_mesh_memory
from meshgen.run.meshing import Mesh, block_spec, checkpoint_block_spec, mesh_block_set
from meshgen.run.resources import check_block_nodes, check_free_space, needs_chunking
from meshgen.run.scheduler import connect, scheduler_address

__all__ = ["DEFAULT_GEOMETRY", "FALLBACK_METHOD", "MeshRequest", "carry_out", "load_checked_geometry", "mesh"]

DEFAULT_GEOMETRY = "semicylinder"
FALLBACK_METHOD = "elliptic"  # what ``auto`` meshes with when no trained model fits


@dataclass(frozen=True)
class MeshRequest:
    """Everything a mesh is made from, as plain data.

    ``dims``: cells per axis (two numbers for a 2D geometry, three for 3D). ``geometry``: a name, a
    plugin file's path or a loaded Geometry; None: the checkpoint's geometry, else semicylinder.
    ``params``: geometry parameters over its defaults. ``method``: ``auto`` (the neural map of
    ``checkpoint``, else the newest ./runs/*/checkpoint.pt trained on the geometry, else the model
    bundled for it, else ``elliptic``), or a method of ``meshgen.methods.registry``. Method options (None:
    the method's default; an option the method does not take is an error): ``tol``, ``max_iter``,
    ``orthogonal`` (faces), ``boundary_layout`` (elliptic, tfi); ``correct``, ``polish``, ``device``,
    ``checkpoint`` (a path or a loaded ``TrainedModel``) for the neural methods. ``clusters``: wall
    clustering specs such as ``"zeta:both:1.1"``; ``first_cell``: first-cell heights on patches of
    a block set (``"0.001"`` every wall patch, ``"cylinder=0.0005"``; ``meshgen.geometry.grading``). ``output``: the file (or OpenFOAM case) to write,
    None to keep the mesh in memory only; ``format``: its format instead of the extension's;
    ``patches``: ``FACE=NAME[:TYPE]`` overrides of the geometry's patches; ``ascii``: OpenFOAM
    ASCII. ``chunked``: True (blocks on Dask streamed into the file), False (in memory), None
    (chunked when in memory would need more than half the available memory); ``scheduler``: a
    dask.distributed address; ``block_nodes``: nodes per block of the chunked path (default from the
    available memory; refused when the blocks in flight would not fit). ``quality``: measure the mesh (report, sidecar, per-cell arrays).
    ``timing_repeats``: mesh this many times, the time being the median.
    """

    dims: tuple[int, ...]
    geometry: str | Geometry | None = None
    params: dict | None = None
    method: str = "auto"
    checkpoint: object = None  # path, or meshgen.neural.inference.TrainedModel
    tol: float | None = None
    max_iter: int | None = None
    correct: bool | None = None
    polish: bool | None = None
    device: str | None = None
    boundary_layout: str | None = None
    orthogonal: tuple[str, ...] = ()
    clusters: tuple[str, ...] = ()
    first_cell: tuple[str, ...] = ()
    output: str | Path | None = None
    format: str | None = None
    patches: tuple[str, ...] = ()
    ascii: bool = False
    chunked: bool | None = None
    scheduler: str | None = None
    block_nodes: int | None = None
    quality: bool = True
    timing_repeats: int = 1


@dataclass
class _Plan:
    """What the checks settled: the method, its geometry and model, where and how to write."""

    method: str
    geometry: Geometry
    model: object
    output: Path | None
    output_format: object
    patches: list
    coords: list
    chunked: bool
    address: str | None
    notes: list


def carry_out(request: MeshRequest, *, say=None, warn=None, progress=None) -> Mesh:
    """Make the mesh ``request`` asks for and, with ``request.output``, write it. Returns the Mesh
    (``notes``: the lines said about the run). ``say(line)`` hears those lines as they happen (the
    model used, a fall-back), ``warn(text)`` the warnings (unreadable run checkpoints skipped, a re-meshed OpenFOAM case's
    kept fields);
    ``progress(label, iterative)``: a context manager yielding a callback ``progress(done,
    **figures)`` or None (``iterative``: the method reports its progress)."""
    say = say or (lambda line: None)
    progress = progress or (lambda label, iterative: contextlib.nullcontext(None))
    spec = block_spec(request.geometry)
    if spec is None and request.geometry is None and request.checkpoint is not None:
        spec = checkpoint_block_spec(request.checkpoint)  # a block set's model names its geometry
    if spec is not None:  # a geometry of several blocks: meshgen.run.meshing.mesh_block_set
        return mesh_block_set(request, spec, say, progress)
    plan = _plan(request, say, warn)
    if plan.chunked:
        return _mesh_in_blocks(request, plan, progress)
    with _warnings_to(warn):
        return _mesh_in_memory(request, plan, progress)


def mesh(
    geometry, dims, method: str = "auto", *, params: dict | None = None, cluster=(), first_cell=(), progress=None, **options
) -> Mesh:
    """Mesh ``geometry`` (a name, a plugin file's path, or a loaded Geometry) with ``dims`` cells
    per axis (two numbers for a 2D geometry, three for 3D) by ``method``, as ``meshgen mesh``
    does: ``auto`` (the default) meshes with the model of ``model=`` (a checkpoint path), else the
    newest ./runs/*/checkpoint.pt trained on the geometry, else the model bundled for it, else with
    ``elliptic`` (the returned Mesh's ``notes`` say so); or ``tfi``, ``elliptic``, ``neural``
    (``meshgen.methods.registry``). ``params``: geometry parameters over its defaults; ``cluster``: wall
    clustering specs such as ``"zeta:both:1.1"`` (a block set: ``"wall:1.1"``, PATCH:RATIO); ``first_cell``: first-cell heights on a block set's
    patches (``"0.001"``: every wall patch; ``"cylinder=0.0005"``); ``progress``: a callback ``progress(done,
    **figures)`` for methods that report it; ``options``: the method's own (``tol``,
    ``max_iter``, ``orthogonal``, ``boundary_layout``; ``model``, ``correct``, ``polish``, ``device`` for the
    neural map). Nothing is written (``Mesh.write``). Raises MeshgenError (ParameterError naming
    the parameter) for bad input."""
    fields = {"checkpoint": options.pop("model", None)}
    for name in ("tol", "max_iter", "correct", "polish", "device", "boundary_layout", "orthogonal"):
        if name in options:
            fields[name] = options.pop(name)
    if options:
        known = "model, tol, max_iter, correct, polish, device, boundary_layout, orthogonal"
        raise ParameterError(sorted(options)[0], f"{{name}} is no option of mesh() (options: {known})")
    if isinstance(fields.get("orthogonal"), str):
        fields["orthogonal"] = (fields["orthogonal"],)
    if isinstance(first_cell, (str, int, float)):
        first_cell = (str(first_cell),)
    request = MeshRequest(
        tuple(dims),
        geometry,
        params,
        method,
        clusters=tuple(cluster),
        first_cell=tuple(map(str, first_cell)),
        quality=False,
        **fields,
    )

    @contextlib.contextmanager
    def callback(label, iterative):
        yield progress

    return carry_out(request, progress=callback)


def load_checked_geometry(spec, params: dict | None, dims=None) -> Geometry:
    """The geometry ``spec`` (a name, a path or a Geometry) with ``params`` bound and its boundary
    checked; with ``dims``, checked to have one cell count per axis."""
    if isinstance(spec, Geometry):
        geometry = spec
        if params:
            geometry = bind(spec, params)
            check_boundary(geometry)
    else:
        geometry = load_geometry(spec, dict(params or {}))
    if dims is not None and len(dims) != geometry.dim:
        raise ParameterError(
            "dims", f"geometry '{geometry.name}' is {geometry.dim}D: {{name}} needs {geometry.dim} numbers, got {len(dims)}"
        )
    return geometry


# ---------------------------------------------------------------------------------------------
# the checks: everything that can fail does so before any work


def _plan(request: MeshRequest, say, warn) -> _Plan:
    dims = tuple(int(n) for n in request.dims)
    if not dims or any(n < 1 for n in dims):
        raise ParameterError("dims", f"{{name}} must be positive cell counts, got {' '.join(map(str, dims))}")
    output = output_format = None
    if request.output is not None:
        output_format = format_for(request.output, request.format)
        output = check_output_path(request.output, output_format.name, len(dims))
        if request.patches and not output_format.patches:
            carriers = ", ".join(f.name for f in FORMATS if f.patches)
            raise ParameterError(
                "patch", f"{{name}}: {output_format.name} files carry no boundary patches (formats that do: {carriers})"
            )
        if request.ascii and not output_format.folder:
            raise ParameterError("ascii", f"{{name}} applies to the openfoam format, not to {output_format.name}")
    if request.first_cell:
        raise ParameterError(
            "first_cell",
            "{name} grades the patches of multi-block geometries; one block: --cluster AXIS:SIDE:h=HEIGHT (parametric)",
        )
    patch_overrides = parse_patch_options(request.patches, len(dims))
    coords = node_coordinates(dims, tuple(request.clusters))  # a malformed cluster fails here
    address = scheduler_address(request.scheduler) if output is not None else None
    method, geometry, model, notes = _method_and_geometry(request, dims, say, warn)
    check_axes(geometry, dims)

    node_count = 1
    for n in dims:
        node_count *= n + 1
    chunked = request.chunked
    if output is None:
        if chunked or request.scheduler:
            raise ParameterError("chunked", "{name} streams the mesh into a file: give an output")
        chunked = False
    elif chunked is None:
        chunked = address is not None or needs_chunking(node_count)
    if chunked:
        if method not in CHUNKED_METHODS:
            raise MeshgenError(
                f"method '{method}' cannot be computed block by block (a mesh of {node_count} nodes needs it); "
                f"methods that can: {', '.join(CHUNKED_METHODS)}"
            )
        if request.polish:
            raise ParameterError("polish", "{name} solves the whole mesh at once: it does not apply to a chunked mesh")
        streaming_writer(output, output_format.name, [n + 1 for n in dims])  # a format that cannot stream fails before any work
        check_block_nodes(request.block_nodes, node_count, MESH_BYTES_PER_BLOCK_NODE)
    elif address is not None:
        raise ParameterError("scheduler", "{name} runs the chunked path; leave out --in-memory")
    elif request.block_nodes is not None:
        raise ParameterError("block_nodes", "{name} sets the blocks of the chunked path; add --chunked")
    check_mesh_memory(dims, chunked)  # memory first: its message names the chunked path
    patches = []
    if output is not None:
        check_free_space(output, node_count * len(dims) * 8)
        patches = check_patches(geometry_patches(geometry, patch_overrides), geometry.dim, output, output_format.name)
    return _Plan(method, geometry, model, output, output_format, patches, coords, chunked, address, notes)


def _method_and_geometry(request: MeshRequest, dims, say, warn):
    """(method, geometry, model or None, notes): ``auto`` resolved, the neural model found."""
    method = request.method
    get_method("neural" if method == "auto" else method)  # an unknown name fails before anything is loaded
    neural = method == "auto" or get_method(method).neural
    notes = []
    if not neural:
        if request.checkpoint is not None:
            raise ParameterError("checkpoint", f"{{name}} applies to the neural method, not to '{method}'")
        return method, load_checked_geometry(request.geometry or DEFAULT_GEOMETRY, request.params, dims), None, notes
    found = _neural_model(request, dims, warn, fallback=method == "auto")
    if found[0] is None:
        geometry = found[1]
        spec = request.geometry if isinstance(request.geometry, str) else geometry.name
        notes.append(
            f"note: no trained model for '{geometry.name}': meshing with {FALLBACK_METHOD} (meshgen train -g {spec} trains one)"
        )
        say(notes[-1])
        return FALLBACK_METHOD, geometry, None, notes
    model, geometry = found
    notes.append(f"model: {model.describe()}")
    say(notes[-1])
    return ("neural" if method == "auto" else method), geometry, model, notes


def _neural_model(request: MeshRequest, dims, warn, fallback: bool):
    """The model to mesh with (``meshgen.neural.models.find_model``) and the geometry it was
    trained on, with its parameters: the one asked for when the model was trained on it, else the
    model's. With ``fallback`` and no checkpoint, (None, geometry) when no trained model fits."""
    spec, checkpoint = request.geometry, request.checkpoint
    given_params = dict(request.params or {})
    if isinstance(checkpoint, TrainedModel):  # a model the caller loaded (meshgen compare)
        return checkpoint, load_checked_geometry(spec or DEFAULT_GEOMETRY, request.params, dims)
    if checkpoint is not None:
        from meshgen.neural.family import load_family_member  # torch

        # A family checkpoint: the parameters pick the member (inside the trained ranges).
        named = None if spec is None else spec.name if isinstance(spec, Geometry) else load_geometry(spec).name
        polished = False if request.correct is False else request.polish  # the mesh the user gets (None: the model's default)
        member = load_family_member(checkpoint, given_params, named, warn=warn, polished=polished)
        if member is not None:
            return _check_model_dims(*member, dims)
    chosen = None
    if checkpoint is None:
        # Without a checkpoint the model is one of the geometry asked for (default semicylinder),
        # never "the newest run of any geometry". The geometry must exist and fit dims first.
        chosen = load_checked_geometry(spec or DEFAULT_GEOMETRY, request.params, dims)
    elif spec is not None:
        chosen = load_checked_geometry(spec, request.params)
    try:
        model = find_model(
            checkpoint,
            geometry_name=chosen.name if chosen is not None else None,
            params=given_params,
            default_geometry=spec if isinstance(spec, str) else DEFAULT_GEOMETRY,
            warn=warn,
        )
    except MeshgenError:
        if fallback and checkpoint is None:
            return None, chosen
        raise
    entry = model.geometry_entry
    if chosen is not None and chosen.name == entry["name"] and _same_spec(spec, entry["spec"]):
        geometry = bind(chosen, dict(entry["params"]))
        if geometry.values != chosen.values:
            check_boundary(geometry)
    else:
        geometry = load_recorded_geometry(entry["spec"], dict(entry["params"]), where=f"checkpoint {model.path}")
    return _check_model_dims(model, geometry, dims)


def _same_spec(spec, recorded: str) -> bool:
    """Whether geometry ``spec`` (name, path or Geometry) is the one a checkpoint records."""
    if spec is None or isinstance(spec, Geometry):
        return True  # the names agree; a loaded geometry is the one asked for
    if spec == recorded:
        return True
    given, other = Path(spec), Path(recorded)
    return given.is_file() and other.is_file() and given.resolve() == other.resolve()


def _check_model_dims(model, geometry, dims):
    if len(dims) != model.dim:
        raise ParameterError(
            "dims", f"model {model.path} ({geometry.name}) is {model.dim}D: {{name}} needs {model.dim} numbers, got {len(dims)}"
        )
    return model, geometry


# ---------------------------------------------------------------------------------------------
# the two paths


@contextlib.contextmanager
def _warnings_to(warn):
    """Pass the writers' ``MeshgenWarning`` lines (a re-meshed case kept a user's field) to
    ``warn(text)``; without ``warn`` (Python) they stay Python warnings. Other warnings pass through."""
    if warn is None:
        yield
        return
    caught = []
    try:
        with warnings.catch_warnings(record=True) as recorded:
            warnings.simplefilter("always", MeshgenWarning)
            try:
                yield
            finally:
                caught = list(recorded)
    finally:  # outside the recording: a warning passed on here is shown, not recorded again
        for item in caught:
            if issubclass(item.category, MeshgenWarning):
                warn(str(item.message))
            else:
                warnings.warn_explicit(item.message, item.category, item.filename, item.lineno)


def _mesh_in_memory(request: MeshRequest, plan: _Plan, progress) -> Mesh:
    options = {
        "tol": request.tol,
        "max_iter": request.max_iter,
        "correct": request.correct,
        "polish": request.polish,
        "device": request.device,
        "boundary_layout": request.boundary_layout,
        "orthogonal": tuple(request.orthogonal or ()) or None,
        "model": plan.model,
    }
    if plan.method == "elliptic" and request.device not in (None, "cpu"):  # the GPU multigrid; auto: cuda if torch sees one
        options["device"] = inference_device(request.device)
    iterative = "progress" in get_method(plan.method).options
    # with a quality report, numba loads in a forked worker while the mesh is made (design notes §21)
    wanted = plan.output is not None and request.quality
    node_shape = tuple(int(n) + 1 for n in request.dims)
    with quality_worker(node_shape, plan.geometry) if wanted else contextlib.nullcontext() as worker:
        timings = []
        with progress(f"{plan.method} mesh", iterative) as callback:
            if callback is not None and iterative:
                options["progress"] = callback
            for _ in range(max(1, int(request.timing_repeats))):
                start = time.perf_counter()
                X, info = make_mesh(plan.method, plan.geometry, plan.coords, **options)
                timings.append(time.perf_counter() - start)
        carries_patches = plan.output is not None and plan.output_format.patches
        mesh = Mesh(
            X,
            plan.geometry,
            plan.method,
            tuple(request.dims),
            tuple(request.clusters),
            info,
            statistics.median(timings),
            output=plan.output,
            patches=tuple(plan.patches) if carries_patches else (),
            timings=tuple(timings),
            notes=tuple(plan.notes),
        )
        if plan.output is None:
            mesh.quality_report = quality_report(X, plan.geometry) if request.quality else None
            return mesh
        write_options = {"binary": not request.ascii} if plan.output_format.folder else {}
        write_options.update(patches=plan.patches, format=plan.output_format.name)
        if request.quality:
            # The mesh with its per-cell quality arrays, and <output>.quality.json beside it.
            mesh.quality_report = write_mesh_with_quality(
                plan.output, X, plan.geometry, mesh.metadata(), worker=worker, **write_options
            )
        else:
            write_mesh_alone(plan.output, X, mesh.metadata(), **write_options)  # and a previous mesh's sidecar is removed
        return mesh


def _mesh_in_blocks(request: MeshRequest, plan: _Plan, progress) -> Mesh:
    """Compute the mesh block by block on Dask and stream it into the file (``meshgen.run.chunked``)."""
    client = connect(plan.address)  # an unreachable scheduler fails fast
    try:
        start = time.perf_counter()
        info = {}
        if plan.method == "tfi":
            X = tfi_array(with_layout(plan.geometry, request.boundary_layout or "fixed"), plan.coords, request.block_nodes)
        else:
            model = plan.model
            trained_on = with_layout(plan.geometry, trained_layout(model.checkpoint))  # the boundary it was trained on
            X, correction = neural_array(
                model.checkpoint["model"],
                trained_on,
                plan.coords,
                correct_boundary=request.correct is not False,
                block_nodes=request.block_nodes,
                # local threads only: a cluster's workers choose nothing (cpu unless asked for cuda)
                device=inference_device(request.device or ("auto" if client is None else "cpu")),
            )
            info = {"model": model.metadata(), "correction": correction, "polish": {"polished": False, "reason": "chunked"}}
        info["chunked"] = {
            "blocks": int(X.npartitions),
            "block_shape": [int(c[0]) for c in X.chunks[:-1]],
            "scheduler": client.scheduler.address if client is not None else "local threads",
        }
        mesh = Mesh(
            None,
            plan.geometry,
            plan.method,
            tuple(request.dims),
            tuple(request.clusters),
            info,
            output=plan.output,
            patches=tuple(plan.patches),
            notes=tuple(plan.notes),
        )
        with progress(f"{plan.method} mesh", True) as bar:

            def blocks_done(done, total, phase):
                if bar is not None:
                    bar(run_fraction(done, total, phase, request.quality), phase=phase, blocks=f"{done}/{total}")

            with single_threaded_torch(plan.method == "neural" and client is None):
                mesh.quality_report, timings = write_chunked_mesh(
                    plan.output,
                    X,
                    plan.geometry,
                    mesh.metadata(),
                    client=client,
                    progress=blocks_done,
                    evaluate=request.quality,
                    patches=plan.patches,
                    format=plan.output_format.name,
                    block_nodes=request.block_nodes,
                    **({"binary": not request.ascii} if plan.output_format.folder else {}),
                )
    finally:
        if client is not None:
            client.close()
    info["chunked"].update(timings)
    mesh.seconds = time.perf_counter() - start
    mesh.timings = (mesh.seconds,)
    return mesh

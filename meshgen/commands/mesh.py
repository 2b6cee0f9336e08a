"""``meshgen mesh``: build a mesh with a method and write it."""

from __future__ import annotations

from pathlib import Path

import click

from meshgen.commands._options import DimsCommand, dims_option, geometry_options, load_selected_geometry
from meshgen.commands._text import echo

METHOD_HELP = (
    "Meshing method: auto, neural, tfi, elliptic. auto: the neural map of --checkpoint, else of the newest "
    "./runs/*/checkpoint.pt trained on the --geometry (default semicylinder), else of the model bundled for it."
)


@click.command("mesh", cls=DimsCommand)
@click.option("--method", "-m", default="auto", show_default=True, help=METHOD_HELP)
@geometry_options()
@dims_option()
@click.option(
    "-o",
    "--output",
    required=True,
    type=click.Path(),
    help="Output file; the extension picks the format (.vtu .vts .vtk .xdmf .cgns .su2 .msh .xyz .fmt), or a case folder with --format openfoam.",
)
@click.option(
    "--format",
    "format_name",
    default=None,
    metavar="NAME",
    help="Output format instead of the extension's: openfoam writes the case folder -o CASE (or CASE/constant/polyMesh).",
)
@click.option(
    "--patch",
    "patch_items",
    multiple=True,
    metavar="FACE=NAME[:TYPE]",
    help="Name a boundary face (xi0 xi1 eta0 eta1 zeta0 zeta1) NAME, of TYPE wall, patch, symmetry or empty (repeatable; "
    "faces may share a name). Default: the geometry's patches (meshgen geometries).",
)
@click.option("--ascii", "ascii_files", is_flag=True, help="openfoam: write the polyMesh as ASCII [default: binary].")
@click.option(
    "--checkpoint",
    type=click.Path(dir_okay=False),
    default=None,
    help="neural: a checkpoint from meshgen train (it sets the geometry and its parameters).",
)
@click.option(
    "--correct/--no-correct",
    "--snap/--no-snap",
    "correct",
    default=None,
    help="neural: add TFI of the network's boundary error, X = N + TFI[g - N], so the boundary is exact and the "
    "interior moves smoothly (also block by block with --chunked); --no-correct keeps the raw network [default: --correct; --snap/--no-snap: old names].",
)
@click.option(
    "--device",
    type=click.Choice(["auto", "cpu", "cuda"]),
    default=None,
    help="neural: where the network is evaluated; auto picks cuda when available [default: auto].",
)
@click.option(
    "--tol",
    type=float,
    default=None,
    help="elliptic: stop when the largest node update, relative to the characteristic length, is below this [default: 1e-6].",
)
@click.option(
    "--max-iter", type=click.IntRange(1), default=None, help="elliptic: most iterations (multigrid cycles) [default: 100]."
)
@click.option(
    "--cluster",
    "clusters",
    multiple=True,
    metavar="AXIS:SIDE:RATIO",
    help="Cluster nodes towards a wall (repeatable): e.g. zeta:both:1.1 (growth ratio) or eta:0:h=0.002 (first-cell height, parametric).",
)
@click.option(
    "--boundary-layout",
    type=click.Choice(["smoothed", "fixed"]),
    default=None,
    help="tfi, elliptic: boundary nodes by arc length on the edges and the surface's own Winslow grid on each face "
    "(smoothed), or the geometry's own map, i.e. each face the Coons layout of its edges (fixed) "
    "[default: smoothed for elliptic, fixed for tfi; a neural model meshes with the layout it was trained on].",
)
@click.option(
    "--orthogonal",
    "orthogonal",
    multiple=True,
    metavar="FACE",
    help="elliptic: the first cell layer meets this wall (xi0 xi1 eta0 eta1 zeta0 zeta1) at right angles; repeatable. "
    "With --cluster for boundary layers.",
)
@click.option(
    "--chunked/--in-memory",
    default=None,
    help="Compute the mesh in blocks on Dask and stream it into the file (tfi, neural; .cgns), for meshes "
    "larger than memory [default: chunked when the in-memory path would need more than half of the available memory].",
)
@click.option(
    "--scheduler",
    metavar="ADDRESS",
    default=None,
    help="Run the blocks on this dask.distributed scheduler (implies --chunked) [default: $DASK_SCHEDULER_ADDRESS, "
    "else Dask's local threads].",
)
@click.option(
    "--quality/--no-quality",
    default=True,
    show_default=True,
    help="Measure the mesh: per-cell quality arrays in the file (in-memory path) and <output>.quality.json. "
    "--no-quality writes the mesh alone (meshgen evaluate can measure it later).",
)
@click.option("--quiet", "-q", is_flag=True, help="Print only errors and warnings.")
def mesh(
    method,
    geometry,
    params,
    dims,
    output,
    format_name,
    patch_items,
    ascii_files,
    checkpoint,
    correct,
    device,
    tol,
    max_iter,
    clusters,
    boundary_layout,
    orthogonal,
    chunked,
    scheduler,
    quality,
    quiet,
):
    """Make a structured mesh of a geometry and write it.

    With no --method and no --checkpoint, a trained model of the --geometry (default: semicylinder)
    meshes: the newest run under ./runs/ trained on it, else the model bundled with meshgen for it;
    one line says which model was used. --dims counts cells; nodes are dims + 1. The write is
    atomic: an interrupted run never leaves a partial file under the output name.

    Boundary patches (named faces) go into .cgns, .vts, .su2, .msh and OpenFOAM cases.

    Meshes larger than memory (e.g. --dims 1000 1000 1000 -o big.cgns) are computed block by block
    and streamed into a .cgns file with bounded memory; their quality report is computed block-wise
    from the written file, and no per-cell quality arrays are attached (see README).
    """
    import sys
    import time

    from meshgen.blocks import is_multiblock
    from meshgen.chunked import CHUNKED_METHODS, check_free_space, needs_chunking
    from meshgen.clustering import node_coordinates
    from meshgen.commands._progress import progress_display
    from meshgen.errors import MeshgenError
    from meshgen.formats import check_output_path, check_patches, format_for, streaming_writer, write_mesh
    from meshgen.meshing import Mesh
    from meshgen.methods import get_method, make_mesh
    from meshgen.patches import geometry_patches, parse_patch_options
    from meshgen.quality import write_mesh_with_quality
    from meshgen.scheduler import connect, scheduler_address

    if checkpoint is None and is_multiblock(geometry):  # a block set: meshgen.commands._blocks does the run
        from meshgen.commands._blocks import mesh_block_geometry

        unsupported = {"--patch": patch_items, "--ascii": ascii_files, "--correct": correct, "--device": device}
        unsupported.update({"--cluster": clusters, "--boundary-layout": boundary_layout, "--orthogonal": orthogonal})
        unsupported.update({"--chunked": chunked, "--scheduler": scheduler})
        mesh_block_geometry(
            method, geometry, params, dims, output, format_name,
            tol=tol, max_iter=max_iter, quality=quality, quiet=quiet, unsupported=unsupported,
        )  # fmt: skip
        return
    output_format = format_for(output, format_name)
    output = check_output_path(output, output_format.name, len(dims))
    if patch_items and not output_format.patches:
        carriers = ", ".join(f.name for f in _patch_formats())
        raise click.UsageError(f"--patch: {output_format.name} files carry no boundary patches (formats that do: {carriers})")
    if ascii_files and not output_format.folder:
        raise click.UsageError(f"--ascii applies to --format openfoam, not to {output_format.name}")
    patch_overrides = parse_patch_options(patch_items, len(dims))
    context = click.get_current_context()
    geometry_given = context.get_parameter_source("geometry") != click.core.ParameterSource.DEFAULT
    if method == "auto":
        # No fall-back to TFI: a geometry without a trained model is an error that says how to get one.
        method = "neural"
    _check_method(method)  # an unknown name fails before anything is loaded
    coords = node_coordinates(dims, clusters)  # and so does a malformed --cluster
    address = scheduler_address(scheduler)
    node_count = 1
    for n in dims:
        node_count *= n + 1
    if chunked is None:
        chunked = address is not None or needs_chunking(node_count)
    if chunked:
        if method not in CHUNKED_METHODS:
            raise MeshgenError(
                f"method '{method}' cannot be computed block by block (a mesh of {node_count} nodes needs it); "
                f"methods that can: {', '.join(CHUNKED_METHODS)}"
            )
        streaming_writer(output, output_format.name)  # a format that cannot stream fails before any work
    elif address is not None:
        raise click.UsageError("--scheduler runs the chunked path; leave out --in-memory")
    check_free_space(output, node_count * len(dims) * 8)
    options = {
        "tol": tol,
        "max_iter": max_iter,
        "correct": correct,
        "device": device,
        "boundary_layout": boundary_layout,
        "orthogonal": orthogonal or None,
    }
    model = None
    if method == "neural":
        model, geometry = _neural_model(checkpoint, geometry, params, geometry_given, dims)
        options["model"] = model
    else:
        if checkpoint is not None:
            raise click.UsageError(f"--checkpoint applies to the neural method, not to '{method}'")
        geometry = load_selected_geometry(geometry, params, dims)
    # Patches are checked (names valid for the format) before any meshing work.
    patches = check_patches(geometry_patches(geometry, patch_overrides), geometry.dim, output, output_format.name)
    if model is not None and not quiet:
        click.echo(f"model: {model.describe()}")
    if chunked:
        client = connect(address)  # an unreachable scheduler fails fast
        try:
            report, info, seconds = _mesh_in_blocks(
                method, geometry, coords, model, correct, boundary_layout, output, dims, clusters, patches, client, quality, quiet
            )
        finally:
            if client is not None:
                client.close()
        _print_result(method, geometry, dims, info, seconds, output, output_format, patches, report, quiet)
        return
    start = time.perf_counter()
    show_progress = not quiet and sys.stdout.isatty() and "progress" in get_method(method).options
    with progress_display(f"{method} mesh", show_progress) as progress:
        X, info = make_mesh(method, geometry, coords, progress=progress, **options)
    seconds = time.perf_counter() - start
    metadata = Mesh(X, geometry, method, dims, clusters, info, seconds).metadata()
    if output_format.patches:
        from meshgen.patches import as_records

        metadata["patches"] = as_records(patches)
    write_options = {"binary": not ascii_files} if output_format.folder else {}
    write_options.update(patches=patches, format=output_format.name)
    if quality:
        # The mesh with its per-cell quality arrays, and <output>.quality.json beside it.
        report = write_mesh_with_quality(output, X, geometry, metadata, **write_options)
    else:
        write_mesh(output, X, metadata=metadata, **write_options)
        report = None
    _print_result(method, geometry, dims, info, seconds, output, output_format, patches, report, quiet)


def _print_result(method, geometry, dims, info, seconds, output, output_format, patches, report, quiet):
    from meshgen.quality import summary_lines

    for line in info.get("warnings", []):
        click.echo(f"Warning: {line}", err=True)
    if quiet:
        return
    cells = 1
    for n in dims:
        cells *= n
    echo(f"{method} mesh of {geometry.name}: {' x '.join(map(str, dims))} = {cells} cells in {seconds:.2f} s")
    if "iterations" in info:
        echo(
            f"{info['iterations']} iterations, final update {info['final_update']:.2e}, "
            f"residual {info['final_residual']:.2e} ({'converged' if info['converged'] else 'not converged'})"
        )
    if "correction" in info:
        echo(_correction_line(info["correction"]))
    if "chunked" in info:
        blocks = info["chunked"]
        line = f"computed in {blocks['blocks']} blocks on {blocks['scheduler']}: written in {blocks['write_seconds']:.1f} s"
        if "quality_seconds" in blocks:
            line += f", quality (block-wise, from the file) in {blocks['quality_seconds']:.1f} s"
        echo(line)
    echo(f"wrote {output}" + (f" ({output_format.name})" if output_format.folder else ""))
    if output_format.patches:
        echo("patches: " + ", ".join(f"{p.name} ({p.type}: {' '.join(p.faces)})" for p in patches))
    for line in summary_lines(report) if report is not None else []:
        echo(line)


def _mesh_in_blocks(
    method, geometry, coords, model, correct, boundary_layout, output, dims, clusters, patches, client, quality, quiet
):
    """The chunked path of ``meshgen mesh``: (report, info, meshing seconds)."""
    import sys
    import time

    from meshgen.chunked import neural_array, single_threaded_torch, tfi_array, write_chunked_mesh
    from meshgen.commands._progress import progress_display
    from meshgen.layout import trained_layout, with_layout
    from meshgen.meshing import run_metadata
    from meshgen.patches import as_records

    start = time.perf_counter()
    info = {}
    if method == "tfi":
        X = tfi_array(with_layout(geometry, boundary_layout or "fixed"), coords)
    else:
        trained_on = with_layout(geometry, trained_layout(model.checkpoint))  # the boundary it was trained on
        X, correction = neural_array(model.checkpoint["model"], trained_on, coords, correct_boundary=correct is not False)
        info = {"model": model.metadata(), "correction": correction}
    info["chunked"] = {
        "blocks": int(X.npartitions),
        "block_shape": [int(c[0]) for c in X.chunks[:-1]],
        "scheduler": client.scheduler.address if client is not None else "local threads",
    }
    metadata = {**run_metadata(method, geometry, dims, clusters), "method_info": info, "patches": as_records(patches)}
    with progress_display(f"{method} mesh", not quiet and sys.stdout.isatty()) as bar:

        def progress(done, total, phase):
            if bar is not None:
                bar(done / total, phase=phase, blocks=f"{done}/{total}")

        with single_threaded_torch(method == "neural" and client is None):
            report, timings = write_chunked_mesh(
                output, X, geometry, metadata, client=client, progress=progress, evaluate=quality, patches=patches
            )
    info["chunked"].update(timings)
    return report, info, time.perf_counter() - start


def _check_method(name):
    """An unknown method, or a trained method (``3dmeshnet``, ``pinn`` ...: ``meshgen compare``
    trains those), is a usage error naming the choices."""
    from meshgen.errors import did_you_mean
    from meshgen.methods import METHODS

    choices = ["auto", *(method for method, entry in METHODS.items() if entry.preset is None)]
    if name in METHODS and name not in choices:
        raise click.UsageError(
            f"method '{name}' is a network trained with preset '{METHODS[name].preset}': train it with "
            f"'meshgen train --preset {METHODS[name].preset}', then mesh with --method neural --checkpoint PATH"
        )
    if name not in choices:
        raise click.UsageError(f"unknown method '{name}' (methods: {', '.join(choices)}){did_you_mean(name, choices)}")


def _neural_model(checkpoint, spec, params, geometry_given, dims):
    """The model to mesh with (``meshgen.neural.inference.find_model``) and the geometry it was
    trained on, with its parameters. The geometry is loaded and checked once: the one given on the
    command line when the model was trained on it, else the model's."""
    from meshgen.geometry import _looks_like_path, bind, check_boundary, load_geometry, parse_params
    from meshgen.neural.inference import find_model

    given_params = parse_params(params)
    if checkpoint is not None:
        from meshgen.neural.family import load_family_member

        # A family checkpoint: --param picks the member (inside the trained ranges).
        member = load_family_member(checkpoint, given_params, load_geometry(spec).name if geometry_given else None)
        if member is not None:
            return member
    chosen = None
    if checkpoint is None:
        # Without --checkpoint the model is one of the --geometry (default: semicylinder), never
        # "the newest run of any geometry". The geometry must exist and fit --dims first.
        chosen = load_selected_geometry(spec, params, dims)
    elif geometry_given:
        chosen = load_selected_geometry(spec, params, None)
    model = find_model(
        checkpoint,
        geometry_name=chosen.name if chosen is not None else None,
        params=given_params,
        default_geometry=spec,
        warn=lambda text: click.echo(f"Warning: {text}", err=True),
    )
    entry = model.geometry_entry
    same_source = (
        chosen is not None
        and chosen.name == entry["name"]
        and (Path(spec).resolve() == Path(entry["spec"]).resolve() if _looks_like_path(spec) else spec == entry["spec"])
    )
    if same_source:
        geometry = bind(chosen, dict(entry["params"]))
        if geometry.values != chosen.values:
            check_boundary(geometry)
    else:
        geometry = load_geometry(entry["spec"], dict(entry["params"]))
    if len(dims) != model.dim:
        raise click.BadParameter(
            f"model {model.path} ({geometry.name}) is {model.dim}D: --dims needs {model.dim} numbers, got {len(dims)}",
            param_hint="'--dims'",
        )
    return model, geometry


def _patch_formats():
    from meshgen.formats import FORMATS

    return [fmt for fmt in FORMATS if fmt.patches]


def _correction_line(correction: dict) -> str:
    """The network's boundary error, said the same way with and without the correction."""
    error = correction["error_before"]
    line = (
        f"network's boundary error (|g(xi) - N(xi)| at the boundary nodes' parametric points): max {error['max']:.3g} "
        f"({error['max_rel']:.3g} of L = {error['characteristic_length']:.4g}), mean {error['mean']:.3g}; "
    )
    if correction["corrected"]:
        return line + "corrected: X = N + TFI[g - N] (--no-correct keeps the raw network)"
    return line + "not corrected (--no-correct)"

"""``meshgen mesh``: build a mesh with a method and write it."""

from __future__ import annotations

import click

from meshgen.commands._options import DimsCommand, dims_option, geometry_options, load_selected_geometry

METHOD_HELP = (
    "Meshing method: auto, neural, tfi, elliptic. auto: the neural map of --checkpoint, else of the newest "
    "./runs/*/checkpoint.pt for the geometry, else of the model bundled for it (semicylinder)."
)


@click.command("mesh", cls=DimsCommand)
@click.option("--method", "-m", default="auto", show_default=True, help=METHOD_HELP)
@geometry_options()
@dims_option()
@click.option("-o", "--output", required=True, type=click.Path(), help="Output file; the extension picks the format (.vtu .vtk .xdmf .cgns .xyz .fmt).")
@click.option("--checkpoint", type=click.Path(dir_okay=False), default=None, help="neural: a checkpoint from meshgen train (it sets the geometry and its parameters).")
@click.option(
    "--correct/--no-correct",
    "--snap/--no-snap",
    "correct",
    default=None,
    help="neural: add TFI of the network's boundary error, X = N + TFI[g - N], so the boundary is exact and the "
    "interior moves smoothly; --no-correct keeps the raw network [default: --correct; --snap/--no-snap: old names].",
)
@click.option("--device", type=click.Choice(["auto", "cpu", "cuda"]), default=None, help="neural: where the network is evaluated; auto picks cuda when available [default: auto].")
@click.option("--tol", type=float, default=None, help="elliptic: stop when the largest node update, relative to the characteristic length, is below this [default 1e-6].")
@click.option("--max-iter", type=click.IntRange(1), default=None, help="elliptic: most iterations (multigrid cycles).")
@click.option(
    "--cluster",
    "clusters",
    multiple=True,
    metavar="AXIS:SIDE:RATIO",
    help="Cluster nodes towards a wall (repeatable): e.g. zeta:both:1.1 (growth ratio) or eta:0:h=0.002 (first-cell height, parametric).",
)
@click.option("--quiet", "-q", is_flag=True, help="Print only errors and warnings.")
def mesh(method, geometry, params, dims, output, checkpoint, correct, device, tol, max_iter, clusters, quiet):
    """Make a structured mesh of a geometry and write it.

    With no --method and no --checkpoint, a trained model meshes: the newest run under ./runs/
    (of the --geometry given), else the semicylinder model bundled with meshgen; the model used is
    printed. --dims counts cells; nodes are dims + 1. The write is atomic: an interrupted run never
    leaves a partial file under the output name.
    """
    import sys
    import time

    from meshgen import __version__
    from meshgen.clustering import node_coordinates
    from meshgen.commands._progress import progress_display
    from meshgen.formats import check_output_path
    from meshgen.methods import get_method, make_mesh
    from meshgen.quality import summary_lines, write_mesh_with_quality

    output = check_output_path(output)
    context = click.get_current_context()
    geometry_given = context.get_parameter_source("geometry") != click.core.ParameterSource.DEFAULT
    if method == "auto":
        # No fall-back to TFI: a geometry without a trained model is an error that says how to get one.
        method = "neural"
    get_method(method)  # an unknown name fails before anything is loaded
    coords = node_coordinates(dims, clusters)  # and so does a malformed --cluster
    options = {"tol": tol, "max_iter": max_iter, "correct": correct, "device": device}
    model = None
    if method == "neural":
        model, geometry = _neural_model(checkpoint, geometry, params, geometry_given, dims)
        options["model"] = model
    else:
        if checkpoint is not None:
            raise click.UsageError(f"--checkpoint applies to the neural method, not to '{method}'")
        geometry = load_selected_geometry(geometry, params, dims)
    if model is not None and not quiet:
        click.echo(f"model: {model.describe()}")
    start = time.perf_counter()
    show_progress = not quiet and sys.stdout.isatty() and "progress" in get_method(method).options
    with progress_display(f"{method} mesh", show_progress) as progress:
        X, info = make_mesh(method, geometry, coords, progress=progress, **options)
    seconds = time.perf_counter() - start
    metadata = {
        "meshgen_version": __version__,
        "method": method,
        "geometry": geometry.name,
        "params": geometry.values,
        "dims": list(dims),
        **({"cluster": list(clusters)} if clusters else {}),
        "meshing_seconds": seconds,
        **({"method_info": info} if info else {}),
    }
    # The mesh with its per-cell quality arrays, and <output>.quality.json beside it.
    report = write_mesh_with_quality(output, X, geometry, metadata)
    for line in info.get("warnings", []):
        click.echo(f"Warning: {line}", err=True)
    if not quiet:
        cells = 1
        for n in dims:
            cells *= n
        click.echo(f"{method} mesh of {geometry.name}: {' x '.join(map(str, dims))} = {cells} cells in {seconds:.2f} s")
        if "iterations" in info:
            click.echo(
                f"{info['iterations']} iterations, final update {info['final_update']:.2e}, "
                f"residual {info['final_residual']:.2e} ({'converged' if info['converged'] else 'not converged'})"
            )
        if "correction" in info:
            click.echo(_correction_line(info["correction"]))
        click.echo(f"wrote {output}")
        for line in summary_lines(report):
            click.echo(line)


def _neural_model(checkpoint, spec, params, geometry_given, dims):
    """The model to mesh with (``meshgen.neural.inference.find_model``) and the geometry it was
    trained on, with its parameters."""
    from meshgen.geometry import load_geometry, parse_params
    from meshgen.neural.inference import find_model

    given_params = parse_params(params)
    name = None
    if checkpoint is None and (geometry_given or given_params):
        # --param without --geometry sets the default geometry's parameters. The geometry must
        # exist and fit --dims before models are looked up.
        name = load_selected_geometry(spec, params, dims).name
    elif geometry_given:
        name = load_geometry(spec, given_params).name
    model = find_model(
        checkpoint,
        geometry_name=name,
        params=given_params,
        default_geometry=spec,
        warn=lambda text: click.echo(f"Warning: {text}", err=True),
    )
    entry = model.geometry_entry
    geometry = load_geometry(entry["spec"], dict(entry["params"]))
    if len(dims) != model.dim:
        raise click.BadParameter(
            f"model {model.path} ({geometry.name}) is {model.dim}D: --dims needs {model.dim} numbers, got {len(dims)}",
            param_hint="'--dims'",
        )
    return model, geometry


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

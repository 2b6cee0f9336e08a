"""``meshgen mesh``: build a mesh with a method and write it."""

from __future__ import annotations

import sys

import click

from meshgen.cli._options import DimsCommand, block_nodes_option, dims_option, geometry_options
from meshgen.cli._progress import progress_display
from meshgen.cli._text import echo
from meshgen.errors import GeometryError, MeshgenError, did_you_mean
from meshgen.formats import format_for
from meshgen.geometry.plugins import parse_params, plugin_module
from meshgen.geometry.topology import TOPOLOGY_DIMS_MEANING, topology_dims
from meshgen.methods.registry import METHODS
from meshgen.neural.checkpoint_data import read_plain_checkpoint
from meshgen.quality import summary_lines
from meshgen.run.request import MeshRequest, carry_out

__all__ = ["METHOD_HELP", "mesh"]

METHOD_HELP = (
    "Meshing method: auto, neural, tfi, elliptic. auto: the neural map of --checkpoint, else of the newest "
    "./runs/*/checkpoint.pt trained on the --geometry (default semicylinder), else of the model bundled for it, "
    "else elliptic (one line says so)."
)


@click.command("mesh", cls=DimsCommand)
@click.option("--method", "-m", default="auto", show_default=True, help=METHOD_HELP)
@geometry_options()
@dims_option(
    required=False,
    help_text="Cells per axis: two numbers (2D) or three (3D), e.g. --dims 30 30 30. Required, except for a topology file "
    "(its 'cells' give the counts; --param refine=R scales them).",
)
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
    "--polish/--no-polish",
    "polish",
    default=None,
    help="neural: after the correction, solve the discrete Winslow equations from the network's mesh (faces "
    "relaxed, multigrid cycles), which a flow solver needs from most networks (a soft-boundary network's own mesh "
    "gives potentialFoam errors thousands of times the elliptic mesh's); --no-polish keeps the corrected network mesh. Not with --chunked "
    "[default: --polish, but --no-polish for a network trained on the smoothed layout's lattice with the exact "
    "boundary (the bundled models, whose own mesh meets the solver-fidelity target) and for block sets, "
    "docs/design.md §18, §20].",
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
    help="neural: where the network is evaluated; auto picks cuda when available [default: auto]. elliptic (one "
    "block): cuda solves on the GPU (torch), auto there when one is available [default: cpu].",
)
@click.option(
    "--tol",
    type=float,
    default=None,
    help="elliptic: stop when the largest node update, relative to the characteristic length (multi-block geometries: "
    "to the node's local cell size), is below this [default: 1e-6].",
)
@click.option(
    "--max-iter", type=click.IntRange(1), default=None, help="elliptic: most iterations (multigrid cycles) [default: 100]."
)
@click.option(
    "--cluster",
    "clusters",
    multiple=True,
    metavar="AXIS:SIDE:RATIO",
    help="Cluster nodes towards a wall (repeatable): e.g. zeta:both:1.1 (growth ratio) or eta:0:h=0.002 (first-cell height, parametric); "
    "multi-block geometries: PATCH:RATIO, e.g. wall:1.1, the same grading in every block.",
)
@click.option(
    "--first-cell",
    "first_cell",
    multiple=True,
    metavar="[PATCH=]H",
    help="Multi-block geometries: the first cells on every wall patch (or on PATCH; repeatable) are H high "
    "(physical length), the grading shared by every block across the interfaces.",
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
    help="Compute the mesh in blocks on Dask and stream it into the file (tfi, neural; .cgns, .vts, .pvts, .su2, .msh, "
    "Plot3D, OpenFOAM), for meshes larger than memory [default: chunked when the in-memory path would need more than "
    "half of the available memory].",
)
@block_nodes_option()
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
@click.option(
    "--yplus",
    type=float,
    default=None,
    help="Geometries meshed to the wall (airfoil): the first cell's y+ (its parameter yplus) [default: the geometry's].",
)
@click.option(
    "--reynolds",
    type=float,
    default=None,
    help="Geometries meshed to the wall (airfoil): the Reynolds number per chord (its parameter reynolds) "
    "[default: the geometry's].",
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
    polish,
    device,
    tol,
    max_iter,
    clusters,
    first_cell,
    boundary_layout,
    orthogonal,
    chunked,
    scheduler,
    block_nodes,
    quality,
    yplus,
    reynolds,
    quiet,
):
    """Make a structured mesh of a geometry and write it.

    With no --method and no --checkpoint, a trained model of the --geometry (default: semicylinder)
    meshes: the newest run under ./runs/ trained on it, else the model bundled with meshgen for it,
    else the elliptic method; one line says which model was used, or that none was. --dims
    counts cells; nodes are dims + 1. The write is atomic: an interrupted run never leaves a
    partial file under the output name.

    Boundary patches (named faces) go into .cgns, .vts, .pvts, .su2, .msh and OpenFOAM cases.

    Meshes larger than memory (e.g. --dims 1000 1000 1000 -o big.cgns) are computed block by block
    and streamed with bounded memory into .cgns, .vts, .pvts, .su2, .msh, Plot3D or an OpenFOAM case
    (the others through a scratch .cgns file beside the output, removed afterwards); their quality
    report is computed block-wise, and no per-cell quality arrays are attached (see README).
    """
    _check_method(method)  # an unknown name fails before anything is loaded
    context = click.get_current_context()
    geometry_given = context.get_parameter_source("geometry") != click.core.ParameterSource.DEFAULT
    if dims is None:
        dims = topology_dims(geometry) if geometry_given else None
        if dims is None:
            raise click.MissingParameter(ctx=context, param=next(p for p in context.command.params if p.name == "dims"))
    request = MeshRequest(
        dims,
        geometry if geometry_given or checkpoint is None else None,
        _wall_options(
            parse_params(params),
            geometry,
            None if geometry_given else checkpoint,
            yplus=yplus,
            reynolds=reynolds,
        ),
        method,
        checkpoint=checkpoint,
        tol=tol,
        max_iter=max_iter,
        correct=correct,
        polish=polish,
        device=device,
        boundary_layout=boundary_layout,
        orthogonal=tuple(orthogonal),
        clusters=tuple(clusters),
        first_cell=tuple(first_cell),
        output=output,
        format=format_name,
        patches=tuple(patch_items),
        ascii=ascii_files,
        chunked=chunked,
        scheduler=scheduler,
        block_nodes=block_nodes,
        quality=quality,
    )
    interactive = not quiet and sys.stdout.isatty()
    made = carry_out(
        request,
        say=None if quiet else click.echo,
        warn=lambda text: click.echo(f"Warning: {text}", err=True),
        progress=lambda label, iterative: progress_display(label, interactive and iterative),
    )
    if made.blocks is not None:
        _print_block_result(made, quiet)
    else:
        _print_result(made, format_for(made.output, format_name), quiet)


def _print_block_result(made, quiet):
    """What a block set's run says: blocks, cells, what --dims counted, the sweeps, the file."""
    info = made.info
    for line in info.get("warnings", []):
        click.echo(f"Warning: {line}", err=True)
    if quiet:
        return
    block_set = made.geometry
    echo(
        f"{made.method} mesh of {block_set.name}: {len(block_set.names)} blocks, {block_set.cells} cells "
        + (
            "(counts from the topology file)"
            if block_set.dims_meaning == TOPOLOGY_DIMS_MEANING
            else f"(--dims {' '.join(map(str, made.dims))}: {block_set.dims_meaning})"
        )
        + f" in {made.seconds:.2f} s"
    )
    for name, height in info.get("first_cell", {}).items():
        echo(
            f"first cells on {name}: {height['mean']:.3g} mean ({height['min']:.3g} to {height['max']:.3g}), "
            f"asked {height['asked']:.3g}"
        )
    if "sweeps" in info:
        echo(
            f"{info['sweeps']} sweeps, final update {info['final_update']:.2e} of the local cell size "
            f"({'converged' if info['converged'] else 'not converged'})"
        )
    polished = info.get("orthogonality")
    if polished:
        (internal, boundary), start = polished["after"], polished["start"]
        echo(
            f"orthogonality polish: largest non-orthogonality {polished['before'][0]:.1f} -> {internal:.1f} deg "
            f"(boundary faces {polished['before'][1]:.1f} -> {boundary:.1f}; the start mesh's {start[0]:.1f} and "
            f"{start[1]:.1f}), {polished['moved']} nodes moved" + ("" if polished["kept"] else ": not kept, a largest angle grew")
        )
    echo(f"wrote {made.output}")
    for line in summary_lines(made.quality_report) if made.quality_report is not None else []:
        echo(line)


def _print_result(made, output_format, quiet):
    info = made.info
    for line in info.get("warnings", []):
        click.echo(f"Warning: {line}", err=True)
    if quiet:
        return
    cells = 1
    for n in made.dims:
        cells *= n
    echo(f"{made.method} mesh of {made.geometry.name}: {' x '.join(map(str, made.dims))} = {cells} cells in {made.seconds:.2f} s")
    if "iterations" in info:
        echo(
            f"{info['iterations']} iterations, final update {info['final_update']:.2e}, "
            f"residual {info['final_residual']:.2e} ({'converged' if info['converged'] else 'not converged'})"
        )
    if "correction" in info:
        echo(_correction_line(info["correction"]))
    if "polish" in info:
        polished = info["polish"]
        if polished.get("polished", True):
            echo(
                f"polished: {polished['cycles']} Winslow cycles, nodes moved up to "
                f"{polished['largest_move_rel']:.2g} of L (--no-polish keeps the network's mesh)"
            )
        else:
            hint = "" if polished["reason"].startswith("--") else "; --polish solves the discrete Winslow equations from it"
            echo(f"not polished ({polished['reason']}{hint})")
    if "chunked" in info:
        blocks = info["chunked"]
        line = f"computed in {blocks['blocks']} blocks on {blocks['scheduler']}: written in {blocks['write_seconds']:.1f} s"
        if "quality_seconds" in blocks:
            line += f", quality (block-wise, from the file) in {blocks['quality_seconds']:.1f} s"
        echo(line)
    echo(f"wrote {made.output}" + (f" ({output_format.name})" if output_format.folder else ""))
    if output_format.patches:
        echo("patches: " + ", ".join(f"{p.name} ({p.type}: {' '.join(p.faces)})" for p in made.patches))
    for line in summary_lines(made.quality_report) if made.quality_report is not None else []:
        echo(line)


def _trained_on(checkpoint, default: str) -> str:
    """The geometry spec a --checkpoint was trained on (what the mesh command meshes without -g),
    else ``default`` (no checkpoint, or one the request will refuse with its own message)."""
    if checkpoint is None:
        return default
    try:
        return str(read_plain_checkpoint(checkpoint)["geometry"]["spec"])
    except (MeshgenError, KeyError, TypeError):
        return default


def _wall_options(values: dict, geometry: str, checkpoint, **given) -> dict:
    """``values`` (the --param values) with --yplus / --reynolds added as the parameters of the same
    names; a geometry without such a parameter, or the same one given as --param too, is refused.
    ``checkpoint``: the --checkpoint when no -g was given (its geometry is the one meshed; read only
    when --yplus or --reynolds is)."""
    given = {key: value for key, value in given.items() if value is not None}
    if not given:
        return values
    geometry = _trained_on(checkpoint, geometry)
    names = getattr(plugin_module(geometry)[0], "params", {})
    for key in given:
        if key not in names:
            raise GeometryError(
                f"--{key} is for geometries meshed to the wall (airfoil); geometry '{geometry}' has no parameter '{key}'"
            )
        if key in values:
            raise GeometryError(f"--{key} and --param {key}= both given: give one")
    return {**values, **given}


def _check_method(name):
    """An unknown method, or a trained method (``3dmeshnet``, ``pinn`` ...: ``meshgen compare``
    trains those), is a usage error naming the choices."""
    choices = ["auto", *(method for method, entry in METHODS.items() if entry.preset is None)]
    if name in METHODS and name not in choices:
        raise click.UsageError(
            f"method '{name}' is a network trained with preset '{METHODS[name].preset}': train it with "
            f"'meshgen train --preset {METHODS[name].preset}', then mesh with --method neural --checkpoint PATH"
        )
    if name not in choices:
        raise click.UsageError(f"unknown method '{name}' (methods: {', '.join(choices)}){did_you_mean(name, choices)}")


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

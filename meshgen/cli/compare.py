"""``meshgen compare``: methods (or mesh files) side by side: one table, and with --out the tables
as JSON / Markdown / CSV, the meshes and pictures.

Exit status: 0, 1 when a method failed (its row says so), 2 for usage errors.
"""

from __future__ import annotations

import struct
from pathlib import Path

import click

from meshgen.cli import comparison as comparing
from meshgen.cli import plots
from meshgen.cli._options import DimsCommand, dims_option, geometry_options, load_selected_geometry
from meshgen.cli.tables import METRIC_LABELS, print_table
from meshgen.formats import format_for
from meshgen.geometry.plugins import load_geometry, parse_params
from meshgen.methods.registry import METHODS
from meshgen.neural.progress import reporter_for
from meshgen.run.limits import check_mesh_memory

__all__ = ["EPILOG", "compare"]

EPILOG = """\b
Columns: means of min angle, max angle, equiangle skewness, aspect ratio, centroid skewness and
non-orthogonality; inverted cells (count and %); valid (no inverted cell); boundary
deviation (largest distance of a boundary node from the true boundary, and its fraction of the
characteristic length L); test-set loss and training time (neural methods); meshing time.
The best value per column is highlighted: closest to 90 degrees for the angles, else smallest.

\b
--out DIR writes compare.json, compare.md, compare.csv, the meshes (<method>.vtu with their
.quality.json), the neural runs (runs/<method>/), sections.png (mid-sections coloured by --metric,
one column per method: 400 x 360 px per panel, plus 120 px for the colour bar and 40 px for the
title) and loss_curves.png (400 x 400 px per neural method). Pictures need matplotlib:
pip install 'meshgen[plot]'.

\b
Examples:
  meshgen compare -g semicylinder --dims 30 30 30 --methods tfi,elliptic,3dmeshnet --steps 2000 --out cmp
  meshgen compare -g semidisk --dims 40 20 --methods tfi,elliptic,pinn --checkpoint pinn=runs/pinn/checkpoint.pt
  meshgen compare a.vtu b.cgns --out cmp
"""


def _methods_help() -> str:
    return f"Comma-separated methods: {', '.join(METHODS)} [default: {','.join(comparing.DEFAULT_METHODS)}]."


@click.command("compare", cls=DimsCommand, epilog=EPILOG)
@click.argument("meshes", nargs=-1, metavar="[MESH...]")
@click.option("--methods", default=None, metavar="LIST", help=_methods_help())
@geometry_options(default=None)
@dims_option(required=False, help_text="Cells per axis when meshing a geometry: two numbers (2D) or three (3D).")
@click.option(
    "--out",
    "out_dir",
    type=click.Path(),
    default=None,
    metavar="DIR",
    help="Write tables, meshes and pictures into DIR (created if missing).",
)
@click.option(
    "--metric",
    type=click.Choice(
        [
            "min_angle",
            "max_angle",
            "equiangle_skewness",
            "aspect_ratio",
            "centroid_skewness",
            "non_orthogonality",
            "scaled_jacobian",
        ]
    ),
    default="non_orthogonality",
    show_default=True,
    metavar="METRIC",
    help="Per-cell metric that colours the pictures: min_angle, max_angle, equiangle_skewness, aspect_ratio, "
    "centroid_skewness, non_orthogonality or scaled_jacobian.",
)
@click.option(
    "--timing-repeats", type=click.IntRange(1), default=1, show_default=True, help="Time meshing as the median of N runs."
)
@click.option(
    "--steps",
    type=click.IntRange(1),
    default=None,
    help="Neural methods: Adam steps of every training run [default: each preset's adam.steps].",
)
@click.option(
    "--set",
    "overrides",
    multiple=True,
    metavar="KEY=VALUE",
    help="Neural methods: override a training setting of every preset (repeatable), e.g. --set model.widths=[20,20].",
)
@click.option(
    "--seed", type=int, default=None, help="Neural methods: random seed of every training run [default: each preset's seed, 0]."
)
@click.option(
    "--checkpoint",
    "checkpoints",
    multiple=True,
    metavar="METHOD=PATH",
    help="Reuse a trained network instead of training (repeatable), e.g. pinn=runs/pinn/checkpoint.pt.",
)
@click.option(
    "--device",
    type=click.Choice(["auto", "cpu", "cuda"]),
    default="auto",
    show_default=True,
    help="Neural methods: where to train; auto picks cuda when available.",
)
@click.option(
    "--tol", type=float, default=None, help="elliptic: convergence tolerance (see 'meshgen mesh --help') [default: 1e-6]."
)
@click.option("--max-iter", type=click.IntRange(1), default=None, help="elliptic: most iterations [default: 100].")
@click.option(
    "--cluster",
    "clusters",
    multiple=True,
    metavar="AXIS:SIDE:RATIO",
    help="Cluster nodes towards a wall, for every method (as in 'meshgen mesh').",
)
@click.option(
    "--polish/--no-polish",
    "polish",
    default=None,
    help="Neural methods: polish each network's mesh to the discrete Winslow equations, as 'meshgen mesh' does "
    "[default: as 'meshgen mesh' decides for each model: not for a network trained with the exact boundary on the "
    "smoothed layout's lattice, else --polish]; --no-polish compares the networks' own meshes (the ablations differ "
    "only there).",
)
@click.option("--mesh-format", default=".vtu", show_default=True, metavar="EXT", help="Format of the meshes written with --out.")
@click.option("--quiet", "-q", is_flag=True, help="Print only the table and errors.")
def compare(
    meshes,
    methods,
    geometry,
    params,
    dims,
    out_dir,
    metric,
    timing_repeats,
    steps,
    overrides,
    seed,
    checkpoints,
    device,
    tol,
    max_iter,
    clusters,
    polish,
    mesh_format,
    quiet,
):
    """Compare meshing methods on a geometry, or existing mesh files, in one table.

    With --dims: mesh the geometry (--geometry, default semicylinder) with each of --methods,
    training the neural ones (budget: --steps, --set) or loading --checkpoint METHOD=PATH.
    With MESH files: measure them as 'meshgen evaluate' does (boundary deviation against the
    geometry each file records, or --geometry).
    """

    def say(text):
        if not quiet:
            click.echo(text, err=True)

    mesh_format = mesh_format if mesh_format.startswith(".") else "." + mesh_format
    if meshes:
        given = [
            flag
            for flag, value in (
                ("--methods", methods),
                ("--dims", dims),
                ("--steps", steps),
                ("--set", overrides),
                ("--seed", seed),
                ("--checkpoint", checkpoints),
                ("--tol", tol),
                ("--max-iter", max_iter),
                ("--polish/--no-polish", polish is not None),
                ("--cluster", clusters),
            )
            if value
        ]
        if given:
            raise click.UsageError(f"{given[0]} applies when meshing a geometry (--dims), not to mesh files")
        if timing_repeats > 1:
            raise click.UsageError("--timing-repeats applies when meshing a geometry; files report the time they record")
    elif dims is None:
        raise click.UsageError("give --dims to mesh a geometry with --methods, or mesh files to compare")

    # Everything the command line can get wrong fails before anything is created or written.
    if meshes:
        parsed = parse_params(params)
        chosen = load_geometry(geometry, parsed) if geometry else None
        comparing.check_mesh_files(meshes)
        out = comparing.prepare_out_dir(out_dir) if out_dir is not None else None
    else:
        names = comparing.parse_methods(methods or ",".join(comparing.DEFAULT_METHODS))
        reuse = comparing.parse_checkpoints(checkpoints)
        chosen = load_selected_geometry(geometry or "semicylinder", params, dims)
        check_mesh_memory(dims, chunked=False)  # compare meshes in memory: too large is an error before any method runs
        if out_dir is not None:
            format_for("mesh" + mesh_format)
        out = Path(out_dir) if out_dir is not None else None  # compare_methods creates it after its checks

    if meshes:
        outcome = comparing.compare_files(meshes, chosen, None if chosen else parsed)
    else:
        outcome = comparing.compare_methods(
            chosen,
            dims,
            names,
            clusters=clusters,
            method_options={"tol": tol, "max_iter": max_iter, "polish": polish},
            budget=comparing.Budget(steps, tuple(overrides), seed, device),
            checkpoints=reuse,
            timing_repeats=timing_repeats,
            out_dir=out,
            mesh_format=mesh_format,
            say=say,
            reporter=None if quiet else _training_reporter,
        )
    comparison = outcome.comparison

    written = []
    if out is not None:
        written += [row["file"] for row in comparison["rows"] if row.get("file") and row["kind"] != "file"]
        written += [str(p) for p in _pictures(outcome, metric, out, say)]
        written += [str(p) for p in comparing.write_tables(comparison, out)]  # last: they record the pictures

    header, rows, highlight = comparing.table(comparison, short=True)
    print_table(
        header, rows, title=comparing.title(comparison), highlight=highlight, caption=comparing.CAPTION, fit_terminal=True
    )
    for row in comparison["rows"]:
        if "error" in row:
            click.echo(f"{row['name']} failed: {row['error']}", err=True)
        for warning in row.get("quality", {}).get("warnings", []):
            say(f"warning: {row['name']}: {warning}")
    if written:
        say(f"wrote {len(written)} files in {out}: " + ", ".join(sorted({_short(p, out) for p in written})))
    elif comparison["mode"] == "methods" and not quiet:
        say("(--out DIR keeps the meshes, tables and pictures)")
    if outcome.interrupted:
        click.echo(f"Interrupted: not run: {', '.join(comparison['interrupted']['not_run'])}.", err=True)
        return 130  # as a Ctrl-C that ends any other command
    if any("error" in row for row in comparison["rows"]):
        return 1
    return 0


def _training_reporter(config):
    """The training progress of a neural row, as ``meshgen train`` shows it (imported only when a
    neural row trains)."""
    return reporter_for(config)


def _short(path, out) -> str:
    try:
        return str(Path(path).relative_to(out))
    except ValueError:
        return str(path)


def _pictures(outcome, metric, out, say) -> list:
    """Write sections.png and loss_curves.png; without matplotlib say how to get them."""
    comparison = outcome.comparison
    if not plots.plotting_available():
        say(f"no pictures: {plots.INSTALL_HINT}")
        comparison.setdefault("notes", []).append(f"No pictures: {plots.INSTALL_HINT}.")
        return []
    if comparison["mode"] == "methods":
        heading = f"{METRIC_LABELS[metric]}: {comparison['geometry']}, {' x '.join(map(str, comparison['dims']))} cells"
    else:
        heading = METRIC_LABELS[metric]
    written = []
    undrawable = [p.label for p in outcome.pictures if not plots.drawable(p)]
    if undrawable:
        note = f"not in the pictures (unstructured 3D meshes have no index mid-planes): {', '.join(undrawable)}"
        say(note)
        comparison.setdefault("notes", []).append(note[0].upper() + note[1:] + ".")
    sections = plots.sections_figure(outcome.pictures, metric, out / "sections.png", heading)
    if sections is not None:
        written.append(sections)
        comparison["pictures"] = {"sections": sections.name, "metric": metric, "size_px": list(_png_size(sections))}
    curves = plots.loss_curves_figure(outcome.pictures, out / "loss_curves.png")
    if curves is not None:
        written.append(curves)
        comparison.setdefault("pictures", {})["loss_curves"] = curves.name
    return written


def _png_size(path) -> tuple[int, int]:
    """(width, height) from a PNG's IHDR chunk."""
    with open(path, "rb") as handle:
        head = handle.read(24)
    return struct.unpack(">II", head[16:24])

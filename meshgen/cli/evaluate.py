"""``meshgen evaluate MESH...``: quality table, JSON / Markdown reports, and CI gates (``--fail-if``).

Exit status: 0 when no gate trips, 1 when one does, 2 for usage errors and files that cannot be
evaluated.
"""

from __future__ import annotations

import json
import sys
import threading

import click

from meshgen.cli._options import block_nodes_option, geometry_options
from meshgen.cli._progress import progress_display
from meshgen.cli.tables import METRIC_LABELS, markdown_table, print_table, warm_up
from meshgen.cli.tables import number as _number
from meshgen.geometry.blocks import block_spec
from meshgen.geometry.plugins import load_geometry, parse_params
from meshgen.quality import METRICS, STATS, evaluate_file, json_ready, write_json
from meshgen.quality.files import zone_reports
from meshgen.quality.gates import GateError, check_gates, parse_gate
from meshgen.run.atomic import atomic_write, check_output_file
from meshgen.run.early import resume_collection
from meshgen.run.scheduler import connect, scheduler_address

__all__ = ["EPILOG", "evaluate", "markdown", "tables"]


def _verdict_rows(report) -> list[tuple[str, str]]:
    inverted = report["inverted"]
    rows = [
        ("cells", f"{report['cells']} {report['cell_type']}"),
        ("inverted cells", f"{inverted['count']} ({100 * inverted['fraction']:.3g}%)"),
        ("valid (no inverted cell)", _number(report["valid"])),
    ]
    rows += solver_figure_rows(report)
    if report.get("skipped"):
        rows.append(("skipped cells", ", ".join(f"{n} {kind}" for kind, n in report["skipped"].items())))
    deviation = report.get("boundary_deviation")
    if deviation:
        rows.append(("boundary deviation max", f"{_number(deviation['max'])} ({_number(deviation['max_rel'])} of L)"))
        rows.append(("boundary deviation mean", f"{_number(deviation['mean'])} ({_number(deviation['mean_rel'])} of L)"))
    else:
        rows.append(("boundary deviation", "n/a (no geometry)"))
    return rows


def _cell(index) -> str:
    return "(" + ", ".join(map(str, index)) + ")"


def solver_figure_rows(report) -> list[tuple[str, str]]:
    """Rows of the figures that predict a solver's error (structured meshes), with worst cells."""
    figures = report.get("solver_figures")
    if not figures:
        return []
    rows = []
    for name, label in (("expansion_ratio", "expansion ratio"), ("grid_smoothness", "grid smoothness")):
        figure = figures[name]
        block = f" of block {figure['worst_block']}" if "worst_block" in figure else ""
        text = f"{_number(figure['max'])} at cell {_cell(figure['worst_cell'])}{block} (mean {_number(figure['mean'])}"
        if "max_by_axis" in figure:
            lines = zip(("xi", "eta", "zeta"), figure["max_by_axis"])
            text += "; along " + ", ".join(f"{axis} lines {_number(value)}" for axis, value in lines)
        rows.append((f"{label} max", text + ")"))
    for name, label in (
        ("non_orthogonality_internal", "non-orthogonality, internal faces (checkMesh)"),
        ("non_orthogonality_boundary", "non-orthogonality, boundary faces"),
    ):
        figure = figures[name]
        if figure["max"] is not None:
            face = figure["worst_face"]
            where = f"face normal to axis {face['axis']} at {_cell(face['index'])}"
            where += f" of block {face['block']}" if "block" in face else ""
            rows.append((f"{label} max", f"{_number(figure['max'])} deg at {where} (average {_number(figure['average'])})"))
    return rows


def tables(reports) -> list[tuple[list[str], list[list[str]]]]:
    """(header, rows) of the quality tables: one mesh gives a metric x statistic grid and a
    verdict table; several give one table with a column per mesh."""
    if len(reports) == 1:
        report = reports[0]
        header = ["metric", *STATS]  # the statistics as --json and --fail-if name them
        rows = [[METRIC_LABELS[m], *(_number(report["metrics"][m][s]) for s in STATS)] for m in METRICS]
        return [(header, rows), (["verdict", ""], [list(row) for row in _verdict_rows(report)])]
    header = ["quantity", *(r["file"] for r in reports)]
    rows = [[f"{METRIC_LABELS[m]} {s}", *(_number(r["metrics"][m][s]) for r in reports)] for m in METRICS for s in STATS]
    verdicts = [dict(_verdict_rows(r)) for r in reports]
    labels = list(dict.fromkeys(label for v in verdicts for label in v))
    rows += [[label, *(v.get(label, "") for v in verdicts)] for label in labels]
    return [(header, rows)]


def markdown(reports, gate_results) -> str:
    """The quality tables as Markdown (a CI job summary), with the gates' outcome."""
    lines = ["## Mesh quality", ""]
    if len(reports) == 1:
        lines += [f"`{reports[0]['file']}`", ""]
    for header, rows in tables(reports):
        lines += markdown_table(header, rows)
        lines.append("")
    if gate_results:
        lines += ["### Gates", ""]
        for result in gate_results:
            status = "**FAILED**" if result["tripped"] else "passed"
            lines.append(f"- `{result['gate']}` on `{result['file']}`: {status} (value {_number(result['value'])})")
        lines.append("")
    lines += [
        "Angles and non-orthogonality in degrees. Summaries leave degenerate cells out; a cell is inverted "
        "when its scaled Jacobian is <= 0 at a corner or it is degenerate.",
        "",
    ]
    return "\n".join(lines)


def _parse_gates(ctx, param, values):
    try:
        return [parse_gate(text) for text in values]
    except GateError as exc:
        raise click.BadParameter(str(exc)) from None


EPILOG = """\b
Gate quantities: METRIC.STAT, METRIC one of min_angle, max_angle, equiangle_skewness,
aspect_ratio, centroid_skewness, non_orthogonality, scaled_jacobian and STAT one of mean, min,
max, p01, p99; inverted.count, inverted.fraction, inverted.percent, valid (true/false), cells,
boundary_deviation.max, .mean, .max_rel, .mean_rel; for meshgen's structured meshes
expansion_ratio and grid_smoothness .max, .mean, .p99, non_orthogonality_internal (checkMesh's)
and non_orthogonality_boundary .max, .average. Operators: < <= > >= == !=.

\b
Exit status: 0 no gate tripped, 1 a gate tripped, 2 usage error or a file that cannot be evaluated.
"""


@click.command("evaluate", epilog=EPILOG)
@click.argument("meshes", nargs=-1, required=True, metavar="MESH...")
@geometry_options(default=None)
@click.option(
    "--json", "json_path", metavar="FILE", help="Write the report as JSON ('-' for stdout): one mesh an object, several a list."
)
@click.option("--markdown", "markdown_path", metavar="FILE", help="Write the table as Markdown (e.g. for a CI job summary).")
@click.option(
    "--fail-if",
    "gates",
    multiple=True,
    metavar="EXPR",
    callback=_parse_gates,
    help="Exit 1 if EXPR holds for any mesh, e.g. 'inverted.count>0', 'min_angle.mean<70', "
    "'boundary_deviation.max_rel>1e-3' (repeatable).",
)
@click.option(
    "--chunked/--in-memory",
    default=None,
    help="Evaluate .cgns files block by block on Dask (meshes larger than memory; p01/p99 from a quantile sketch of "
    "relative accuracy 1e-4) [default: chunked when the in-memory path would need more than half of the available memory].",
)
@click.option(
    "--scheduler",
    metavar="ADDRESS",
    default=None,
    help="Run the blocks on this dask.distributed scheduler (implies --chunked; the workers must see the files) "
    "[default: $DASK_SCHEDULER_ADDRESS, else Dask's local threads].",
)
@click.option("--per-block", is_flag=True, help="Multi-zone .cgns files (block sets): also report each zone (block) on its own.")
@block_nodes_option()
@click.option("--quiet", "-q", is_flag=True, help="Print only tripped gates and errors.")
def evaluate(meshes, geometry, params, json_path, markdown_path, gates, chunked, scheduler, per_block, block_nodes, quiet):
    """Measure the quality of hexahedral or quadrilateral meshes (any file meshio reads, meshgen's
    .vts, .cgns, .xyz, or an OpenFOAM case folder meshgen wrote).

    Prints per metric the mean, min, max and 1st/99th percentiles, the inverted cells and the
    validity verdict (valid: no inverted cell), and the boundary deviation when
    the geometry is known: files written by meshgen record it; for others pass --geometry.
    """
    resume_collection()  # the imports are done (meshgen.run.early)
    # Report paths first: a bad one fails before any mesh is read.
    if json_path and json_path != "-":  # '-': stdout
        check_output_file(json_path, "report.json")
    if markdown_path:
        check_output_file(markdown_path, "report.md")
    parsed_params = parse_params(params)
    # A multi-block geometry goes by name: evaluate_file measures against its block set.
    chosen = load_geometry(geometry, parsed_params) if geometry and not block_spec(geometry) else geometry
    address = scheduler_address(scheduler)
    if address is not None and chunked is False:
        raise click.UsageError("--scheduler runs the chunked path; leave out --in-memory")
    client = connect(address)  # an unreachable scheduler fails fast, before any file is read
    # A bar with a running clock on a terminal (a big file takes minutes); nothing when piped.
    interactive = not quiet and json_path != "-" and sys.stdout.isatty()
    try:
        options = {"chunked": True if client else chunked, "client": client, "block_nodes": block_nodes}
        if per_block:
            options["per_block"] = True
        by_name = isinstance(chosen, str)
        table = not quiet and json_path != "-"
        params_of = parsed_params if by_name or not chosen else None
        reports = [_evaluate_one(path, chosen, params_of, interactive, options, table) for path in meshes]
    finally:
        if client is not None:
            client.close()
    # Each block of a block set after the whole mesh (evaluate_file's per_block); the blocks of a
    # chunked evaluation (no block reports of its own) read again.
    if per_block:
        reports = [
            entry
            for path, report in zip(meshes, reports)
            for entry in (report, *(report.pop("blocks") if "blocks" in report else zone_reports(path)))
        ]

    gate_results = []
    try:
        for report in reports:
            results = check_gates(report, gates)
            for result in results:
                result["file"] = report["file"]
            if gates:
                report["gates"] = results
            gate_results += results
    except GateError as exc:
        raise click.UsageError(str(exc)) from None

    to_stdout = json_path == "-"
    if json_path:
        data = reports[0] if len(reports) == 1 else reports
        if to_stdout:
            click.echo(json.dumps(json_ready(data), indent=2, allow_nan=False))
        else:
            write_json(json_path, data)
    if markdown_path:
        with atomic_write(markdown_path) as temporary:
            temporary.write_text(markdown(reports, gate_results))

    if not quiet and not to_stdout:
        _print_table(reports)
        for report in reports:
            for warning in report.get("warnings", []):
                click.echo(f"warning: {report['file']}: {warning}", err=True)
    tripped = [r for r in gate_results if r["tripped"]]
    for result in gate_results:
        if result["tripped"] or not (quiet or to_stdout):
            status = "FAILED" if result["tripped"] else "passed"
            shown = "undefined" if result["value"] is None else _number(result["value"])
            click.echo(
                f"gate {result['gate']}: {status} for {result['file']} ({result['quantity']} = {shown})",
                err=result["tripped"] or to_stdout,
            )
    return 1 if tripped else 0


def _print_table(reports) -> None:
    for number, (header, rows) in enumerate(tables(reports)):
        title = "mesh quality" + (f": {reports[0]['file']}" if len(reports) == 1 else "") if number == 0 else None
        print_table(header, rows, title=title)


def _evaluate_one(path, geometry, params, interactive: bool, options: dict, table: bool = False) -> dict:
    """The report of one mesh file, with a progress bar and a running clock at a terminal.
    ``table``: the report will be printed as a table; rich is warmed up on a thread once the file
    is read (``tables.warm_up``), while the metrics are computed, and that thread ends here, before
    the next file is read (where a worker may be forked: no import may be under way then)."""
    warming = []

    def progress(done, **figures):
        if table and figures.get("phase") == "metrics" and not warming:
            warming.append(threading.Thread(target=warm_up, name="meshgen-rich", daemon=True))
            warming[0].start()
        if bar is not None:
            bar(done, **figures)

    with progress_display(f"evaluating {click.format_filename(path)}", interactive) as bar:
        try:
            return evaluate_file(path, geometry, params, progress=progress, **options)
        finally:
            for thread in warming:
                thread.join()

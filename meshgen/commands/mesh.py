"""``meshgen mesh``: build a mesh with a method and write it."""

from __future__ import annotations

import click

from meshgen.commands._options import DimsCommand, dims_option, geometry_options, load_selected_geometry


@click.command("mesh", cls=DimsCommand)
@click.option("--method", "-m", default="tfi", show_default=True, help="Meshing method: tfi, elliptic.")
@geometry_options()
@dims_option()
@click.option("-o", "--output", required=True, type=click.Path(), help="Output file; the extension picks the format (.vtu .vtk .xdmf .cgns .xyz .fmt).")
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
def mesh(method, geometry, params, dims, output, tol, max_iter, clusters, quiet):
    """Make a structured mesh of a geometry and write it.

    --dims counts cells; nodes are dims + 1. The write is atomic: an interrupted run never leaves a
    partial file under the output name.
    """
    import sys
    import time

    from meshgen import __version__
    from meshgen.commands._progress import progress_display
    from meshgen.formats import check_output_path
    from meshgen.methods import get_method, make_mesh
    from meshgen.clustering import node_coordinates
    from meshgen.quality import summary_lines, write_mesh_with_quality

    output = check_output_path(output)
    geometry = load_selected_geometry(geometry, params, dims)
    coords = node_coordinates(dims, clusters)
    start = time.perf_counter()
    show_progress = not quiet and sys.stdout.isatty() and "progress" in get_method(method).options
    with progress_display(f"{method} mesh", show_progress) as progress:
        X, info = make_mesh(method, geometry, coords, tol=tol, max_iter=max_iter, progress=progress)
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
        click.echo(f"wrote {output}")
        for line in summary_lines(report):
            click.echo(line)

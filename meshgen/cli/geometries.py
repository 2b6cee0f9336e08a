"""``meshgen geometries``: list the available geometries and the shape files accepted; ``show NAME
-o FILE.stl`` writes a surface, ``show FILE -o faces.vtu`` the surface with each triangle's cube face."""

from __future__ import annotations

import json

import click

from meshgen.cli._options import load_selected_geometry
from meshgen.errors import GeometryError
from meshgen.geometry.blocks import BlockSet, block_spec, measured_block_set
from meshgen.geometry.blocks import describe as describe_blocks
from meshgen.geometry.plugins import available_names, load_geometry, parse_params
from meshgen.geometry.set_surface import write_block_set_surface
from meshgen.geometry.shapes.loader import FORMAT_HELP
from meshgen.geometry.shapes.show import write_face_surface
from meshgen.geometry.surface import check_surface_path, write_surface
from meshgen.run.atomic import check_output_file

__all__ = ["geometries", "show"]


@click.group("geometries", invoke_without_command=True)
@click.option(
    "--json", "as_json", is_flag=True, help="Print a JSON list of {name, dim, description, params, patches, axes, dims}."
)
@click.pass_context
def geometries(ctx, as_json):
    """List the available geometries (built-in, installed plugins) with their parameters,
    boundary patches (name, type: cube faces) and what each --dims number counts, and the shape files -g also takes: STEP/IGES/BREP
    solids, STL/OBJ/PLY surfaces and YAML geometry files (docs: shapes-from-files)."""
    if ctx.invoked_subcommand is not None:
        return
    described = []
    for name in available_names():
        try:
            described.append(describe_blocks(name) or load_geometry(name, check=False).describe())
        except GeometryError as exc:  # one broken installed plugin must not hide the others
            click.echo(f"Warning: {' '.join(str(exc).split())}", err=True)
    if as_json:
        click.echo(json.dumps(described, indent=2))
        return
    from rich.console import Console
    from rich.table import Table

    table = Table(title="meshgen geometries")
    for column in ("name", "dim", "description", "parameters (defaults)", "patches (type: faces)"):
        table.add_column(column)
    for item in described:
        params = ", ".join(f"{k}={v:g}" for k, v in item["params"].items()) or "-"
        patches = "\n".join(f"{p['name']} ({p['type']}: {' '.join(p['faces'])})" for p in item["patches"])
        if "blocks" in item:
            description = f"{item['description']}\n{len(item['blocks'])} blocks; --dims {item['dims']}"
        else:
            description = f"{item['description']}\n--dims counts {item['dims'] or 'xi, eta, zeta (not said)'}"
        table.add_row(item["name"], f"{item['dim']}D", description, params, patches)
    console = Console()
    console.print(table)

    formats = Table(title="shape files (-g FILE): a block bounded by six four-cornered faces, or a CAD sweep")
    for column in ("kind", "extensions", "what it must hold"):
        formats.add_column(column)
    for row in FORMAT_HELP:
        formats.add_row(*row)
    console.print(formats)


@geometries.command("show", short_help="Write a geometry's boundary surface (.stl .ply .obj .off; .vtu with cube faces).")
@click.argument("name")
@click.option("--param", "params", multiple=True, metavar="NAME=VALUE", help="Set a geometry parameter (repeatable).")
@click.option(
    "-o", "--output", required=True, type=click.Path(dir_okay=False), help="Surface file (.stl, .ply, .obj, .off, or .vtu)."
)
@click.option("--resolution", default=64, show_default=True, type=click.IntRange(2, 2048), help="Samples per face edge.")
def show(name, params, output, resolution):
    """Write the closed boundary surface of geometry NAME (2D: the filled domain in z = 0). With a
    .vtu output: the surface with the cell arrays cube_face (0..5: xi0 xi1 eta0 eta1 zeta0 zeta1)
    and patch, to check a shape file's face assignment before meshing (a triangulated surface's own
    triangles; otherwise the boundary map sampled). A multi-block geometry: its blocks' patch
    faces (interfaces left out), --resolution cells per block edge; a .vtu adds the cell array block."""

    if output.lower().endswith(".vtu"):
        check_output_file(output, "faces.vtu")
        geometry = _shown(name, params)
        if geometry.dim != 3:
            raise click.BadParameter("a .vtu of cube faces needs a 3D geometry", param_hint="--output")
        path, count = write_face_surface(geometry, output, resolution)
        arrays = "block, cube_face and patch" if isinstance(geometry, BlockSet) else "cube_face and patch"
        click.echo(f"wrote {path}: {count} triangles with cell arrays {arrays}")
        return
    check_surface_path(output)  # before loading: a bad path fails fast, whatever the geometry
    geometry = _shown(name, params)
    write = write_block_set_surface if isinstance(geometry, BlockSet) else write_surface
    path, surface = write(geometry, output, resolution)
    click.echo(
        f"wrote {path}: {len(surface.vertices)} vertices, {len(surface.faces)} triangles"
        + (
            f", {'watertight' if surface.is_watertight else 'NOT watertight'}, volume {surface.volume:.6g}"
            if geometry.dim == 3
            else f", area {surface.area:.6g}"
        )
    )


def _shown(name, params):
    """The geometry to show: a multi-block one as its block set (its blocks' patch faces)."""
    spec = block_spec(name)
    if spec is not None:
        return measured_block_set(spec, parse_params(params))
    return load_selected_geometry(name, params)

"""Options shared by several commands: geometry selection, ``--param``, ``--dims``."""

from __future__ import annotations

import re

import click

from meshgen.errors import GeometryError
from meshgen.geometry.blocks import block_spec
from meshgen.geometry.plugins import load_geometry, parse_params

__all__ = ["DimsCommand", "block_nodes_option", "dims_option", "geometry_options", "load_selected_geometry", "parse_dims"]

_DIM_VALUE = re.compile(r"^(-?\d.*|[^-].*)$")  # anything but an option (negative numbers included)
_NUMBER = re.compile(r"^[-+]?[\d.]+([eE][-+]?\d+)?$")


class DimsCommand(click.Command):
    """A command whose ``--dims`` takes two or three values (``--dims 30 30 30``): the values are
    joined into one token before parsing, because click options take a fixed number of values."""

    def parse_args(self, ctx, args):
        joined, i = [], 0
        while i < len(args):
            token = args[i]
            if token == "--dims":
                values = []
                while len(values) < 3 and i + 1 < len(args) and _DIM_VALUE.match(args[i + 1]):
                    values.append(args[i + 1])
                    i += 1
                # A fourth number is a miscount, not an argument: let parse_dims say so.
                while i + 1 < len(args) and _NUMBER.match(args[i + 1]):
                    values.append(args[i + 1])
                    i += 1
                joined += [token, ",".join(values)]
            else:
                joined.append(token)
            i += 1
        return super().parse_args(ctx, joined)


def parse_dims(ctx, param, value):
    """'30,30,30' -> (30, 30, 30): positive integers, two or three of them."""
    if value is None:
        return None
    parts = [p for p in value.split(",") if p]
    if len(parts) not in (2, 3):
        raise click.BadParameter(f"give 2 (2D) or 3 (3D) cell counts, got {len(parts)}: {' '.join(parts) or 'none'}")
    dims = []
    for part in parts:
        try:
            number = int(part)
        except ValueError:
            raise click.BadParameter(f"cell counts must be positive integers, got {part!r}") from None
        if number < 1:
            raise click.BadParameter(f"cell counts must be positive integers, got {part}")
        dims.append(number)
    return tuple(dims)


def dims_option(required=True, help_text="Cells per axis: two numbers (2D) or three (3D), e.g. --dims 30 30 30."):
    return click.option("--dims", callback=parse_dims, required=required, metavar="N N [N]", help=help_text)


def block_nodes_option():
    """``--block-nodes N``: nodes per block of the chunked paths (``meshgen mesh``, ``meshgen evaluate``)."""
    return click.option(
        "--block-nodes",
        type=click.IntRange(min=1024),
        default=None,
        metavar="N",
        help="Nodes per block of the chunked path; peak memory grows with it [default: from the available memory, at "
        "most 1048576].",
    )


def geometry_options(default="semicylinder"):
    """--geometry NAME|FILE.py and repeatable --param name=value."""

    def decorate(function):
        function = click.option(
            "--param",
            "params",
            multiple=True,
            metavar="NAME=VALUE",
            help="Set a geometry parameter (repeatable), e.g. --param radius=2.",
        )(function)
        function = click.option(
            "--geometry",
            "-g",
            default=default,
            show_default=default is not None,
            metavar="NAME|FILE",
            help="Built-in or installed geometry name, a plugin file (.py), or a shape file "
            "(.step .stp .iges .igs .brep .stl .obj .ply, or a .yaml geometry file).",
        )(function)
        return function

    return decorate


def load_selected_geometry(spec, params, dims=None):
    """Load the geometry chosen on the command line; check dims against its dimension. A block set
    is loaded unchecked: its blocks are checked when ``meshgen.run.request.carry_out`` meshes it."""
    geometry = load_geometry(spec, parse_params(params), check=block_spec(spec) is None, dims=dims)
    for line in getattr(geometry.boundary_map, "face_lines", ()):  # a shape file's face assignment
        click.echo(f"{geometry.name}: {line}", err=True)
    if dims is not None and len(dims) != geometry.dim:
        raise GeometryError(
            f"geometry '{geometry.name}' is {geometry.dim}D: --dims needs {geometry.dim} numbers, got {len(dims)}"
        )
    return geometry

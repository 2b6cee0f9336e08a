"""``meshgen mesh`` of a multi-block geometry (``meshgen.blocks``): mesh every block (tfi or
elliptic), write the block set, measure the merged mesh."""

from __future__ import annotations

import sys
import time

import click

from meshgen.blocks import load_block_set, merged_mesh, tfi_blocks
from meshgen.commands._progress import progress_display
from meshgen.commands._text import echo
from meshgen.elliptic_blocks import elliptic_blocks
from meshgen.formats.multiblock import check_block_output, write_blocks
from meshgen.geometry import parse_params
from meshgen.meshing import run_metadata
from meshgen.quality import quality_report, sidecar_path, summary_lines, write_json

__all__ = ["BLOCK_METHODS", "mesh_block_geometry"]

BLOCK_METHODS = ("tfi", "elliptic")


def mesh_block_geometry(method, spec, params, dims, output, format_name, *, tol, max_iter, quality, quiet, unsupported) -> None:
    """The whole ``meshgen mesh`` run of a block set. ``unsupported``: {option: given value} of the
    options that single-block meshes take and block sets do not yet (a usage error when given)."""

    given = [name for name, value in unsupported.items() if value not in (None, False, (), [])]
    if given:
        raise click.UsageError(f"{', '.join(given)}: not available for the multi-block geometry '{spec}'")
    if method == "auto":
        method = "elliptic"
    if method not in BLOCK_METHODS:
        raise click.UsageError(
            f"method '{method}' does not mesh multi-block geometries (methods that do: {', '.join(BLOCK_METHODS)})"
        )
    block_set = load_block_set(spec, parse_params(params), dims)
    output = check_block_output(output, format_name, block_set)
    start = time.perf_counter()
    if method == "tfi":
        Xs, info = tfi_blocks(block_set), {}
    else:
        with progress_display("elliptic mesh", not quiet and sys.stdout.isatty()) as progress:
            Xs, info = elliptic_blocks(block_set, tol=tol, max_iter=max_iter, progress=progress)
    seconds = time.perf_counter() - start
    metadata = {
        **run_metadata(method, block_set, dims),
        "meshing_seconds": seconds,
        "blocks": {name: [len(t) - 1 for t in coords] for name, coords in zip(block_set.names, block_set.coords)},
        **({"method_info": info} if info else {}),
    }
    # The mesh is a block set, not one geometry's structured grid: recorded as such.
    metadata["block_set"] = metadata.pop("geometry")
    metadata["block_dims"] = metadata.pop("dims")
    path = write_blocks(output, block_set, Xs, metadata, format_name)
    report = None
    if quality:
        points, cells, _ = merged_mesh(block_set, Xs)
        report = {"file": str(path), "structured": False, **quality_report((points, cells))}
        write_json(sidecar_path(path), report)
    for line in info.get("warnings", []):
        click.echo(f"Warning: {line}", err=True)
    if quiet:
        return
    echo(
        f"{method} mesh of {block_set.name}: {len(block_set.names)} blocks, {block_set.cells} cells "
        f"(--dims {' '.join(map(str, dims))}: {block_set.dims_meaning}) in {seconds:.2f} s"
    )
    if "sweeps" in info:
        echo(
            f"{info['sweeps']} sweeps, final update {info['final_update']:.2e} ({'converged' if info['converged'] else 'not converged'})"
        )
    echo(f"wrote {path}")
    if report is not None:
        for line in summary_lines(report):
            echo(line)

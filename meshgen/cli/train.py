"""``meshgen train``: train a mesh network (3DMeshNet or an ablation) on a geometry."""

from __future__ import annotations

import shlex

import click

from meshgen.cli._options import geometry_options
from meshgen.cli._text import echo
from meshgen.geometry.extrusion import extrusion_from, extrusion_of
from meshgen.geometry.plugins import looks_like_path
from meshgen.neural.config import list_presets as preset_list
from meshgen.neural.progress import FIELD_HELP
from meshgen.neural.session import prepare_run, run_training
from meshgen.quality import summary_lines

__all__ = ["MESH_HINT", "train"]


MESH_HINT = "meshgen mesh --method neural --checkpoint {checkpoint} --dims {dims} -o mesh.vtu"


def _epilog() -> str:
    """What the figures of the progress line mean (only those the preset uses are shown)."""
    import textwrap

    lines = ["\b", "Progress line: stage, bar, step/total, ETA, then the figures the preset uses:"]
    for name, text in FIELD_HELP.items():
        lines += textwrap.wrap(text, 76, initial_indent=f"  {name:<9}", subsequent_indent=" " * 11)
    return "\n".join(lines)


@click.command("train", epilog=_epilog())
@geometry_options(default=None)
@click.option("--preset", "-p", default=None, metavar="NAME", help="Configuration preset [default: default]; see --list-presets.")
@click.option(
    "--config",
    "config_file",
    type=click.Path(dir_okay=False),
    default=None,
    help="YAML configuration file applied over the preset (a run's config.yaml repeats that run).",
)
@click.option(
    "--set",
    "overrides",
    multiple=True,
    metavar="KEY=VALUE",
    help="Override a configuration key (repeatable), e.g. --set adam.lr=5e-4 --set model.widths=[64,64,64].",
)
@click.option(
    "--steps",
    type=click.IntRange(0),
    default=None,
    help="Adam steps (shortcut for --set adam.steps=N) [default: the preset's adam.steps; default preset: 500].",
)
@click.option(
    "--out",
    type=click.Path(file_okay=False),
    default=None,
    help="Run folder [default: runs/<geometry>-<timestamp>/; with --resume the checkpoint's folder].",
)
@click.option("--resume", type=click.Path(dir_okay=False), default=None, help="Continue training from this checkpoint.")
@click.option(
    "--init",
    type=click.Path(dir_okay=False),
    default=None,
    help="Block sets: start a new run from this checkpoint's weights (same geometry and widths; needs --set pretrain.steps=0).",
)
@click.option(
    "--seed",
    type=int,
    default=None,
    help="Random seed (a CPU run with the same seed and threads repeats exactly) [default: the preset's seed, 0].",
)
@click.option(
    "--device",
    type=click.Choice(["auto", "cpu", "cuda"]),
    default="auto",
    show_default=True,
    help="Where to train; auto picks cuda when available.",
)
@click.option("--threads", type=click.IntRange(1), default=None, help="CPU threads for torch [default: torch's choice].")
@click.option("--quiet", "-q", is_flag=True, help="No progress bar: a log line every tenth of each stage.")
@click.option(
    "--vary",
    "vary",
    multiple=True,
    metavar="NAME=LOW:HIGH",
    help="Train one network for a family of shapes: vary this geometry parameter over [LOW, HIGH] (repeatable), e.g. --vary twist=0:180; the preset defaults to family.",
)
@click.option(
    "--force",
    is_flag=True,
    help="Train into an --out folder that holds a run of another geometry or configuration, replacing it.",
)
@click.option("--list-presets", is_flag=True, help="List the presets with one line each and exit.")
def train(
    geometry,
    params,
    preset,
    config_file,
    overrides,
    steps,
    out,
    resume,
    init,
    seed,
    device,
    threads,
    quiet,
    vary,
    force,
    list_presets,
):
    """Train a network that maps the unit cube onto a geometry (the 3DMeshNet method).

    Writes a run folder holding checkpoint.pt, config.yaml (the resolved configuration),
    history.csv (one row per step) and summary.json (quality of a 30^3 mesh, 2D 30^2, next to TFI's).
    The geometry defaults to semicylinder, or with --resume to the checkpoint's. Ctrl-C saves a
    checkpoint and stops (so do SIGTERM and SIGHUP); --resume continues it. An existing run folder given
    with --out is reused for the same geometry and configuration (else --force); a default folder name
    already taken gets -2, -3 ...
    """
    import os

    # Before torch starts its OpenMP threads: spinning threads make a CPU that other processes
    # share tens of times slower (measured: 386 ms instead of 18 ms per step); the user's own
    # setting wins.
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

    if list_presets:
        presets = preset_list()
        width = max(len(name) for name, _ in presets)
        for name, description in presets:
            click.echo(f"{name:<{width}}  {description}")
        return

    run = prepare_run(
        geometry=geometry,
        params=params,
        preset=preset,
        config_file=config_file,
        overrides=overrides,
        steps=steps,
        out=out,
        resume=resume,
        seed=seed,
        device=device,
        threads=threads,
        vary=vary,
        force=force,
        init=init,
    )
    result = run_training(run, quiet=quiet)
    if result.interrupted:
        click.echo(f"Interrupted at step {result.step} ({result.stage}); checkpoint saved: {result.checkpoint_path}")
        click.echo(f"Continue with: meshgen train --resume {result.checkpoint_path}")
        raise click.exceptions.Exit(130)
    summary = result.summary
    if run.family is not None:
        _family_report(run, result)
        return
    if "family" in summary:
        _wall_family_report(run, result)
        return
    dims = " ".join(str(n) for n in summary["dims"])
    size = " x ".join(str(n) for n in summary["dims"])
    losses = (
        f"held-out misfit of the grid lines' directions {result.test_loss['fit']:.3g}"
        if "fit" in result.test_loss  # a wall-layer model (meshgen.neural.wall_map): fitted, no PDE term
        else f"test-set loss: PDE {result.test_loss['pde']:.3g}, boundary {result.test_loss['boundary']:.3g}"
    )
    echo(f"Trained {run.geometry.name} for {result.step} steps in {result.seconds:.1f} s ({losses})")
    extrusion = extrusion_of(run.block_set) if run.block_set is not None else None
    if extrusion is None and "extruded" in result.checkpoint["model"]:  # a one-block section model
        extrusion = extrusion_from(result.checkpoint["model"]["extruded"])
    if extrusion is not None:
        sweep = ", ".join(f"{v:g}" for v in extrusion.direction)
        echo(f"'{run.geometry.name}' is an extrusion along ({sweep}): the networks map its 2D section (docs/design.md §20)")
    echo(f"Network, {size} mesh:")
    for line in summary_lines(summary["network"]):
        echo(f"  {line}")
    if not run.config.model.exact_boundary:
        corrected = "faces made conforming" if run.block_set is not None else "N + TFI[g - N]"
        echo(f"Network corrected to {corrected} (what meshgen mesh writes), {size} mesh:")
        for line in summary_lines(summary["corrected"]):
            echo(f"  {line}")
    if "elliptic" in summary:  # a wall-layer model: the marched mesh it learned
        echo(f"Elliptic (the marched mesh the network learned), {size} mesh:")
        for line in summary_lines(summary["elliptic"]):
            echo(f"  {line}")
    echo(f"TFI, {size} mesh:")
    for line in summary_lines(summary["tfi"]):
        echo(f"  {line}")
    echo(f"Run folder: {run.run_dir}")
    echo(f"Checkpoint: {result.checkpoint_path}")
    hint = MESH_HINT.format(checkpoint=result.checkpoint_path, dims=dims)
    if geometry and looks_like_path(geometry):  # a file: a checkpoint naming it is trusted only with -g
        hint = hint.replace("meshgen mesh ", f"meshgen mesh -g {shlex.quote(geometry)} ", 1)
    echo("Mesh with: " + hint)


def _family_report(run, result) -> None:
    """What a finished family run prints: the summarised members and how to mesh one."""
    from meshgen.neural.family import range_text
    from meshgen.neural.family_train import summary_table

    family = run.family
    echo(
        f"Trained {family.base.name} over {' '.join(range_text(family.ranges))} for {result.step} steps "
        f"in {result.seconds:.1f} s (test-set PDE loss {result.test_loss['pde']:.3g})"
    )
    for line in summary_table(result.summary):
        echo(line)
    echo(f"Run folder: {run.run_dir}")
    echo(f"Checkpoint: {result.checkpoint_path}")
    member = " ".join(f"--param {name}={value:g}" for name, value in family.middle().items())
    dims = " ".join(["30"] * family.base.dim)
    echo(f"Mesh a member with: meshgen mesh --checkpoint {result.checkpoint_path} {member} --dims {dims} -o mesh.vtu")


def _wall_family_report(run, result) -> None:
    """What a finished family of sections round a wall prints (``meshgen.neural.wall_family``): the
    check of its grid of members against their elliptic meshes, the failing ones named."""
    check, family = result.summary["family"], result.checkpoint["model"]["family"]
    ranges = {n: tuple(r) for n, r in family["ranges"].items()}
    echo(
        f"Trained {run.geometry.name} over {', '.join(f'{n}={lo:g}:{hi:g}' for n, (lo, hi) in ranges.items())} for {result.step} steps in {result.seconds:.1f} s "
        f"(held-out misfit of the grid lines' directions {result.test_loss['fit']:.3g})"
    )
    size, grid = " x ".join(str(n) for n in check["dims"]), " x ".join([str(check["points"])] * len(ranges))
    echo(
        f"Checked {len(check['members'])} members ({grid}, the corners included) at {size}: worst mean min angle "
        f"{check['worst_gap']:.2f} deg below the member's elliptic mesh, "
        f"{sum(m['inverted'] for m in check['members'])} inverted cells; a member's mesh in {check['seconds'] * 1e3:.0f} ms"
    )
    for member in check["failed"]:
        at = ", ".join(f"{k}={v:g}" for k, v in member["params"].items())
        echo(
            f"  FAILED member {at}: {member['inverted']} inverted cells, mean min angle {member['mean_min_angle']:.2f} deg "
            f"(elliptic {member['elliptic_mean_min_angle']:.2f})"
        )
    echo(f"Run folder: {run.run_dir}")
    echo(f"Checkpoint: {result.checkpoint_path}")
    member = " ".join(f"--param {n}={0.5 * (lo + hi):g}" for n, (lo, hi) in ranges.items())
    dims = " ".join(str(n) for n in check["dims"])
    echo(
        f"Mesh a member with: meshgen mesh -g {run.geometry.name} --method neural --checkpoint {result.checkpoint_path} {member} --dims {dims} -o mesh.vtu"
    )

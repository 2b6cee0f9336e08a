"""The ``meshgen`` command group. Each command lives in ``meshgen.cli.<name>`` and is imported
only when it runs, so ``meshgen --help`` stays fast (no torch, no trimesh, no numpy).

Errors a user can act on (MeshgenError, click usage errors, and an OSError that no command
turned into one: a full disk, no permission) are printed as one line with exit status 2; Ctrl-C
exits with status 130, SIGTERM and SIGHUP (unwound like Ctrl-C: ``meshgen.run.signals``) with 128 + the
signal's number. Set MESHGEN_DEBUG=1 to see tracebacks.
"""

from __future__ import annotations

import importlib
import os
import sys

import click

from meshgen import __version__
from meshgen.errors import MeshgenError, ParameterError, did_you_mean, excerpt
from meshgen.run.early import EARLY_STARTS, start_early
from meshgen.run.quick_exit import exit_quickly
from meshgen.run.signals import Terminated, exit_interrupted, install_termination_handlers

__all__ = [
    "COMMANDS",
    "EARLY_STARTS",
    "FLAGS",
    "MAX_ERROR_CHARS",
    "MeshgenGroup",
    "QUICK_EXITS",
    "cli",
    "flag_of",
    "main",
    "message_for_command_line",
    "one_line",
    "start_early",
]

# name -> (module:function, one-line help). The help is kept here so listing commands imports nothing.
COMMANDS = {
    "train": ("meshgen.cli.train:train", "Train a mesh network (3DMeshNet and ablations) on a geometry."),
    "mesh": ("meshgen.cli.mesh:mesh", "Make a mesh (tfi, elliptic or a trained network) and write it."),
    "evaluate": ("meshgen.cli.evaluate:evaluate", "Measure mesh quality; gate it with --fail-if."),
    "compare": ("meshgen.cli.compare:compare", "Compare meshing methods side by side."),
    "geometries": ("meshgen.cli.geometries:geometries", "List geometries; show one as a surface."),
}


# Commands whose process ends without the interpreter's teardown (``meshgen.run.quick_exit``): by
# the exit their output is written and flushed, and nothing runs after them.
QUICK_EXITS = frozenset({"evaluate"})

# The longest error line printed: a message that quotes a file's contents is cut here at the latest.
MAX_ERROR_CHARS = 600


def one_line(message: str) -> str:
    """``message`` on one line, at most ``MAX_ERROR_CHARS`` characters."""
    return excerpt(message, MAX_ERROR_CHARS)


# Library parameters whose flag is not their name with dashes.
FLAGS = {"overrides": "--set"}


def flag_of(parameter: str) -> str:
    """The command-line flag of a library parameter: ``max_iter`` -> ``--max-iter``."""
    return FLAGS.get(parameter, "--" + parameter.replace("_", "-"))


def message_for_command_line(exc) -> str:
    """A library error as the command line words it: a ParameterError names the flag
    (``--tol must be positive``) where the library names the parameter (``tol must be positive``)."""
    return exc.message_for(flag_of(exc.parameter)) if isinstance(exc, ParameterError) else str(exc)


class MeshgenGroup(click.Group):
    def list_commands(self, ctx):
        return list(COMMANDS)

    def get_command(self, ctx, name):
        if name not in COMMANDS:
            return None
        module_name, function_name = COMMANDS[name][0].split(":")
        return getattr(importlib.import_module(module_name), function_name)

    def format_commands(self, ctx, formatter):
        with formatter.section("Commands"):
            formatter.write_dl([(name, help_text) for name, (_, help_text) in COMMANDS.items()])

    def resolve_command(self, ctx, args):
        name = args[0] if args else None
        if name is not None and name not in COMMANDS and not name.startswith("-"):
            hint = did_you_mean(name, COMMANDS)
            raise click.UsageError(f"no command '{name}' (commands: {', '.join(COMMANDS)}){hint}", ctx)
        return super().resolve_command(ctx, args)

    def main(self, args=None, prog_name=None, **extra):
        """Run with our own error reporting: one line on stderr, exit 2 for usage errors. With no
        arguments at all, print the help (exit 0), not an error."""
        extra.pop("standalone_mode", None)
        if args is None:
            args = sys.argv[1:]
        if not args:
            args = ["--help"]
        debug = bool(os.environ.get("MESHGEN_DEBUG"))
        try:
            result = super().main(args=args, prog_name=prog_name or "meshgen", standalone_mode=False, **extra)
        except click.exceptions.Exit as exc:  # 130: a training stopped by Ctrl-C after its checkpoint
            (exit_interrupted if exc.exit_code == 130 else sys.exit)(exc.exit_code)
        except click.exceptions.Abort:
            click.echo("Aborted.", err=True)
            exit_interrupted(130)
        except click.UsageError as exc:
            if debug:
                raise
            command = exc.ctx.command_path if exc.ctx else "meshgen"
            click.echo(f"Error: {one_line(exc.format_message())} (see '{command} --help')", err=True)
            sys.exit(2)
        except click.ClickException as exc:
            if debug:
                raise
            click.echo(f"Error: {one_line(exc.format_message())}", err=True)
            sys.exit(exc.exit_code)
        except MeshgenError as exc:
            if debug:
                raise
            click.echo(f"Error: {one_line(message_for_command_line(exc))}", err=True)
            sys.exit(2)
        except Terminated as exc:  # SIGTERM, SIGHUP: unwound like Ctrl-C, every write cleaned up
            click.echo(f"Terminated ({exc}).", err=True)
            exit_interrupted(128 + exc.signum)
        except KeyboardInterrupt:
            click.echo("Interrupted.", err=True)
            exit_interrupted(130)
        except BrokenPipeError:
            sys.exit(1)
        except OSError as exc:  # the machine, not meshgen: a full disk, no permission, a vanished file
            if debug:
                raise
            where = f" ({exc.filename})" if exc.filename else ""
            click.echo(f"Error: {one_line(exc.strerror or exc)}{where}", err=True)
            sys.exit(2)
        except Exception as exc:  # a bug of ours: still one line, the traceback on request
            if debug:
                raise
            click.echo(
                f"Error: internal error {type(exc).__name__}: {one_line(exc)} (set MESHGEN_DEBUG=1 for a traceback)",
                err=True,
            )
            sys.exit(1)
        sys.exit(result if isinstance(result, int) else 0)


@click.group(cls=MeshgenGroup, context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(__version__, "--version", prog_name="meshgen")
def cli():
    """meshgen: structured hexahedral and quadrilateral meshes of parametrised geometries.

    Methods: transfinite interpolation (tfi), an elliptic Winslow solver (elliptic), and a network
    trained on the Winslow equations (3DMeshNet), which meshes at any size in one forward pass.
    """


def main():
    # Before torch starts its OpenMP threads (train, compare's neural rows, neural meshes): spinning
    # threads make a CPU that other processes share tens of times slower; the user's setting wins.
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    install_termination_handlers()
    start_early(sys.argv[1:])
    try:
        cli.main()
    except SystemExit as exc:  # the process's own command line only: cli.main() called in a program returns to it
        if sys.argv[1:2] and sys.argv[1] in QUICK_EXITS and isinstance(exc.code, (int, type(None))):
            exit_quickly(exc.code or 0)
        raise

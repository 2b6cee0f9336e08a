"""What a file may name: the trust boundary between data and code (design notes, "Trust boundary
and faults").

A geometry plugin file is Python code. meshgen runs one only when the user names it: on the
command line (``-g PATH``) or from Python (``load_geometry(PATH)``). A geometry named by the
contents of a file (a mesh's metadata, a ``.quality.json`` sidecar, a checkpoint's
``geometry.spec``) is resolved only among the built-in geometries and installed entry points,
unless the very same plugin file was given by the user in this process. A plugin's ``name``
becomes part of file names (run folders, layout caches), so it is a plain identifier, never a path.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from meshgen.errors import GeometryError, excerpt

__all__ = [
    "NAME_PATTERN",
    "UntrustedGeometry",
    "check_plugin_name",
    "is_given_plugin",
    "note_given_plugin",
    "recorded_spec",
]

# A plugin name: letters, digits, '_' and '-', starting with a letter or digit; at most 64 characters.
NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_-]{0,63}")

_GIVEN_PLUGIN_FILES: set[str] = set()  # resolved paths of plugin files the user named in this process


class UntrustedGeometry(GeometryError):
    """A file names a plugin file as its geometry; meshgen does not run code a file names."""


def note_given_plugin(path: str | os.PathLike) -> None:
    """Record that the user named the plugin file ``path`` (command line or Python)."""
    _GIVEN_PLUGIN_FILES.add(str(Path(path).resolve()))


def is_given_plugin(path: str | os.PathLike) -> bool:
    """Whether the user named the plugin file ``path`` in this process."""
    try:
        return str(Path(path).resolve()) in _GIVEN_PLUGIN_FILES
    except (OSError, ValueError, RuntimeError):
        return False


def check_plugin_name(name, source: str) -> str:
    """``name`` when it is a plain identifier (``NAME_PATTERN``), else GeometryError: a name
    becomes part of file names and must never reach outside the folder it is put in."""
    if not isinstance(name, str) or not NAME_PATTERN.fullmatch(name):
        raise GeometryError(
            f"geometry plugin {source}: 'name' must be 1 to 64 letters, digits, '_' or '-' "
            f"(starting with a letter or digit), got {excerpt(repr(name))}"
        )
    return name


def recorded_spec(spec, where: str) -> str:
    """The geometry spec to load for ``spec`` as recorded in a file (``where`` says which, e.g.
    "checkpoint run/checkpoint.pt"): a geometry name, or a plugin path the user gave in this
    process. Any other path raises UntrustedGeometry, which asks for ``-g PATH``."""
    if not isinstance(spec, str) or not spec:
        raise GeometryError(f"{where} records no usable geometry ({excerpt(repr(spec))})")
    if NAME_PATTERN.fullmatch(spec):
        return spec  # looked up among built-ins and entry points only
    if is_given_plugin(spec):
        return spec
    raise UntrustedGeometry(
        f"{where} names the geometry file {excerpt(spec, tail=True)}; a geometry named by a file is only looked up among "
        f"built-in and installed geometries (a file never makes meshgen run or read another): pass -g PATH to use it"
    )

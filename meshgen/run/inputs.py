"""Input files, opened defensively (design notes, "Trust boundary and faults").

Every file meshgen reads is a regular file: a FIFO would block the reader forever, a device such
as ``/dev/zero`` (or a link to one) would be read until memory runs out. ``check_input_file``
says so before a library (h5py, meshio, torch, VTK) is handed the path; ``read_input_bytes`` and
``read_input_text`` open the file without blocking, check what was opened (not only what the path
named a moment before) and read at most a limit. ``load_yaml`` reads YAML with limits: no aliases
(an alias bomb expands a few hundred bytes into gigabytes), bounded nesting and size.
"""

from __future__ import annotations

import os
import stat
from pathlib import Path

from meshgen.errors import MeshgenError

__all__ = [
    "MAX_TEXT_BYTES",
    "MAX_YAML_BYTES",
    "MAX_YAML_DEPTH",
    "InputError",
    "check_input_file",
    "load_yaml",
    "read_input_bytes",
    "read_input_text",
]

MAX_TEXT_BYTES = 256 * 2**20  # a sidecar, a history, an OpenFOAM list read whole
MAX_YAML_BYTES = 2**20  # a configuration file: a few kB in practice
MAX_YAML_DEPTH = 32  # nested mappings and lists


class InputError(MeshgenError):
    """An input file is missing, not a regular file, too large, or not what it should be."""


def _kind(mode: int) -> str:
    for test, name in (
        (stat.S_ISDIR, "a folder"),
        (stat.S_ISFIFO, "a FIFO"),
        (stat.S_ISCHR, "a character device"),
        (stat.S_ISBLK, "a block device"),
        (stat.S_ISSOCK, "a socket"),
    ):
        if test(mode):
            return name
    return "not a regular file"


def check_input_file(path, what: str = "input file", folder: bool = False) -> Path:
    """``path`` when it names a regular file (links followed), or with ``folder`` a folder; else
    InputError. Reads nothing, so it never blocks."""
    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        raise InputError(f"{what} {path} cannot be read: it does not exist") from None
    except OSError as exc:
        raise InputError(f"{what} {path} cannot be read: {exc.strerror or exc}") from None
    if stat.S_ISREG(mode) or (folder and stat.S_ISDIR(mode)):
        return path
    raise InputError(f"{what} {path} is {_kind(mode)}: meshgen reads regular files only")


def read_input_bytes(path, what: str = "input file", limit: int = MAX_TEXT_BYTES) -> bytes:
    """The bytes of the regular file ``path``, at most ``limit`` of them (InputError beyond)."""
    path = check_input_file(path, what)
    try:
        descriptor = os.open(path, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_NOCTTY", 0))
    except OSError as exc:
        raise InputError(f"{what} {path} cannot be read: {exc.strerror or exc}") from None
    with os.fdopen(descriptor, "rb") as handle:
        opened = os.fstat(descriptor)
        if not stat.S_ISREG(opened.st_mode):  # swapped after the check: what was opened counts
            raise InputError(f"{what} {path} is {_kind(opened.st_mode)}: meshgen reads regular files only")
        if opened.st_size > limit:
            raise InputError(f"{what} {path} is larger than {limit} bytes: not a file meshgen reads whole")
        data = handle.read(opened.st_size + 1)  # one byte more: a file that grew meanwhile is seen
    if len(data) > limit:
        raise InputError(f"{what} {path} is larger than {limit} bytes: not a file meshgen reads whole")
    return data


def read_input_text(path, what: str = "input file", limit: int = MAX_TEXT_BYTES) -> str:
    """The UTF-8 text of the regular file ``path`` (``read_input_bytes``); InputError if not text."""
    data = read_input_bytes(path, what, limit)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise InputError(f"{what} {path} is not a text file (not UTF-8)") from None


def load_yaml(text: str, what: str):
    """``text`` parsed by YAML's safe loader with limits: at most ``MAX_YAML_BYTES``, no aliases
    or anchors, at most ``MAX_YAML_DEPTH`` levels of nesting. InputError otherwise (the message
    quotes at most a short excerpt); yaml.YAMLError for malformed YAML (the caller words it)."""
    import yaml

    if len(text.encode("utf-8", "replace")) > MAX_YAML_BYTES:
        raise InputError(f"{what} is larger than {MAX_YAML_BYTES} bytes: not a configuration file")
    depth = 0
    for event in yaml.parse(text, Loader=yaml.SafeLoader):
        if isinstance(event, yaml.AliasEvent) or getattr(event, "anchor", None) is not None:
            where = f" at line {event.start_mark.line + 1}" if event.start_mark else ""
            raise InputError(f"{what} uses a YAML anchor or alias{where}: meshgen reads plain YAML without them")
        if isinstance(event, (yaml.MappingStartEvent, yaml.SequenceStartEvent)):
            depth += 1
            if depth > MAX_YAML_DEPTH:
                raise InputError(f"{what} nests deeper than {MAX_YAML_DEPTH} levels: not a configuration file")
        elif isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
            depth -= 1
    return yaml.safe_load(text)

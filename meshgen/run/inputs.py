"""Input files, opened defensively (design notes, "Trust boundary and faults").

Every file meshgen reads is a regular file: a FIFO would block the reader forever, a device such
as ``/dev/zero`` (or a link to one) would be read until memory runs out. ``check_input_file``
says so before a library (h5py, meshio, torch, VTK) is handed the path; ``read_input_bytes`` and
``read_input_text`` open the file without blocking, check what was opened (not only what the path
named a moment before) and read at most a limit. ``load_yaml`` reads YAML with limits: no aliases
(an alias bomb expands a few hundred bytes into gigabytes), bounded nesting and size;
``load_yaml_file`` reads a YAML file (``--config``, a geometry file) that way. ``named_input_file``
is the one way to follow a name written inside an input file (a geometry file's surface files):
the same regular-file check. ``inflate`` decompresses a zlib stream without ever producing more
than the size its file declared (a few kB can inflate to gigabytes).
"""

from __future__ import annotations

import os
import stat
import zlib
from pathlib import Path

from isal import isal_zlib

from meshgen.errors import MeshgenError

__all__ = [
    "MAX_DEFLATE_RATIO",
    "MAX_TEXT_BYTES",
    "MAX_YAML_BYTES",
    "MAX_YAML_DEPTH",
    "InputError",
    "check_input_file",
    "inflate",
    "load_yaml",
    "load_yaml_file",
    "named_input_file",
    "read_input_bytes",
    "read_input_text",
]

MAX_TEXT_BYTES = 256 * 2**20  # a sidecar, a history, an OpenFOAM list read whole
MAX_YAML_BYTES = 2**20  # a configuration file: a few kB in practice
MAX_YAML_DEPTH = 32  # nested mappings and lists
MAX_DEFLATE_RATIO = 1032  # deflate (zlib, gzip) never inflates a byte to more than this many


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


def _problem(path: Path, folder: bool = False) -> str | None:
    """What keeps meshgen from reading ``path`` (links followed), or None for a regular file (or,
    with ``folder``, a folder). Reads nothing, so it never blocks."""
    try:
        mode = os.stat(path).st_mode
    except FileNotFoundError:
        return "does not exist"
    except OSError as exc:
        return f"cannot be read: {exc.strerror or exc}"
    if stat.S_ISREG(mode) or (folder and stat.S_ISDIR(mode)):
        return None
    return f"is {_kind(mode)}: meshgen reads regular files only"


def check_input_file(path, what: str = "input file", folder: bool = False) -> Path:
    """``path`` when it names a regular file (links followed), or with ``folder`` a folder; else
    InputError. Reads nothing, so it never blocks."""
    path = Path(path)
    problem = _problem(path, folder)
    if problem == "does not exist":
        problem = "cannot be read: it does not exist"
    if problem is not None:
        raise InputError(f"{what} {path} {problem}")
    return path


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


def load_yaml_file(path, what: str):
    """The YAML file ``path`` read as ``read_input_text`` does (at most ``MAX_YAML_BYTES``) and
    parsed by ``load_yaml`` (no aliases, bounded nesting)."""
    return load_yaml(read_input_text(path, what, MAX_YAML_BYTES), f"{what} {path}")


def named_input_file(base, name, what: str) -> Path:
    """The file ``name`` (relative to the folder ``base``) that an input file names, through the
    check of ``check_input_file`` (a name inside a file is as untrusted as the file); the message
    is ``what`` followed by the problem."""
    if not isinstance(name, str) or not name or "\0" in name:
        raise InputError(f"{what} is not a file name")
    path = (Path(base) / name).expanduser()
    problem = _problem(path)
    if problem is not None:
        raise InputError(f"{what} {problem}")
    return path


def inflate(data, size: int, what: str) -> bytes:
    """The zlib stream ``data`` inflated to exactly ``size`` bytes, the size its file declares:
    InputError, before more than ``size`` bytes are produced, when it inflates to more (a stream
    of a few MB can inflate to gigabytes), to fewer, or is not zlib data. Inflated by ISA-L (the
    same bytes as zlib's, a stream's inflation being unique; 40% less CPU), a stream ISA-L
    refuses by zlib, whose verdict and message stand."""
    limit = max(int(size), 0) + 1
    decompressor = isal_zlib.decompressobj()
    try:
        out = decompressor.decompress(data, limit)
    except isal_zlib.error:
        decompressor = zlib.decompressobj()
        try:
            out = decompressor.decompress(data, limit)
        except zlib.error as exc:
            raise InputError(f"{what} is not a zlib stream ({exc})") from None
    if len(out) > size or decompressor.unconsumed_tail:
        raise InputError(f"{what} inflates to more than the {size} bytes its file declares")
    if len(out) < size:
        raise InputError(f"{what} inflates to {len(out)} bytes, not the {size} its file declares")
    return out

"""Atomic file replacement: write to a new temporary in the target folder (its name carries the
pid and a random token; made with ``O_EXCL | O_NOFOLLOW``: ``meshgen.run.publish.temporary_path``),
then rename, so an interrupted or failed write never leaves a partial file under the real name and keeps the old one. Inside a publication
(``meshgen.run.publish.publishing``) the rename waits for the publication's end, so a mesh and its
sidecar take their names together."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

from meshgen.errors import FormatError, MeshgenError
from meshgen.run.publish import (
    TEMPORARY_PATTERN,
    current_publication,
    reason,
    remove_path,
    remove_stale_temporaries,
    replace_into,
    temporary_path,
)

__all__ = ["atomic_path", "atomic_write", "check_output_file", "check_pieces_folder"]


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike, keep_existing: bool = False, folder: bool = False):
    """Yield a new temporary beside ``target`` (same suffix; ``meshgen.run.publish.temporary_path``:
    an empty file the caller writes over, or with ``folder`` an empty folder it fills); on success it replaces ``target``, on any exception (also KeyboardInterrupt, SIGTERM)
    it is removed and ``target`` is untouched. ``keep_existing``: an existing ``target`` wins (the
    temporary is dropped). Temporaries of ``target`` left by processes that are gone are removed
    first. Inside a publication the rename happens when the publication ends."""
    target = Path(target)
    remove_stale_temporaries(target.parent, target)
    temporary = temporary_path(target, folder)
    publication = current_publication()
    try:
        yield temporary
        if not os.path.lexists(temporary):
            raise OSError(f"nothing was written to {temporary}")
        if publication is not None:
            publication.stage(temporary, target, keep_existing)
        elif keep_existing and os.path.lexists(target):
            remove_path(temporary)
        else:
            aside = replace_into(temporary, target)
            if aside is not None:
                remove_path(aside)
    except BaseException:
        with contextlib.suppress(OSError):
            remove_path(temporary)
        raise


@contextlib.contextmanager
def atomic_write(target: str | os.PathLike, error=None, what: str = ""):
    """``atomic_path`` for a file meshgen writes for the user: an OSError (a full disk, no
    permission) or a library's RuntimeError (h5py's and torch's way to report one) becomes
    ``error`` (default MeshgenError), one line ``could not write <what><target>: <reason>``, and
    the previous file is kept."""
    try:
        with atomic_path(target) as temporary:
            yield temporary
    except (OSError, RuntimeError) as exc:
        raise (error or MeshgenError)(f"could not write {what}{target}: {reason(exc)}") from exc


def check_output_file(path: str | os.PathLike, example_name: str) -> Path:
    """Validate an output file path before any work is done: not a folder, inside an existing,
    writable folder. ``example_name`` (e.g. "mesh.vtu") is suggested when ``path`` is a folder.
    Raises MeshgenError; returns the path."""
    path = Path(path)
    if path.is_dir():
        raise MeshgenError(f"output {path} is a folder; give a file name such as {path / example_name}")
    folder = path.parent if str(path.parent) else Path(".")
    if folder.exists() and not folder.is_dir():
        raise MeshgenError(f"output folder {folder} is not a folder")
    if not folder.is_dir():
        raise MeshgenError(f"output folder {folder} does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise MeshgenError(f"output folder {folder} is not writable")
    return path


def check_pieces_folder(path: str | os.PathLike, is_piece, pieces: str) -> None:
    """FormatError when the folder ``<name>/`` beside ``path`` (where a .pvts or .vtm writes its
    pieces) exists and is not that file's own pieces folder: a link, not a folder, or holding an
    entry that ``is_piece(entry name)`` does not claim (meshgen's own temporaries aside). Writing
    would replace a file of the user's. ``pieces`` says what the pieces are called."""
    folder = Path(path).with_suffix("")
    if not os.path.lexists(folder):
        return
    if (
        folder.is_symlink()
        or not folder.is_dir()
        or any(not (is_piece(entry.name) or TEMPORARY_PATTERN.match(entry.name)) for entry in os.scandir(folder))
    ):
        raise FormatError(f"{folder} exists and is not the pieces folder of {Path(path).name} ({pieces}): pick another name")

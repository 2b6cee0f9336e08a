"""Atomic file replacement: write to a temporary name in the target folder, then rename, so an
interrupted or failed write never leaves a partial file under the real name and keeps the old one."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

from meshgen.errors import MeshgenError

__all__ = ["atomic_path", "atomic_write", "check_output_file"]


@contextlib.contextmanager
def atomic_path(target: str | os.PathLike):
    """Yield a temporary path beside ``target`` (same suffix); on success it replaces ``target``,
    on any exception (also KeyboardInterrupt) it is removed and ``target`` is untouched."""
    target = Path(target)
    temporary = target.with_name(f".{target.stem}.tmp-{os.getpid()}{target.suffix}")
    try:
        yield temporary
        if not temporary.exists():
            raise OSError(f"nothing was written to {temporary}")
        os.replace(temporary, target)
    except BaseException:
        with contextlib.suppress(OSError):
            temporary.unlink()
        raise


@contextlib.contextmanager
def atomic_write(target: str | os.PathLike, error=None, what: str = ""):
    """``atomic_path`` for a file meshgen writes for the user: an OSError (a full disk, no
    permission) becomes ``error`` (default MeshgenError), one line ``could not write <what><target>:
    <reason>``, and the previous file is kept."""
    try:
        with atomic_path(target) as temporary:
            yield temporary
    except OSError as exc:
        raise (error or MeshgenError)(f"could not write {what}{target}: {exc.strerror or exc}") from exc


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

"""Atomic file replacement: write to a temporary name in the target folder, then rename, so an
interrupted or failed write never leaves a partial file under the real name and keeps the old one."""

from __future__ import annotations

import contextlib
import os
from pathlib import Path


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

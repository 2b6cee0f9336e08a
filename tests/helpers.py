"""Helpers shared by several test files (one copy each)."""

from __future__ import annotations

from pathlib import Path

__all__ = ["files_in"]


def files_in(folder: Path, skip=()) -> dict:
    """Every file under ``folder`` with its bytes and every folder with None, by relative path:
    two calls compare equal only if nothing was created, removed or changed. Python's bytecode
    caches, names in ``skip`` and a test's own ``stalled*`` markers are left out."""
    return {
        str(p.relative_to(folder)): p.read_bytes() if p.is_file() else None
        for p in sorted(Path(folder).rglob("*"))
        if "__pycache__" not in p.parts and p.name not in skip and not p.name.startswith("stalled")
    }

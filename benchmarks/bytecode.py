"""meshgen's bytecode, compiled before its commands are timed in subprocesses.

A user's meshgen starts from compiled bytecode: pip compiles it when it installs the package, and
Python keeps it in ``__pycache__`` after a module's first import. These machines set
``PYTHONDONTWRITEBYTECODE=1``, under which a source checkout never gets it and every start
compiles meshgen's hundred-odd modules from source again (about 0.15 s of ``meshgen evaluate``
here, and as much again in its forked worker). ``compile_bytecode()`` compiles them once
(``compileall``: an up-to-date file is left alone), so a timed command starts as a user's does.
"""

from __future__ import annotations

import compileall
import os
from pathlib import Path

__all__ = ["compile_bytecode"]

ROOT = Path(__file__).resolve().parents[1]


def compile_bytecode() -> dict:
    """Compile ``meshgen/`` and ``geometries/`` to bytecode where it is missing or stale; what was
    done, for the benchmark's JSON."""
    done = all(compileall.compile_dir(ROOT / folder, quiet=1) for folder in ("meshgen", "geometries"))
    return {
        "bytecode": "compiled" if done else "compiling failed",
        "python_dont_write_bytecode": bool(os.environ.get("PYTHONDONTWRITEBYTECODE")),
    }

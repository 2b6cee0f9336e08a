"""``meshgen.run.early``: what a command starts before click parses it (the cyclic garbage
collector paused until the command's body resumes it), and that the module needs nothing but the
standard library (``python -m meshgen`` imports it first)."""

from __future__ import annotations

import gc
import subprocess
import sys

from meshgen.run import early


def test_the_collector_is_paused_by_an_early_start_until_resumed(monkeypatch):
    monkeypatch.setitem(early.EARLY_STARTS, "probe", "gc:collect")  # a harmless early start
    monkeypatch.setattr(early, "_collection_paused", False)
    try:
        early.start_early(["probe", "--help"])  # help: nothing starts, nothing pauses
        assert gc.isenabled()
        early.start_early(["probe", "file.vts"])
        assert not gc.isenabled()
        early.resume_collection()
        assert gc.isenabled()
        early.resume_collection()  # once only: a collector the user turned off stays off
        gc.disable()
        early.resume_collection()
        assert not gc.isenabled()
    finally:
        gc.enable()


def test_other_commands_start_nothing_early():
    try:
        early.start_early(["geometries", "--json"])
        assert gc.isenabled() and "geometries" not in early.EARLY_STARTS
    finally:
        gc.enable()


def test_the_module_imports_only_the_standard_library():
    code = "import sys; before = set(sys.modules); import meshgen.run.early; print(sorted(set(sys.modules) - before))"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=60)
    new = eval(done.stdout)  # noqa: S307 - our own subprocess's list of module names
    assert all(name.split(".")[0] in sys.stdlib_module_names or name.startswith("meshgen") for name in new), new
    assert not [
        name for name in new if name.startswith("meshgen") and name not in ("meshgen", "meshgen.run", "meshgen.run.early")
    ]

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from meshgen.geometry.plugins import load_geometry

REPO = Path(__file__).resolve().parents[1]
HANDLED_SIGNALS = [getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name)]


@pytest.fixture
def run_cli(tmp_path):
    """Run ``meshgen ARGS`` through the command line's own entry (``meshgen.cli.cli``, its error
    reporting and exit statuses included) in this process, in tmp_path by default, with ``env``
    added to the environment for the call. Returns a ``CompletedProcess`` (``returncode``, text
    ``stdout`` and ``stderr``). In-process runs skip the interpreter start and the imports (torch,
    numba) a subprocess pays each time; tests about the process itself (signals, imports,
    concurrency) use ``run_cli_process``."""

    def run(*args, cwd=None, env=None, timeout=None):
        from click.testing import CliRunner

        from meshgen.cli import cli

        arguments = list(map(str, args))
        environment = {"MESHGEN_DEBUG": None, **(env or {})}
        handlers = {signum: signal.getsignal(signum) for signum in HANDLED_SIGNALS}
        folder = os.getcwd()
        os.chdir(cwd or tmp_path)
        try:
            result = CliRunner(env=environment).invoke(cli, arguments, prog_name="meshgen")
        finally:
            os.chdir(folder)
            for signum, handler in handlers.items():
                signal.signal(signum, handler)
        if result.exception is not None and not isinstance(result.exception, SystemExit):
            raise result.exception  # a bug the CLI did not turn into a message
        return subprocess.CompletedProcess(["meshgen", *arguments], result.exit_code, result.stdout, result.stderr)

    return run


@pytest.fixture
def run_cli_process(tmp_path):
    """Run ``python -m meshgen ARGS`` in a subprocess (this checkout's code), in tmp_path by default.
    Returns the CompletedProcess with text stdout/stderr."""

    def run(*args, cwd=None, env=None, timeout=600):
        environment = {**os.environ, "PYTHONPATH": str(REPO), **(env or {})}
        environment.pop("MESHGEN_DEBUG", None)
        return subprocess.run(
            [sys.executable, "-m", "meshgen", *map(str, args)],
            cwd=cwd or tmp_path,
            env=environment,
            capture_output=True,
            text=True,
            timeout=timeout,
        )

    return run


@pytest.fixture(autouse=True, scope="session")
def _subprocesses_run_this_checkout():
    """Every ``python -m meshgen`` a test starts (fixtures, examples, helpers) imports this
    checkout's code, whatever an editable install elsewhere points at."""
    previous = os.environ.get("PYTHONPATH")
    os.environ["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), previous]))
    yield
    if previous is None:
        os.environ.pop("PYTHONPATH", None)
    else:
        os.environ["PYTHONPATH"] = previous


@pytest.fixture(scope="session")
def semidisk():
    return load_geometry("semidisk")


@pytest.fixture(scope="session")
def semicylinder():
    return load_geometry("semicylinder")


@pytest.fixture(autouse=True)
def _work_in_tmp_path(tmp_path, monkeypatch):
    """Every test runs in its own temporary folder, so a command that writes beside the working
    directory (``meshgen mesh -o m.vtu`` and its ``m.vtu.quality.json``) never writes into the
    checkout."""
    monkeypatch.chdir(tmp_path)


@pytest.fixture(autouse=True, scope="session")
def _layout_cache_in_tmp(tmp_path_factory):
    """The boundary-layout cache (``meshgen.geometry.layout.cache_path``) of the whole session, commands run
    by ``run_cli`` included, in a temporary folder rather than the user's ~/.cache; the parallel
    workers of one run (``-n 2``) share it, so each layout is solved once."""
    previous = os.environ.get("MESHGEN_CACHE_DIR")
    if os.environ.get("PYTEST_XDIST_WORKER"):  # workers of one run share a cache (its writes are atomic)
        cache = tmp_path_factory.getbasetemp().parent / "layout-cache"
        cache.mkdir(exist_ok=True)
    else:
        cache = tmp_path_factory.mktemp("cache")
    os.environ["MESHGEN_CACHE_DIR"] = str(cache)
    yield
    if previous is None:
        os.environ.pop("MESHGEN_CACHE_DIR", None)
    else:
        os.environ["MESHGEN_CACHE_DIR"] = previous


TOOL_MARKERS = {  # marker -> words in a skip reason that name the tool the test runs
    "needs_openfoam": ("openfoam", "checkmesh", "potentialfoam"),
    "needs_gmsh": ("gmsh",),
    "needs_cgnscheck": ("cgnscheck", "cgns-convert"),
}


def pytest_collection_modifyitems(items):
    """Mark the tests that run an external tool (``-m needs_openfoam`` and so on), read from the
    skip condition each such test carries; the skip itself stays where the test declares it."""
    for item in items:
        reasons = " ".join(str(mark.kwargs.get("reason", "")) for mark in item.iter_markers("skipif")).lower()
        for marker, words in TOOL_MARKERS.items():
            if any(word in reasons for word in words):
                item.add_marker(marker)


@pytest.fixture
def children():
    """Child processes a test starts; any still running at its end (a failed test) are killed."""
    started = []
    yield started
    for process in started:
        if process.poll() is None:
            process.kill()
            process.communicate()

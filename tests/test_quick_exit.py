"""``meshgen evaluate`` ends without the interpreter's teardown (``meshgen.run.quick_exit``): its
files and output are all there, its exit status is the command's, ``atexit`` handlers still run,
and ``cli.main()`` called inside a program still returns to it by ``SystemExit``."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from click.testing import CliRunner

from meshgen.cli import QUICK_EXITS, cli
from meshgen.formats import write_mesh

# ``meshgen`` in a new interpreter; an atexit handler of the program's says it ran, and the
# interpreter's teardown would say so too (a module-level object's __del__), which a quick exit skips.
DRIVER = """
import atexit, sys
atexit.register(lambda: print("atexit ran", file=sys.stderr, flush=True))
class Goodbye:
    def __del__(self):
        print("teardown ran", file=sys.stderr, flush=True)
goodbye = Goodbye()
from meshgen.cli import main
sys.argv = ["meshgen", *sys.argv[1:]]
main()
"""


def run(*arguments) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", DRIVER, *map(str, arguments)], capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def vts(tmp_path_factory):
    axes = [np.linspace(0.0, 1.0, 6)] * 3
    path = tmp_path_factory.mktemp("quick") / "box.vts"
    write_mesh(path, np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1))
    return path


def test_evaluate_writes_everything_and_skips_only_the_teardown(vts, tmp_path):
    report, table = tmp_path / "report.json", tmp_path / "report.md"
    result = run("evaluate", vts, "--json", report, "--markdown", table)
    assert result.returncode == 0, result.stderr
    assert json.loads(report.read_text())["cells"] == 125 and "min angle" in table.read_text()
    assert "atexit ran" in result.stderr and "teardown ran" not in result.stderr


def test_a_tripped_gate_keeps_its_exit_status_and_message(vts):
    result = run("evaluate", vts, "--json", "-", "--fail-if", "min_angle.min<100")
    assert result.returncode == 1
    assert json.loads(result.stdout)["cells"] == 125 and "FAILED" in result.stderr


def test_an_error_keeps_its_exit_status_and_one_line(tmp_path):
    result = run("evaluate", tmp_path / "missing.vts")
    assert result.returncode == 2 and result.stderr.count("Error:") == 1


def test_other_commands_exit_as_python_does():
    assert "geometries" not in QUICK_EXITS
    result = run("geometries", "--json")
    assert result.returncode == 0 and "teardown ran" in result.stderr


def test_called_in_a_program_evaluate_returns_by_system_exit(vts):
    # click's runner calls cli.main() in this process: no quick exit may end it
    result = CliRunner().invoke(cli, ["evaluate", str(vts), "--json", "-"])
    assert result.exit_code == 0 and json.loads(result.stdout)["cells"] == 125


def test_a_thread_still_working_finishes_first():
    code = (
        "import threading, time\n"
        "from meshgen.run.quick_exit import exit_quickly\n"
        "threading.Thread(target=lambda: (time.sleep(0.5), print('thread done', flush=True))).start()\n"
        "exit_quickly(3)\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert result.returncode == 3 and "thread done" in result.stdout


def test_exit_quickly_exits_with_the_status():
    code = "from meshgen.run.quick_exit import exit_quickly\nprint('said', end='')\nexit_quickly(5)\n"
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert result.returncode == 5 and result.stdout == "said"  # flushed before the exit

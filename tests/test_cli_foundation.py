"""The command line's foundation: help, version, the geometry listing, and bad input.

Every bad input gives ONE line ``Error: ...`` on stderr, exit status 2, no traceback, and writes
nothing. One test per row (ids in brackets); ``mesh`` and ``geometries show`` share the checks:

| id                      | command line (in a fresh folder)                            | message says                         |
|-------------------------|-------------------------------------------------------------|--------------------------------------|
| unknown-geometry        | mesh -g semicylindr --dims 4 4 4 -o m.vtu                   | the available ones, did you mean     |
| unknown-geometry-show   | geometries show flowr -o s.stl                              | did you mean 'flower'                |
| dims-one-number         | mesh --dims 4 -o m.vtu                                      | 2 (2D) or 3 (3D) cell counts, got 1  |
| dims-four-numbers       | mesh --dims 4 4 4 4 -o m.vtu                                | 2 (2D) or 3 (3D) cell counts, got 4  |
| dims-none               | mesh --dims -o m.vtu                                        | got 0                                |
| dims-2-for-3d           | mesh -g semicylinder --dims 4 4 -o m.vtu                    | is 3D: --dims needs 3 numbers        |
| dims-3-for-2d           | mesh -g semidisk --dims 4 4 4 -o m.vtu                      | is 2D: --dims needs 2 numbers        |
| dims-zero               | mesh --dims 0 4 4 -o m.vtu                                  | positive integers, got 0             |
| dims-negative           | mesh --dims 4 -3 4 -o m.vtu                                 | positive integers, got -3            |
| dims-fraction           | mesh --dims 4 4.5 4 -o m.vtu                                | positive integers, got '4.5'         |
| dims-word               | mesh --dims 4 4 four -o m.vtu                               | positive integers, got 'four'        |
| unknown-extension       | mesh --dims 4 4 4 -o m.foo                                  | unknown output extension .foo        |
| no-extension            | mesh --dims 4 4 4 -o mesh                                   | unknown output extension (none)      |
| unknown-extension-show  | geometries show semicylinder -o s.xyz                       | unknown surface extension .xyz       |
| missing-folder          | mesh --dims 4 4 4 -o nowhere/m.vtu                          | output folder nowhere does not exist |
| missing-folder-show     | geometries show semicylinder -o nowhere/s.stl               | output folder nowhere does not exist |
| folder-is-a-file        | mesh --dims 4 4 4 -o afile/m.vtu   (afile a plain file)    | afile                                |
| folder-is-a-file-show   | geometries show semicylinder -o afile/s.stl                 | afile is not a folder                |
| output-is-a-folder      | mesh --dims 4 4 4 -o out.vtu       (out.vtu a folder)       | is a folder                          |
| folder-not-writable     | mesh --dims 4 4 4 -o locked/m.vtu  (chmod 555; skipped as root) | not writable                     |
| param-no-equals         | mesh --dims 4 4 4 --param radius -o m.vtu                   | malformed --param 'radius'           |
| param-not-a-number      | mesh --dims 4 4 4 --param radius=big -o m.vtu               | 'big' is not a number                |
| param-not-finite        | mesh --dims 4 4 4 --param radius=nan -o m.vtu               | must be finite                       |
| param-no-name           | geometries show semicylinder --param =2 -o s.stl            | malformed --param '=2'               |
| param-unknown           | mesh --dims 4 4 4 --param radus=2 -o m.vtu                  | no parameter 'radus' ... 'radius'    |
| param-out-of-range      | geometries show canal --param tube_radius=3 -o s.stl        | tube_radius < bend_radius            |
| plugin-missing-file     | mesh -g nothere.py --dims 4 4 4 -o m.vtu                    | nothere.py does not exist            |
| plugin-syntax-error     | mesh -g plugin.py ... (a line that does not parse)          | plugin.py failed to load: SyntaxError|
| plugin-raises-on-import | mesh -g plugin.py ... (raise RuntimeError at import)        | failed to load: RuntimeError         |
| plugin-no-boundary      | mesh -g plugin.py ... (no boundary function)                | does not define 'boundary'           |
| plugin-bad-dim          | mesh -g plugin.py ... (dim = 4)                             | 'dim' must be 2 or 3                 |
| plugin-wrong-shape      | mesh -g plugin.py ... (boundary returns (N, 2) in 3D)       | boundary() returned shape            |
| plugin-non-finite       | mesh -g plugin.py ... (boundary returns nan)                | non-finite values                    |
| plugin-raises           | mesh -g plugin.py ... (boundary divides by zero)            | boundary() raised ZeroDivisionError  |
| plugin-not-numbers      | mesh -g plugin.py ... (boundary returns strings)            | not an array of numbers              |
| plugin-discontinuous    | geometries show plugin.py -o s.stl (a face lifted off)      | boundary is not continuous           |
| unknown-method          | mesh -m nosuch --dims 4 4 4 -o m.vtu                        | unknown method 'nosuch'              |
| unknown-command         | mesg                                                        | no command 'mesg' ... did you mean   |

The rows run in-process (click's CliRunner calls the same ``main`` as the console script); a few
of them also run as real ``python -m meshgen`` processes, to see the exit path end to end.
"""

import json
import os
import sys
import textwrap
from pathlib import Path

import pytest
from click.testing import CliRunner
from helpers import files_in as snapshot

import meshgen
from meshgen.cli import COMMANDS, cli

PLUGIN_HEAD = """
import numpy as np
name = "brokenplugin"
dim = 3
description = "A plugin that breaks the contract"
"""

PLUGINS = {
    "plugin-syntax-error": PLUGIN_HEAD + "def boundary(points:\n    return points\n",
    "plugin-raises-on-import": PLUGIN_HEAD + "raise RuntimeError('boom at import')\n",
    "plugin-no-boundary": PLUGIN_HEAD,
    "plugin-bad-dim": PLUGIN_HEAD.replace("dim = 3", "dim = 4") + "def boundary(points):\n    return points\n",
    "plugin-wrong-shape": PLUGIN_HEAD + "def boundary(points):\n    return points[:, :2]\n",
    "plugin-non-finite": PLUGIN_HEAD + "def boundary(points):\n    return points * np.nan\n",
    "plugin-raises": PLUGIN_HEAD + "def boundary(points):\n    scale = 1 / 0\n    return scale * points\n",
    "plugin-not-numbers": PLUGIN_HEAD + "def boundary(points):\n    return [['a', 'b', 'c']] * len(points)\n",
    "plugin-discontinuous": PLUGIN_HEAD
    + textwrap.dedent(
        """
        def boundary(points):
            inner = (points[:, 1] > 0) & (points[:, 1] < 1) & (points[:, 2] > 0) & (points[:, 2] < 1)
            return points + 0.1 * (np.isclose(points[:, 0], 1.0) & inner)[:, None]
        """
    ),
}

MESH = ["mesh", "--dims", "4", "4", "4", "-o", "m.vtu"]
SHOW = ["geometries", "show", "semicylinder", "-o", "s.stl"]

# id -> (arguments, fragments the one-line message must contain)
BAD_INPUTS = {
    "unknown-geometry": (
        ["mesh", "-g", "semicylindr", "--dims", "4", "4", "4", "-o", "m.vtu"],
        ["unknown geometry 'semicylindr'", "available: ", "semidisk", "did you mean 'semicylinder'"],
    ),
    "unknown-geometry-show": (
        ["geometries", "show", "flowr", "-o", "s.stl"],
        ["unknown geometry 'flowr'", "did you mean 'flower'"],
    ),
    "dims-one-number": (["mesh", "--dims", "4", "-o", "m.vtu"], ["2 (2D) or 3 (3D) cell counts, got 1"]),
    "dims-four-numbers": (["mesh", "--dims", "4", "4", "4", "4", "-o", "m.vtu"], ["2 (2D) or 3 (3D) cell counts, got 4"]),
    "dims-none": (["mesh", "--dims", "-o", "m.vtu"], ["cell counts, got 0"]),
    "dims-2-for-3d": (
        ["mesh", "-g", "semicylinder", "--dims", "4", "4", "-o", "m.vtu"],
        ["is 3D: --dims needs 3 numbers, got 2"],
    ),
    "dims-3-for-2d": (
        ["mesh", "-g", "semidisk", "--dims", "4", "4", "4", "-o", "m.vtu"],
        ["is 2D: --dims needs 2 numbers, got 3"],
    ),
    "dims-zero": (["mesh", "--dims", "0", "4", "4", "-o", "m.vtu"], ["positive integers, got 0"]),
    "dims-negative": (["mesh", "--dims", "4", "-3", "4", "-o", "m.vtu"], ["positive integers, got -3"]),
    "dims-fraction": (["mesh", "--dims", "4", "4.5", "4", "-o", "m.vtu"], ["positive integers, got '4.5'"]),
    "dims-word": (["mesh", "--dims", "4", "4", "four", "-o", "m.vtu"], ["positive integers, got 'four'"]),
    "unknown-extension": (MESH[:-1] + ["m.foo"], ["unknown output extension .foo", ".vtu"]),
    "no-extension": (MESH[:-1] + ["mesh"], ["unknown output extension (none)"]),
    "unknown-extension-show": (SHOW[:-1] + ["s.xyz"], ["unknown surface extension .xyz", ".stl"]),
    "missing-folder": (MESH[:-1] + ["nowhere/m.vtu"], ["output folder nowhere does not exist"]),
    "missing-folder-show": (SHOW[:-1] + ["nowhere/s.stl"], ["output folder nowhere does not exist"]),
    "folder-is-a-file": (MESH[:-1] + ["afile/m.vtu"], ["afile"]),
    "folder-is-a-file-show": (SHOW[:-1] + ["afile/s.stl"], ["output folder afile is not a folder"]),
    "output-is-a-folder": (MESH[:-1] + ["out.vtu"], ["out.vtu is a folder"]),
    "folder-not-writable": (MESH[:-1] + ["locked/m.vtu"], ["locked is not writable"]),
    "param-no-equals": (MESH + ["--param", "radius"], ["malformed --param 'radius'", "name=value"]),
    "param-not-a-number": (MESH + ["--param", "radius=big"], ["'big' is not a number"]),
    "param-not-finite": (MESH + ["--param", "radius=nan"], ["must be finite"]),
    "param-no-name": (SHOW + ["--param", "=2"], ["malformed --param '=2'"]),
    "param-unknown": (MESH + ["--param", "radus=2"], ["no parameter 'radus'", "radius, length", "did you mean 'radius'"]),
    "param-out-of-range": (
        ["geometries", "show", "canal", "--param", "tube_radius=3", "-o", "s.stl"],
        ["geometry 'canal'", "tube_radius < bend_radius"],
    ),
    "plugin-missing-file": (["mesh", "-g", "nothere.py", "--dims", "4", "4", "4", "-o", "m.vtu"], ["nothere.py does not exist"]),
    "plugin-syntax-error": (None, ["plugin.py failed to load: SyntaxError"]),
    "plugin-raises-on-import": (None, ["plugin.py failed to load: RuntimeError: boom at import"]),
    "plugin-no-boundary": (None, ["plugin.py does not define 'boundary'"]),
    "plugin-bad-dim": (None, ["'dim' must be 2 or 3, got 4"]),
    "plugin-wrong-shape": (None, ["geometry 'brokenplugin'", "plugin.py", "boundary() returned shape"]),
    "plugin-non-finite": (None, ["geometry 'brokenplugin'", "plugin.py", "non-finite values"]),
    "plugin-raises": (None, ["geometry 'brokenplugin'", "plugin.py", "boundary() raised ZeroDivisionError"]),
    "plugin-not-numbers": (None, ["geometry 'brokenplugin'", "not an array of numbers"]),
    "plugin-discontinuous": (
        ["geometries", "show", "plugin.py", "-o", "s.stl"],
        ["geometry 'brokenplugin'", "plugin.py", "not continuous"],
    ),
    "unknown-method": (["mesh", "-m", "nosuch", "--dims", "4", "4", "4", "-o", "m.vtu"], ["unknown method 'nosuch'"]),
    "unknown-command": (["mesg"], ["no command 'mesg'", "did you mean 'mesh'"]),
}


def prepare(row, folder: Path) -> list[str]:
    """Set up ``folder`` for bad-input ``row`` and return its command line."""
    args, _ = BAD_INPUTS[row]
    (folder / "afile").write_text("a plain file where a folder should be\n")
    (folder / "out.vtu").mkdir()
    locked = folder / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    if row in PLUGINS:
        (folder / "plugin.py").write_text(PLUGINS[row])
    if args is None:
        args = ["mesh", "-g", "plugin.py", "--dims", "4", "4", "4", "-o", "m.vtu"]
    return args


def assert_one_line_error(exit_code, stdout, stderr, fragments):
    assert exit_code == 2, stderr
    lines = stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: "), stderr
    assert "Traceback" not in stderr + stdout
    for fragment in fragments:
        assert fragment in lines[0]


def test_bad_input_table_is_complete():
    documented = [line.split("|")[1].strip() for line in __doc__.splitlines() if line.startswith("| ") and "---" not in line]
    assert documented[1:] == list(BAD_INPUTS)
    assert set(PLUGINS) <= set(BAD_INPUTS)


@pytest.mark.parametrize("row", list(BAD_INPUTS))
def test_bad_input_gives_one_line_exit_2_and_writes_nothing(row, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    args = prepare(row, tmp_path)
    if row == "folder-not-writable" and os.access(tmp_path / "locked", os.W_OK):
        pytest.skip("chmod does not stop this user (root) from writing; folder-is-a-file covers the check")
    before = snapshot(tmp_path)
    result = CliRunner().invoke(cli, args)
    assert_one_line_error(result.exit_code, result.stdout, result.stderr, BAD_INPUTS[row][1])
    assert result.stdout == ""
    assert snapshot(tmp_path) == before


@pytest.mark.parametrize("row", ["unknown-geometry", "dims-zero", "plugin-raises"])
def test_bad_input_in_a_real_process(row, tmp_path, run_cli):
    args = prepare(row, tmp_path)
    before = snapshot(tmp_path)
    result = run_cli(*args)
    assert_one_line_error(result.returncode, result.stdout, result.stderr, BAD_INPUTS[row][1])
    assert snapshot(tmp_path) == before


HELP_PROBE = """
import json, sys
from click.testing import CliRunner
from meshgen.cli import COMMANDS, cli
runner = CliRunner()
outputs = {"": runner.invoke(cli, ["--help"]).output}
outputs.update({name: runner.invoke(cli, [name, "--help"]).output for name in COMMANDS})
heavy = sorted(m for m in ("torch", "trimesh", "meshio", "scipy", "matplotlib") if m in sys.modules)
print(json.dumps({"outputs": outputs, "heavy": heavy}))
"""


def test_help_lists_the_commands_without_importing_heavy_modules(tmp_path):
    import subprocess

    repo = Path(__file__).resolve().parents[1]
    probe = subprocess.run(
        [sys.executable, "-c", HELP_PROBE],
        capture_output=True,
        text=True,
        env={**os.environ, "PYTHONPATH": str(repo)},
        cwd=tmp_path,
        timeout=120,
    )
    assert probe.returncode == 0, probe.stderr
    report = json.loads(probe.stdout)
    assert report["heavy"] == []
    assert set(COMMANDS) == {"train", "mesh", "evaluate", "compare", "geometries"}
    top = report["outputs"][""]
    for name, (_, help_text) in COMMANDS.items():
        assert f"  {name}" in top and help_text in top
        assert report["outputs"][name].startswith("Usage: ") and f" {name} " in report["outputs"][name].splitlines()[0]


def test_version(run_cli):
    result = run_cli("--version")
    assert result.returncode == 0
    assert result.stdout.strip() == f"meshgen, version {meshgen.__version__}"


def test_geometries_json_matches_the_plugins():
    import importlib.util

    from meshgen.geometry.plugins import _builtin_files, available_names

    result = CliRunner().invoke(cli, ["geometries", "--json"])
    assert result.exit_code == 0, result.output
    listed = json.loads(result.stdout)
    assert [item["name"] for item in listed] == available_names()
    for item in listed:  # what --dims counts: per axis (axes) and on one line (dims); block sets also list their blocks
        assert list(item) == ["name", "dim", "description", "params", "patches", "axes"] + (
            ["blocks", "dims"] if "blocks" in item else ["dims"]
        )
    by_name = {item["name"]: item for item in listed}
    for stem, path in _builtin_files().items():  # read the plugin files directly, not through meshgen.geometry.plugins
        spec = importlib.util.spec_from_file_location(f"_listing_check_{stem}", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        item = by_name[module.name]
        assert item["dim"] == module.dim
        assert item["description"] == module.description
        assert item["params"] == {k: float(v) for k, v in module.params.items()}
        assert list(item["axes"].values()) == list(getattr(module, "axes", ()))


def test_geometries_table_lists_every_geometry():
    from meshgen.geometry.plugins import available_names

    result = CliRunner().invoke(cli, ["geometries"], env={"COLUMNS": "200"})
    assert result.exit_code == 0, result.output
    for name in available_names():
        assert name in result.stdout

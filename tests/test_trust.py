"""The trust boundary (design notes, "Trust boundary and faults"): files are data and never run
code, sizes and numbers are checked before anything is allocated, untrusted files are read
defensively, and plugin code is contained. Each test drives the real command line."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from click.testing import CliRunner
from neural_helpers import tiny_config

from meshgen.cli import cli
from meshgen.formats import write_mesh
from meshgen.geometry.plugins import load_geometry
from meshgen.neural.train import train

# A valid 2D plugin (the unit square) whose import writes MARKER: if MARKER appears, meshgen ran it.
MARKER_PLUGIN = """
import numpy as np
open({marker!r}, "w").write("ran")
name = {name!r}
dim = 2
description = "the unit square, and a side effect"

def boundary(points):
    return np.array(points, dtype=float)
"""


def invoke(*args):
    return CliRunner().invoke(cli, [str(a) for a in args])


def one_line_error(result, *fragments):
    assert result.exit_code == 2, (result.exit_code, result.output)
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: "), result.stderr
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])


def snapshot(folder: Path) -> dict:
    return {str(p.relative_to(folder)): p.read_bytes() if p.is_file() else None for p in sorted(folder.rglob("*"))}


@pytest.fixture
def evil(tmp_path) -> tuple[Path, Path]:
    """(plugin file that would write the marker, the marker's path)."""
    marker = tmp_path / "pwned"
    plugin = tmp_path / "evil.py"
    plugin.write_text(MARKER_PLUGIN.format(marker=str(marker), name="square"))
    return plugin, marker


@pytest.fixture(scope="module")
def semidisk_checkpoint(tmp_path_factory) -> dict:
    folder = tmp_path_factory.mktemp("semidisk")
    train(tiny_config(), load_geometry("semidisk"), folder, stop=lambda: True, summary=False)
    return torch.load(folder / "checkpoint.pt", weights_only=True)


# ---------------------------------------------------------------------------------------------
# 1. data never runs code


SQUARE = np.stack(np.meshgrid(np.linspace(0, 1, 5), np.linspace(0, 1, 4), indexing="ij"), axis=-1)


@pytest.mark.parametrize("where", ["vtu", "cgns", "sidecar"])
def test_a_mesh_naming_a_plugin_file_is_evaluated_without_running_it(where, tmp_path, evil):
    plugin, marker = evil
    recorded = {"geometry": str(plugin), "params": {}, "dims": [4, 3]}
    if where == "sidecar":  # a Plot3D file records nothing itself: its sidecar names the plugin
        path = write_mesh(tmp_path / "m.xyz", SQUARE)
        sidecar = {"mesh": "m.xyz", "cells": 12, **recorded}
        (tmp_path / "m.xyz.quality.json").write_text(json.dumps(sidecar))
    else:
        path = write_mesh(tmp_path / f"m.{where}", SQUARE, metadata=recorded)
    result = invoke("evaluate", path)
    assert result.exit_code == 0, result.output
    assert not marker.exists()
    warnings = [line for line in result.stderr.splitlines() if "evil.py" in line]
    assert len(warnings) == 1 and "no boundary deviation" in warnings[0] and "-g PATH" in warnings[0], result.stderr
    # Named by the user, the same plugin is run, and the boundary deviation measured.
    given = invoke("evaluate", path, "-g", plugin, "--json", "-")
    assert given.exit_code == 0, given.output
    assert marker.exists()
    assert json.loads(given.stdout)["boundary_deviation"]["max"] == pytest.approx(0.0, abs=1e-12)


def test_a_checkpoint_naming_a_plugin_file_asks_for_it(tmp_path, evil, semidisk_checkpoint):
    plugin, marker = evil
    hostile = {**semidisk_checkpoint, "geometry": {**semidisk_checkpoint["geometry"], "spec": str(plugin)}}
    torch.save(hostile, tmp_path / "hostile.pt")
    before = snapshot(tmp_path)
    result = invoke("mesh", "--checkpoint", "hostile.pt", "--dims", 4, 4, "-o", "out.vtu")
    one_line_error(result, "evil.py", "pass -g PATH")
    resumed = invoke("train", "--resume", "hostile.pt", "-q")
    one_line_error(resumed, "evil.py", "pass -g PATH")
    assert not marker.exists() and snapshot(tmp_path) == before


def test_a_long_recorded_path_keeps_its_file_name_in_the_message(tmp_path, semidisk_checkpoint):
    # The message is cut to a short excerpt; for a path it keeps the end, the file the user must pass.
    deep = tmp_path.joinpath(*["folder-with-a-long-name"] * 6, "plugin-the-user-trained.py")
    hostile = {**semidisk_checkpoint, "geometry": {**semidisk_checkpoint["geometry"], "spec": str(deep)}}
    torch.save(hostile, tmp_path / "hostile.pt")
    result = invoke("mesh", "--checkpoint", "hostile.pt", "--dims", 4, 4, "-o", "out.vtu")
    one_line_error(result, "plugin-the-user-trained.py", "characters)", "pass -g PATH")


@pytest.mark.parametrize("name", ["../../escaped", "/tmp/abs", "a/b", "", "x" * 65, "dot.dot"])
def test_a_plugin_name_never_becomes_a_path(name, tmp_path):
    plugin = tmp_path / "named.py"
    plugin.write_text(MARKER_PLUGIN.format(marker=str(tmp_path / "imported"), name=name))
    (tmp_path / "work").mkdir()
    before = snapshot(tmp_path)
    result = CliRunner().invoke(cli, ["train", "-g", str(plugin), "--preset", "2d", "--set", "adam.steps=1", "-q"])
    one_line_error(result, "named.py", "'name' must be")
    after = snapshot(tmp_path)
    after.pop("imported", None)  # the user named the file: it was imported, then refused
    assert after == before


# ---------------------------------------------------------------------------------------------
# 6. plugins that misbehave are contained

CONTAINED_PLUGIN = """
import numpy as np
name = "misbehaving"
dim = 2
description = "the unit square, misbehaving"
params = {{"scale": 1.0}}

class Unusual(BaseException):
    pass

def boundary(points, scale):
    points = np.array(points, dtype=float)
{body}
    return points * scale
"""

MISBEHAVIOURS = {
    "system-exit": ("    raise SystemExit(0)", "boundary() raised SystemExit"),
    "generator-exit": ("    raise GeneratorExit()", "boundary() raised GeneratorExit"),
    "base-exception": ("    raise Unusual('odd')", "boundary() raised Unusual: odd"),
    "complex": ("    return points * (1 + 1j)", "boundary() returned complex numbers"),
    "overflow": ("    points = points * np.exp(scale * 1000.0)", "boundary() raised FloatingPointError: overflow"),
    "long-message": ("    raise ValueError('x' * 100000)", "boundary() raised ValueError: xxx"),
}


@pytest.mark.parametrize("row", list(MISBEHAVIOURS))
def test_a_misbehaving_plugin_is_one_line_naming_it_and_the_function(row, tmp_path):
    body, message = MISBEHAVIOURS[row]
    (tmp_path / "plugin.py").write_text(CONTAINED_PLUGIN.format(body=body))
    before = snapshot(tmp_path)
    result = invoke("mesh", "-m", "tfi", "-g", "plugin.py", "--dims", 4, 4, "-o", "out.vtu")
    one_line_error(result, message)
    assert message in result.stderr and "'misbehaving'" in result.stderr and "plugin.py" in result.stderr
    assert len(result.stderr) < 700  # a short excerpt of what the plugin said, never all of it
    assert snapshot(tmp_path) == before


TORN_BOX = """
import numpy as np
name = "tornbox"
dim = 3
description = "the unit box; face xi = 1 lifted off along 1% of its edge with eta = 0"

def boundary(points):
    torn = np.isclose(points[:, 0], 1.0) & (points[:, 1] > 0) & ({low} < points[:, 2]) & (points[:, 2] < {low} + 0.01)
    return points + 0.01 * torn[:, None]
"""


@pytest.mark.parametrize("low", [0.5, 0.913, 0.0021])
def test_a_tear_of_one_percent_of_an_edge_is_found(low, tmp_path):
    """The face xi = 1 leaves its neighbour eta = 0 along 1% of their common edge, by 1% of the
    box: the faces disagree there, and loading the plugin says where."""
    from meshgen.errors import GeometryError
    from meshgen.geometry.plugins import load_geometry as load

    (tmp_path / "torn.py").write_text(TORN_BOX.format(low=low))
    unchecked = load(str(tmp_path / "torn.py"), check=False)
    edge = np.column_stack([np.ones(5), np.zeros(5), np.linspace(low, low + 0.01, 7)[1:-1]])
    into_face = edge.copy()
    into_face[:, 1] = 1e-3
    gap = np.linalg.norm(unchecked.boundary(into_face) - unchecked.boundary(edge), axis=1)
    assert gap.min() > 0.009  # the tear is real: the face moved off the edge by about 1%
    with pytest.raises(GeometryError, match="not continuous across the cube's edge at \\(1, 0, "):
        load(str(tmp_path / "torn.py"))


# ---------------------------------------------------------------------------------------------
# 4. sizes and values are checked before anything is allocated

TOO_LARGE = {
    "mesh-one-long-axis": (
        ["mesh", "-m", "tfi", "-g", "semidisk", "--dims", 10000000000, 1, "-o", "m.cgns"],
        "even block by block",
    ),
    "mesh-in-memory": (
        ["mesh", "-m", "tfi", "-g", "semicylinder", "--dims", 2000, 2000, 2000, "--in-memory", "-o", "m.cgns"],
        "--chunked",
    ),
    "compare": (["compare", "-g", "semicylinder", "--dims", 100000, 100000, 100000, "--methods", "tfi"], "even block by block"),
    "compare-in-memory": (["compare", "-g", "semicylinder", "--dims", 3000, 3000, 3000, "--methods", "tfi"], "in memory"),
    "train-widths": (["train", "-g", "semidisk", "--preset", "2d", "--set", "model.widths=[100000,100000]"], "[1, 4096]"),
    "train-points": (["train", "-g", "semidisk", "--preset", "2d", "--set", "points.interior=1000000000"], "'points.interior'"),
    "train-memory": (["train", "-g", "semicylinder", "--set", "points.interior=10000000"], "of memory but"),
    "train-lr-inf": (["train", "-g", "semidisk", "--preset", "2d", "--set", "adam.lr=.inf"], "finite number, got inf"),
    "train-weight-nan": (["train", "-g", "semidisk", "--preset", "2d", "--set", "method.pde_weight=.nan"], "finite number"),
    "compare-set-inf": (["compare", "-g", "semidisk", "--dims", 4, 4, "--methods", "pinn", "--set", "adam.lr=-.inf"], "finite"),
    "gate-nan": (["evaluate", "m.vtu", "--fail-if", "min_angle.mean<nan"], "'nan' is not a finite number"),
    "gate-inf": (["evaluate", "m.vtu", "--fail-if", "cells>inf"], "'inf' is not a finite number"),
    "param-inf": (["mesh", "-m", "tfi", "-g", "semidisk", "--dims", 4, 4, "--param", "radius=inf", "-o", "o.vtu"], "finite"),
    "param-huge": (["mesh", "-m", "tfi", "-g", "semidisk", "--dims", 4, 4, "--param", "radius=1e300", "-o", "o.vtu"], "1e+100"),
    "cluster-nan": (
        ["mesh", "-m", "tfi", "-g", "semidisk", "--dims", 4, 4, "--cluster", "eta:0:nan", "-o", "o.vtu"],
        "--cluster",
    ),
    "tol-nan": (["mesh", "-m", "elliptic", "-g", "semidisk", "--dims", 4, 4, "--tol", "nan", "-o", "o.vtu"], "--tol"),
    "vary-inf": (["train", "-g", "flower", "--preset", "family", "--vary", "twist=0:1e999"], "finite"),
    "cgns-header": (["evaluate", "claims.cgns"], "claims (100001, 100001, 100001) nodes"),
    "cgns-sparse": (["evaluate", "sparse.cgns"], "stores 0 GB"),
}


def crafted_cgns(folder: Path) -> None:
    """claims.cgns: a zone header claiming 100001^3 nodes over 5 x 4 x 3 coordinates; sparse.cgns:
    coordinate arrays of that size too, but with no bytes stored (an HDF5 dataset never written)."""
    import h5py

    box = np.stack(np.meshgrid(*(np.linspace(0, 1, n) for n in (5, 4, 3)), indexing="ij"), axis=-1)
    for name in ("claims.cgns", "sparse.cgns"):
        write_mesh(folder / name, box)
        with h5py.File(folder / name, "r+") as root:
            header = root["Base/Zone/ data"]
            sizes = header[()]
            sizes[0], sizes[1] = 100001, 100000
            header[...] = sizes
            if name == "sparse.cgns":
                for axis in "XYZ":
                    group = root[f"Base/Zone/GridCoordinates/Coordinate{axis}"]
                    del group[" data"]
                    group.create_dataset(" data", shape=(100001,) * 3, dtype="<f8", chunks=(1, 64, 64))


@pytest.mark.parametrize("row", list(TOO_LARGE))
def test_sizes_and_numbers_are_checked_before_anything_is_allocated(row, tmp_path):
    args, fragment = TOO_LARGE[row]
    write_mesh(tmp_path / "m.vtu", SQUARE)
    crafted_cgns(tmp_path)
    before = snapshot(tmp_path)
    result = invoke(*args, *(["--out", "run", "-q"] if args[0] == "train" else []))
    one_line_error(result, fragment)
    assert snapshot(tmp_path) == before  # no run folder, no mesh, nothing


def test_every_number_of_the_training_configuration_has_both_bounds():
    """Each int and float key of the configuration schema has a range in BOUNDS, and a value one
    past either end of it is refused."""
    from meshgen.neural.config import BOUNDS, ConfigError, resolve_config, schema

    numeric = {key for key, kind in schema().items() if "int" in str(kind) or "float" in str(kind)}
    assert numeric == set(BOUNDS)
    for key, (low, high) in BOUNDS.items():
        if key in ("dim", "model.widths"):
            continue
        above = high + 1 if isinstance(high, int) else high * 2 + 1
        for outside in (above, low - 1):
            with pytest.raises(ConfigError, match=key.replace(".", "\\.")):
                resolve_config("default", None, [f"{key}={outside}"])


# ---------------------------------------------------------------------------------------------
# 5. untrusted files are read defensively

ALIAS_BOMB = "a: &a [x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"{chr(98 + i)}: &{chr(98 + i)} [*{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}, *{chr(97 + i)}]\n"
    for i in range(9)
)


@pytest.mark.parametrize(
    "row",
    ["fifo-evaluate", "zero-evaluate", "zero-config", "zero-checkpoint", "alias-bomb", "deep-nesting", "long-line"],
)
def test_untrusted_files_are_refused_in_one_short_line(row, tmp_path, run_cli):
    """A FIFO or a link to /dev/zero is never read (a reader would wait or fill memory), a YAML
    alias bomb and 5000 nested brackets are refused at once, an error never repeats a long input."""
    import os

    train = ["train", "-g", "semidisk", "--preset", "2d", "--out", "run", "-q"]
    if row == "fifo-evaluate":
        os.mkfifo(tmp_path / "m.vtu")
        args, fragment = ["evaluate", "m.vtu"], "is a FIFO"
    elif row.startswith("zero"):
        name = {"zero-evaluate": "m.xyz", "zero-config": "c.yaml", "zero-checkpoint": "c.pt"}[row]
        (tmp_path / name).symlink_to("/dev/zero")
        args = {
            "zero-evaluate": ["evaluate", name],
            "zero-config": [*train, "--config", name],
            "zero-checkpoint": ["mesh", "--checkpoint", name, "--dims", 4, 4, "-o", "o.vtu"],
        }[row]
        fragment = "is a character device"
    elif row == "alias-bomb":
        (tmp_path / "c.yaml").write_text(ALIAS_BOMB)
        args, fragment = [*train, "--config", "c.yaml"], "anchor or alias at line 1"
    elif row == "deep-nesting":
        (tmp_path / "c.yaml").write_text("adam: " + "[" * 5000 + "]" * 5000 + "\n")
        args, fragment = [*train, "--config", "c.yaml"], "nests deeper than"
    else:
        args, fragment = [*train, "--set", "adam.lr=" + "9" * 100000 + "x"], "adam.lr"
    before = snapshot(tmp_path)
    if row in ("fifo-evaluate", "zero-evaluate", "zero-config", "zero-checkpoint"):  # a child: a hang ends in its timeout
        result = run_cli(*args, timeout=60)
        code, stderr = result.returncode, result.stderr
    else:
        result = invoke(*args)
        code, stderr = result.exit_code, result.stderr
    assert code == 2, stderr[-2000:]
    assert stderr.count("\n") == 1 and stderr.startswith("Error: "), stderr[-2000:]
    assert fragment in stderr and len(stderr) < 700
    assert snapshot(tmp_path) == before


def test_the_alias_bomb_is_one():
    """Loaded without the limits, the bomb's last key expands to 9 * 5^9 items: a real bomb."""
    import yaml

    assert len(yaml.safe_load(ALIAS_BOMB.replace("x, x, x, x, x, x, x, x, x", "x"))["j"]) == 5
    data = yaml.safe_load("a: &a [x, x]\nb: [*a, *a]\n")
    assert data["b"] == [["x", "x"], ["x", "x"]]


def corrupt_list(path: Path, swap: tuple[int, int]) -> None:
    """Swap two entries of an OpenFOAM label list (ASCII or binary) in place."""
    from meshgen.formats._openfoam import read_list

    labels = read_list(path, "labels")
    data = path.read_bytes()
    if b"format      binary" in data or b"format binary" in data or b"binary;" in data:
        position = data.index(f"{len(labels)}\n(".encode()) + len(f"{len(labels)}\n(")
        values = np.frombuffer(data, dtype="<i4", count=len(labels), offset=position).copy()
        values[[swap[0], swap[1]]] = values[[swap[1], swap[0]]]
        path.write_bytes(data[:position] + values.tobytes() + data[position + values.nbytes :])
    else:
        head, _, body = data.partition(f"{len(labels)}\n(\n".encode())
        lines = body.split(b"\n")
        lines[swap[0]], lines[swap[1]] = lines[swap[1]], lines[swap[0]]
        path.write_bytes(head + f"{len(labels)}\n(\n".encode() + b"\n".join(lines))


@pytest.mark.parametrize("ascii_files", [False, True])
@pytest.mark.parametrize("damaged", ["owner", "neighbour"])
def test_an_openfoam_case_with_a_corrupt_owner_or_neighbour_list_is_an_error(damaged, ascii_files, tmp_path):
    from meshgen.formats._openfoam import read_list

    args = ["mesh", "-m", "tfi", "-g", "semicylinder", "--dims", 4, 3, 2, "--format", "openfoam", "-o", "case", "-q"]
    assert invoke(*args, *(["--ascii"] if ascii_files else [])).exit_code == 0
    assert invoke("evaluate", "case").exit_code == 0
    path = tmp_path / "case" / "constant" / "polyMesh" / damaged
    before = read_list(path, "labels")
    corrupt_list(path, (0, len(before) - 1))  # first and last labels differ: a real change
    after = read_list(path, "labels")
    assert not np.array_equal(before, after) and sorted(before) == sorted(after)
    one_line_error(invoke("evaluate", "case"), "corrupt")


def test_a_checkpoint_with_nan_weights_is_an_error_and_writes_nothing(tmp_path, semidisk_checkpoint):
    model = semidisk_checkpoint["model"]
    state = dict(model["state_dict"])
    state["layers.0.weight"] = state["layers.0.weight"].clone()
    state["layers.0.weight"][0, 0] = float("nan")
    torch.save({**semidisk_checkpoint, "model": {**model, "state_dict": state}}, tmp_path / "nan.pt")
    before = snapshot(tmp_path)
    one_line_error(invoke("mesh", "--checkpoint", "nan.pt", "--dims", 4, 4, "-o", "o.vtu"), "non-finite weights")
    one_line_error(invoke("train", "--resume", "nan.pt", "-q"), "non-finite weights")
    assert snapshot(tmp_path) == before


def test_a_non_finite_network_output_is_an_error(semidisk_checkpoint):
    """Finite weights whose product overflows float32: the output check, not the weight check."""
    from meshgen.errors import MeshgenError
    from meshgen.neural.gpu_forward import evaluate_on_grid

    model = dict(semidisk_checkpoint["model"])
    state = dict(model["state_dict"])
    last = max(int(k.split(".")[1]) for k in state)
    state[f"layers.{last}.weight"] = torch.full_like(state[f"layers.{last}.weight"], 3e38)
    model["state_dict"] = state
    with pytest.raises(MeshgenError, match="non-finite"):
        evaluate_on_grid(model, [np.linspace(0, 1, 5), np.linspace(0, 1, 4)])


@pytest.fixture
def interrupted_run(tmp_path) -> Path:
    """A tiny semidisk run stopped after its 6th step (history rows 0..5, checkpoint at step 6)."""
    polls = iter(range(1000))
    (tmp_path / "run").mkdir()
    train(tiny_config("lbfgs.steps=0"), load_geometry("semidisk"), tmp_path / "run", stop=lambda: next(polls) >= 6, summary=False)
    return tmp_path / "run"


def test_resume_survives_a_truncated_history(interrupted_run):
    history = interrupted_run / "history.csv"
    lines = history.read_text().splitlines()
    assert len(lines) == 7  # header and steps 0..5
    history.write_text("\n".join(lines[:-1]) + "\n" + lines[-1][:3])  # the last row (step 5) cut short
    resumed = invoke("train", "--resume", interrupted_run / "checkpoint.pt", "-q")
    assert resumed.exit_code == 0, resumed.output
    import csv

    rows = list(csv.DictReader(history.read_text().splitlines()))
    steps = [int(r["step"]) for r in rows]
    # The whole rows kept, the cut one (step 5) dropped, the resumed steps from the checkpoint's 6 on.
    assert steps == [0, 1, 2, 3, 4, *range(6, 6 + len(steps) - 5)] and len(steps) >= 9
    assert history.read_text().splitlines()[:6] == lines[:6]  # the whole rows kept as they were


def test_a_damaged_checkpoint_fails_before_the_run_folder_changes(interrupted_run):
    """A checkpoint whose optimiser state is not its stage's (stitched by hand) fails with one line,
    leaving config.yaml and history.csv as they were."""
    checkpoint = torch.load(interrupted_run / "checkpoint.pt", weights_only=True)
    stage = checkpoint["stage"]
    torch.save({**checkpoint, "stage": "lbfgs" if stage != "lbfgs" else "adam"}, interrupted_run / "checkpoint.pt")
    before = snapshot(interrupted_run)
    one_line_error(invoke("train", "--resume", interrupted_run / "checkpoint.pt", "-q"), "optimiser state")
    assert snapshot(interrupted_run) == before


def test_a_checkpoint_trained_on_a_plugin_file_meshes_with_that_file_named(tmp_path, semidisk_checkpoint):
    """A checkpoint recording a plugin file meshes when the user names the file with -g, and asks
    for it otherwise (the plugin is not imported)."""
    marker = tmp_path / "imported"
    plugin = tmp_path / "disk.py"
    plugin.write_text(
        MARKER_PLUGIN.format(marker=str(marker), name="semidisk")
        .replace("description", 'params = {"radius": 1.0}\ndescription')
        .replace("def boundary(points):", "def boundary(points, radius):")
    )
    entry = {**semidisk_checkpoint["geometry"], "spec": str(plugin)}
    torch.save({**semidisk_checkpoint, "geometry": entry}, tmp_path / "c.pt")
    asked = invoke("mesh", "--checkpoint", "c.pt", "--dims", 4, 4, "-o", "o.vtu")
    one_line_error(asked, "disk.py", "pass -g PATH")
    assert not marker.exists()
    named = invoke("mesh", "--checkpoint", "c.pt", "-g", "disk.py", "--dims", 4, 4, "-o", "o.vtu")
    assert named.exit_code == 0, named.output
    assert marker.exists() and (tmp_path / "o.vtu").is_file()


def test_ctrl_c_and_meshgen_signals_pass_through_a_plugin_call():
    """The user's Ctrl-C, and a BaseException of meshgen's own (what its SIGTERM handler raises),
    stop meshgen even inside plugin code; a plugin's own BaseException does not."""
    import types

    from meshgen.errors import GeometryError
    from meshgen.geometry.plugin_calls import call_plugin

    own = types.new_class("Stop", (BaseException,))
    own.__module__ = "meshgen.run.signals"
    foreign = types.new_class("Stop", (BaseException,))
    foreign.__module__ = "meshgen_plugin_x"

    def raising(kind):
        raise kind()

    for kind in (KeyboardInterrupt, own):
        with pytest.raises(kind):
            call_plugin("'x' (x.py)", "boundary()", raising, kind)
    with pytest.raises(GeometryError, match="boundary\\(\\) raised Stop"):
        call_plugin("'x' (x.py)", "boundary()", raising, foreign)

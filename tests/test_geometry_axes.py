"""What each --dims number counts (``axes``): declared by every single-block built-in, checked
against the geometry itself (its inlet and outlet patches, the direction its grid lines run), shown
by ``meshgen geometries`` (table and --json); a plugin's ``axes`` is checked when it loads."""

from __future__ import annotations

import json
import re
import textwrap

import numpy as np
import pytest
from click.testing import CliRunner

from meshgen.cli import cli
from meshgen.errors import GeometryError
from meshgen.geometry.patches import Patch, flow_role
from meshgen.geometry.plugins import load_geometry
from meshgen.methods.tfi import tfi

SINGLE_BLOCK = ["bump", "canal", "flower", "semicylinder", "semidisk", "topcurve"]
AXES = ("xi", "eta", "zeta")
COORDINATE = re.compile(r"(?<![\w'])([xyz])(?![\w'])")  # a coordinate named on its own: "(x)", "along the axis z"


@pytest.mark.parametrize("name", SINGLE_BLOCK)
def test_builtin_axes_say_what_the_geometry_does(name):
    geometry = load_geometry(name)
    assert len(geometry.axes) == geometry.dim
    roles = {face: flow_role(Patch(patch, kind, (face,))) for face, (patch, kind) in geometry.patches.items()}
    X = tfi(geometry, (6, 7, 8)[: geometry.dim])
    for axis, meaning in enumerate(geometry.axes):
        name_of = AXES[axis]
        flows = roles.get(f"{name_of}0") == "inflow" and roles.get(f"{name_of}1") == "outflow"
        assert ("(flow)" in meaning) == flows, f"{name}: {name_of} says {meaning!r}"
        if "wall-normal" in meaning:
            assert geometry.patches[f"{name_of}0"][1] == "wall" and geometry.patches[f"{name_of}1"][1] == "wall"
        named = COORDINATE.findall(meaning)
        if named:  # the grid lines of this axis run mostly along that coordinate
            steps = np.abs(np.diff(X, axis=axis)).reshape(-1, geometry.dim).mean(axis=0)
            assert "xyz"[int(np.argmax(steps))] == named[-1], f"{name}: {name_of} steps {steps}"


def test_geometries_lists_the_axes():
    listed = CliRunner().invoke(cli, ["geometries", "--json"])
    assert listed.exit_code == 0
    items = {item["name"]: item for item in json.loads(listed.stdout)}
    for name in SINGLE_BLOCK:
        axes = load_geometry(name).axes
        assert list(items[name]["axes"].values()) == list(axes)
        assert items[name]["dims"].startswith(f"xi: {axes[0]}, eta: {axes[1]}")
    assert items["pipe"]["dims"].startswith("N M A")  # a block set says what --dims counts its own way
    table = CliRunner().invoke(cli, ["geometries"], env={"COLUMNS": "400"})
    assert "--dims counts xi: " + load_geometry("topcurve").axes[0] in table.stdout


PLUGIN = """
import numpy as np
name = "plainbox"
dim = 2
description = "unit square"
{axes}
def boundary(points):
    return np.asarray(points, dtype=float)
"""


def test_plugin_axes_are_checked(tmp_path):
    good = tmp_path / "good.py"
    good.write_text(textwrap.dedent(PLUGIN.format(axes='axes = ("along x (flow)", "across")')))
    assert load_geometry(str(good)).describe()["axes"] == {"xi": "along x (flow)", "eta": "across"}
    plain = tmp_path / "plain.py"
    plain.write_text(textwrap.dedent(PLUGIN.format(axes="")))
    assert load_geometry(str(plain)).describe()["axes"] == {}
    bad = tmp_path / "bad.py"
    bad.write_text(textwrap.dedent(PLUGIN.format(axes='axes = ("one",)')))
    with pytest.raises(GeometryError, match="'axes' must be 2 non-empty strings"):
        load_geometry(str(bad))

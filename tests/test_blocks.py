"""Block sets (meshgen.geometry.blocks) and their TFI and elliptic meshes: the pipe O-grid and the DFG
channel with a cylinder; bad block sets rejected with one line."""

import numpy as np
import pytest
from blocks_helpers import cell_measures, size_ratios

from meshgen.errors import GeometryError
from meshgen.geometry.block_nodes import global_numbering, interface_gaps, merged_mesh, unify_interfaces
from meshgen.geometry.blocks import load_block_set, tfi_blocks
from meshgen.geometry.plugins import load_geometry
from meshgen.methods.elliptic import elliptic_blocks
from meshgen.quality import quality_report


def pipe_unique_nodes(n, m, a):
    """Closed form: the section has the core's (N+1)^2 nodes and M rings of 4N nodes around it."""
    return ((n + 1) ** 2 + 4 * m * n) * (a + 1)


@pytest.mark.parametrize("dims", [(8, 4, 4), (16, 8, 4)])
@pytest.mark.parametrize("method", ["tfi", "elliptic"])
def test_pipe_quality_does_not_degrade(dims, method):
    block_set = load_block_set("pipe", None, dims)
    Xs = tfi_blocks(block_set) if method == "tfi" else elliptic_blocks(block_set)[0]
    assert all(gap == 0.0 for gap in interface_gaps(block_set, Xs))  # identical, not merely close
    _, count = global_numbering(block_set)
    assert count == pipe_unique_nodes(*dims)
    points, cells, _ = merged_mesh(block_set, Xs)
    report = quality_report((points, cells))
    assert report["inverted"]["count"] == 0
    assert report["metrics"]["min_angle"]["min"] >= 40.0
    assert report["metrics"]["max_angle"]["max"] <= 140.0
    across, inside = size_ratios(block_set, Xs)
    assert across <= 1.3
    if method == "elliptic":
        assert across <= inside


@pytest.mark.parametrize("name, dims", [("pipe", (6, 3, 2)), ("dfg-cylinder-3d", (8, 4, 3))])
def test_unify_interfaces_gives_every_shared_node_its_first_holders_value(name, dims):
    """Against the plain rule written out: every node takes the value of the first block (in block
    order) that holds it; nodes on no interface do not move; arrays of any memory layout."""
    block_set = load_block_set(name, None, dims)
    rng = np.random.default_rng(1)
    noise = 1e-3 * 1e-9 * block_set.length  # within the gap tolerance
    Xs = [X + noise * rng.standard_normal(X.shape) for X in tfi_blocks(block_set)]
    Xs[1] = np.asfortranarray(Xs[1])  # a copy made by reshape would leave it unchanged
    before = [X.copy() for X in Xs]
    numbering, count = global_numbering(block_set)
    first = np.full((count, block_set.dim), np.nan)
    for X, ids in zip(reversed(before), reversed(numbering)):  # later blocks first: the first holder writes last
        first[ids.reshape(-1)] = X.reshape(-1, block_set.dim)
    unify_interfaces(block_set, Xs)
    holders = np.bincount(np.concatenate([ids.reshape(-1) for ids in numbering]), minlength=count)
    for X, old, ids in zip(Xs, before, numbering):
        np.testing.assert_array_equal(X, first[ids])
        alone = holders[ids] == 1
        np.testing.assert_array_equal(X[alone], old[alone])
    assert all(gap == 0.0 for gap in interface_gaps(block_set, Xs))
    assert max(np.abs(X - old).max() for X, old in zip(Xs, before)) > 0  # shared nodes did move


def test_pipe_elliptic_is_smoother_than_tfi_and_on_the_wall():
    block_set = load_block_set("pipe", {"radius": 0.5, "length": 1.0}, (8, 4, 4))
    Xs, info = elliptic_blocks(block_set)
    assert info["converged"]
    tfi = tfi_blocks(block_set)
    moved = max(float(np.max(np.abs(X - T))) for X, T in zip(Xs, tfi))
    assert moved > 1e-3  # the interior did move
    for name, X in zip(block_set.names[1:], Xs[1:]):  # wall blocks: xi = 1 on the circle r = 0.5
        wall = X[-1]
        assert np.allclose(np.hypot(wall[..., 0], wall[..., 1]), 0.5, atol=1e-12), name


@pytest.mark.parametrize("method", ["tfi", "elliptic"])
def test_dfg_cylinder(method):
    block_set = load_block_set("dfg-cylinder", None, (8, 8))
    Xs = tfi_blocks(block_set) if method == "tfi" else elliptic_blocks(block_set)[0]
    assert all(gap == 0.0 for gap in interface_gaps(block_set, Xs))
    points, cells, _ = merged_mesh(block_set, Xs)
    report = quality_report((points, cells))
    assert report["inverted"]["count"] == 0
    # The area meshed is the channel minus the disk (closed form), to the polygon's error.
    area = 2.2 * 0.41 - np.pi * 0.05**2
    x, y = points[cells, 0], points[cells, 1]
    shoelace = 0.5 * np.sum(x * np.roll(y, -1, axis=1) - np.roll(x, -1, axis=1) * y)
    assert abs(shoelace - area) < 2e-3 * area
    across, _ = size_ratios(block_set, Xs)
    assert across <= 1.3


@pytest.mark.parametrize("method", ["tfi", "elliptic"])
def test_dfg_cylinder_3d(method):
    block_set = load_block_set("dfg-cylinder-3d", None, (4, 3, 3))
    Xs = tfi_blocks(block_set) if method == "tfi" else elliptic_blocks(block_set)[0]
    assert all(gap == 0.0 for gap in interface_gaps(block_set, Xs))
    points, cells, _ = merged_mesh(block_set, Xs)
    assert quality_report((points, cells))["inverted"]["count"] == 0
    # The volume meshed is the channel minus the cylinder (closed form), to the polygon's error.
    volume = (2.2 * 0.41 - np.pi * 0.05**2) * 0.41
    measured = sum(float(cell_measures(X).sum()) for X in Xs)
    assert abs(measured - volume) < 1e-2 * volume


def test_single_block_plugin_unchanged():
    geometry = load_geometry("semicylinder")
    assert geometry.boundary(np.array([[0.5, 1.0, 0.5]])).shape == (1, 3)


def _plugin(tmp_path, **changes):
    """A two-block 2D plugin (two unit squares side by side), with ``changes`` to its source."""
    source = {
        "blocks": '("left", "right")',
        "interfaces": '[("left", "xi1", "right", "xi0")]',
        "block_patches": '{"left": {"xi0": ("inlet", "patch"), "eta0": ("wall", "wall"), "eta1": ("wall", "wall")}, '
        '"right": {"xi1": ("outlet", "patch"), "eta0": ("wall", "wall"), "eta1": ("wall", "wall")}}',
        "shift": "0.0",
        "right_cells": "n",
        "flip": "False",
    } | changes
    path = tmp_path / "two.py"
    path.write_text(
        f"""
import numpy as np
name = "two"
dim = 2
description = "two squares"
params = {{}}
dims_meaning = "N N"
blocks = {source["blocks"]}
interfaces = {source["interfaces"]}
block_patches = {source["block_patches"]}
def block_coords(dims):
    n, m = dims
    return {{"left": [np.linspace(0, 1, n + 1), np.linspace(0, 1, m + 1)],
             "right": [np.linspace(0, 1, {source["right_cells"]} + 1), np.linspace(0, 1, m + 1)]}}
def boundary(block, points):
    x, y = points[:, 0], points[:, 1]
    if block == "right":
        x = x + 1.0 + {source["shift"]}
        if {source["flip"]}:
            y = 1.0 - y
    return np.stack([x, y], axis=1)
"""
    )
    return str(path)


def test_two_blocks_merge(tmp_path):
    block_set = load_block_set(_plugin(tmp_path), None, (3, 2))
    assert block_set.interfaces[0].transform == (1, 2)
    Xs = tfi_blocks(block_set)
    points, cells, _ = merged_mesh(block_set, Xs)
    assert len(points) == 7 * 3 and len(cells) == 12


@pytest.mark.parametrize(
    "changes, words",
    [
        ({"shift": "0.01"}, ["left.xi1 = right.xi0", "do not coincide", "largest gap 0.01"]),
        ({"interfaces": '[("left", "xi1", "right", "xi0"), ("left", "xi1", "right", "xi1")]'}, ["claimed by two interfaces"]),
        (
            {"block_patches": '{"left": {"xi1": ("x", "wall")}, "right": {}}'},
            ["on the interface", "also named patch 'x'"],
        ),
        ({"flip": "True"}, ["left-handed"]),
    ],
)
def test_bad_block_sets(tmp_path, changes, words):
    with pytest.raises(GeometryError) as error:
        block_set = load_block_set(_plugin(tmp_path, **changes), None, (3, 2))
        tfi_blocks(block_set)
    message = str(error.value)
    assert "\n" not in message
    assert any(word in message for word in words), message


def test_node_counts_must_match(tmp_path):
    path = _plugin(
        tmp_path,
        block_patches='{"left": {"xi0": ("i", "patch"), "eta0": ("w", "wall"), "eta1": ("w", "wall")}, '
        '"right": {"xi1": ("o", "patch"), "eta0": ("w", "wall"), "eta1": ("w", "wall")}}',
    )
    text = (
        open(path)
        .read()
        .replace(
            '"right": [np.linspace(0, 1, n + 1), np.linspace(0, 1, m + 1)]',
            '"right": [np.linspace(0, 1, n + 1), np.linspace(0, 1, m + 2)]',
        )
    )
    open(path, "w").write(text)
    with pytest.raises(GeometryError, match="has 2 cells on one side and 3 on the other"):
        load_block_set(path, None, (3, 2))

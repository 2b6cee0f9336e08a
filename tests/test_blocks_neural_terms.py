"""The block set's training terms added for the pipe's quality (design notes §20): the right-angle
rule on flat patches, the parallelogram rule at junctions, the L-BFGS stage's lattices, and
``meshgen train --init`` (a new run from a block model's weights). Closed forms throughout: maps
given as plain functions whose derivatives are known."""

from pathlib import Path

import numpy as np
import pytest
import torch
from neural_helpers import tiny_config

from meshgen.geometry import cube
from meshgen.geometry.blocks import load_block_set
from meshgen.neural.checkpoint import load_checkpoint
from meshgen.neural.interfaces import (
    INTERFACE_STEP,
    JUNCTION_STEP,
    BlockNetworks,
    block_lengths,
    block_problem,
    fixed_block_points,
    flat_patch_rows,
    junction_pool,
    junction_rows,
    lattice_tangents,
)
from meshgen.neural.train import train


class Map(torch.nn.Module):
    """A closed-form map as a float64 "network" (the terms evaluate in their networks' type)."""

    def __init__(self, function):
        super().__init__()
        self.function = function
        self.unused = torch.nn.Parameter(torch.zeros(1, dtype=torch.float64))

    def forward(self, points):
        return self.function(points)


TINY_BLOCKS = ("pretrain.steps=5", "pretrain.points=300", "lbfgs.max_iter=3", "adam.steps=5", "model.widths=[16,16]")


@pytest.mark.parametrize("side", [0, 1])
def test_the_right_angle_rule_is_the_sine_of_the_grid_lines_tilt(side):
    """x(xi, eta, zeta) = (xi + a zeta + b zeta^2, eta, L zeta) on the face zeta = side: the
    one-sided differences are exact for a quadratic, so the row is the in-plane part of
    +-(a + 2 b side, 0, L) over its length, i.e. (+-(a + 2 b side), 0, 0) / |(a + 2 b side, 0, L)|."""
    a, b, length = 0.3, -0.2, 2.0

    def network(p):
        return torch.stack([p[:, 0] + a * p[:, 2] + b * p[:, 2] ** 2, p[:, 1], length * p[:, 2]], -1)

    face = cube.face_named(f"zeta{side}", 3)
    points = torch.rand((20, 3), dtype=torch.float64)
    points[:, 2] = float(side)
    rows = flat_patch_rows(network, face, points, network(points), torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64))
    slope = a + 2 * b * side
    expected = np.array([slope, 0.0, 0.0]) / np.hypot(slope, length) * (1 if side == 0 else -1)
    np.testing.assert_allclose(rows.numpy(), np.tile(expected, (20, 1)), atol=1e-12)
    straight = lambda p: torch.stack([p[:, 0], p[:, 1], length * p[:, 2]], -1)  # noqa: E731 (meets the plane at right angles)
    rows = flat_patch_rows(straight, face, points, straight(points), torch.tensor([0.0, 0.0, 1.0], dtype=torch.float64))
    assert float(rows.abs().max()) < 1e-12


def test_the_pipes_junction_quads_are_its_core_corners_made_physically_square():
    """(4, 2, 4) cells: the core's four long edges have 3 inner nodes each (12 junctions), each with
    one quad in the core and one in each of the two wall blocks beside it; every quad has the side
    JUNCTION_STEP times the shortest mean block length there, in physical units."""
    block_set = load_block_set("pipe", None, (4, 2, 4))
    pool = junction_pool(block_set, torch.device("cpu"))
    assert pool["count"] == 12 and len(pool["node"]) == 36
    assert np.bincount(pool["block"]).tolist() == [12, 6, 6, 6, 6]
    assert np.bincount(pool["node"].numpy()).tolist() == [3] * 12
    lengths = [block_lengths(g, 3) for g in block_set.geometries]
    side = JUNCTION_STEP * min(min(lengths[0][:2]), min(lengths[1][:2]))  # the core's and a wall block's, in the section
    points = pool["points"].numpy()
    for q, block in enumerate(pool["block"]):
        du, dv, dz = points[q, 3] - points[q, 0]
        assert dz == 0.0 and points[q, 0, 2] in (0.25, 0.5, 0.75)  # in the node's layer
        assert abs(du) * lengths[block][0] == pytest.approx(side) and abs(dv) * lengths[block][1] == pytest.approx(side)


def test_the_parallelogram_rule_vanishes_for_affine_maps_and_measures_a_mixed_derivative():
    """Per block affine maps (any, different per block) complete every parallelogram exactly: rows 0.
    x = u v e in the core alone: each core quad misses by du dv e, so a junction's row is
    du dv e / 3 (three quads) over the mean |du dv| of its quads."""
    block_set = load_block_set("pipe", None, (4, 2, 4))
    pool = junction_pool(block_set, torch.device("cpu"))
    generator = torch.Generator().manual_seed(3)
    affine = [
        (torch.rand((3, 3), generator=generator, dtype=torch.float64), torch.rand(3, generator=generator, dtype=torch.float64))
        for _ in range(5)
    ]
    networks = [Map(lambda p, A=A, c=c: p @ A.T + c) for A, c in affine]
    assert float(junction_rows(networks, pool).abs().max()) < 1e-12
    e = torch.tensor([1.0, -2.0, 0.5], dtype=torch.float64)
    zero = Map(torch.zeros_like)
    rows = junction_rows([Map(lambda p: (p[:, 0] * p[:, 1])[:, None] * e), *[zero] * 4], pool).numpy()
    points, node = pool["points"].numpy(), pool["node"].numpy()
    for j in range(pool["count"]):
        quads = np.flatnonzero(node == j)
        core = quads[pool["block"][quads] == 0][0]
        du, dv = (points[core, 3] - points[core, 0])[:2]
        areas = [np.prod(np.abs(points[q, 3] - points[q, 0])[np.abs(points[q, 3] - points[q, 0]) > 0]) for q in quads]
        np.testing.assert_allclose(rows[j], du * dv * e.numpy() / 3 / np.mean(areas), rtol=1e-10)


def test_junction_nodes_at_every_blocks_corner_get_no_rows():
    """The T-joint's junction nodes include nodes at a corner of every block round them (on no block
    edge's interior: no quad in the layer of an edge): they are left out, so every junction kept has
    quads, a finite area and rows, and affine maps still complete every parallelogram (before, such
    a node's 0 / 0 area made the held-out PDE loss NaN)."""
    from meshgen.methods.interfaces import junction_nodes

    topology = Path(__file__).resolve().parents[1] / "examples" / "topologies" / "t-joint-3d.yaml"
    block_set = load_block_set(str(topology), None, (2, 2, 2))
    pool = junction_pool(block_set, torch.device("cpu"))
    assert 0 < pool["count"] < len(junction_nodes(block_set)[0])
    assert np.bincount(pool["node"].numpy(), minlength=pool["count"]).min() >= 1
    assert np.all(np.isfinite(pool["area"].numpy())) and np.all(pool["area"].numpy() > 0)
    generator = torch.Generator().manual_seed(5)
    networks = [Map(lambda p, A=torch.rand((3, 3), generator=generator, dtype=torch.float64): p @ A.T) for _ in block_set.names]
    rows = junction_rows(networks, pool)
    assert rows.shape == (pool["count"], 3) and float(rows.abs().max()) < 1e-9  # rounding over small areas


def test_the_lbfgs_lattices_are_regular_and_the_same_on_every_face():
    tangents = lattice_tangents(81, 3, INTERFACE_STEP).numpy()
    assert tangents.shape == (81, 2)
    for axis in range(2):
        values = np.unique(tangents[:, axis])
        np.testing.assert_allclose(values, INTERFACE_STEP + (np.arange(9) + 0.5) * (1 - 2 * INTERFACE_STEP) / 9)
    assert lattice_tangents(5, 2, 0.0).numpy().ravel().tolist() == pytest.approx([0.1, 0.3, 0.5, 0.7, 0.9])
    config = tiny_config(*TINY_BLOCKS)
    problem = block_problem(load_block_set("pipe", None, (4, 2, 4)), torch.device("cpu"))
    fixed = fixed_block_points(problem, config, 16, 2, lattice=9)
    assert all(torch.equal(t, fixed["tangent"][0]) for t in fixed["tangent"])
    assert fixed["index"].tolist() == [list(range(9))] * len(problem.patch_faces)


@pytest.fixture(scope="module")
def tiny_pipe(tmp_path_factory):
    run_dir = tmp_path_factory.mktemp("pipe-init")
    config = tiny_config(*TINY_BLOCKS)
    return train(config, load_block_set("pipe", None, (4, 2, 4)), run_dir, summary=False, geometry_spec="pipe").checkpoint_path


def test_init_starts_a_new_run_from_the_checkpoints_weights(tiny_pipe, run_cli, tmp_path):
    """No steps at all: the new run's weights and loss weights are the checkpoint's, bit for bit,
    and the checkpoint records where it started; one L-BFGS step then moves them."""
    tiny = [f"--set={item}" for item in ("model.widths=[16,16]", "points.interior=100", "points.boundary=100",
                                         "points.boundary_pool=4", "test.interior=50", "test.boundary=50",
                                         "pretrain.steps=0", "adam.steps=0", "lbfgs.max_iter=3")]  # fmt: skip
    started = load_checkpoint(tiny_pipe)
    for steps, moved in ((0, False), (1, True)):
        run = tmp_path / f"run{steps}"
        result = run_cli("train", "-g", "pipe", "--out", run, "--quiet", "--init", tiny_pipe, *tiny, f"--set=lbfgs.steps={steps}")
        assert result.returncode == 0, result.stderr
        checkpoint = load_checkpoint(run / "checkpoint.pt")
        assert checkpoint["init"] == {
            "path": str(tiny_pipe),
            "step": started["step"],
            "training_seconds": started["elapsed_seconds"],
        }
        assert checkpoint["step"] == steps
        same = [torch.equal(checkpoint["model"]["state_dict"][k], v) for k, v in started["model"]["state_dict"].items()]
        assert all(same) != moved
        assert torch.equal(checkpoint["reweighting"]["log_a"], started["reweighting"]["log_a"])


@pytest.mark.parametrize(
    "args, message",
    [
        (["-g", "pipe", "--set", "model.widths=[16,16]"], "--set pretrain.steps=0 (got"),
        (["-g", "pipe", "--set", "pretrain.steps=0"], "has model.widths=[16, 16], the run [48, 48, 48]"),
        (["-g", "semicylinder", "--set", "pretrain.steps=0"], "--init is made for block sets"),
        (["-g", "pipe", "--set", "pretrain.steps=0", "--resume", "x.pt"], "does not go with --resume"),
    ],
)
def test_init_refusals_are_one_line_errors(tiny_pipe, run_cli, args, message):
    result = run_cli("train", *args, "--init", str(tiny_pipe), "--out", "run", "--quiet")
    assert result.returncode == 2, result.stdout
    assert message in result.stderr and len(result.stderr.strip().splitlines()) == 1, result.stderr


def test_tfi_anchor_is_validated_and_refused_for_one_block(run_cli, tmp_path):
    from meshgen.neural.config import ConfigError, resolve_config

    assert resolve_config("default").method.tfi_anchor == 1.0
    with pytest.raises(ConfigError, match="method.tfi_anchor"):
        tiny_config("method.tfi_anchor=-0.5")
    result = run_cli("train", "-g", "semicylinder", "--set", "method.tfi_anchor=0.1", "--out", "run", "--quiet")
    assert result.returncode == 2 and not (tmp_path / "run").exists()
    assert "'semicylinder' is one block: method.tfi_anchor=0.1 applies to block sets only" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("weight", [0.0, 0.3, 1.0])
def test_tfi_anchor_weighs_the_pull_towards_the_tfi_in_l1(weight):
    """L1 = the residual part + tfi_anchor times the mean over blocks of the mean squared distance
    from the TFI at the pool's points (computed here with NumPy's TFI); 0 leaves the residual alone."""
    from meshgen.methods.tfi import transfinite
    from meshgen.neural.interfaces import BlockNetworks, block_pde_term, block_samples, tfi_anchor_pool

    config = tiny_config(*TINY_BLOCKS, f"method.tfi_anchor={weight}")
    problem = block_problem(load_block_set("pipe", None, (4, 2, 4)), torch.device("cpu"))
    torch.manual_seed(0)
    networks = BlockNetworks(3, [8], 5).double().networks
    sample, _ = block_samples(config, problem, fixed_block_points(problem, config, 32, 1), random=False)
    pools = tfi_anchor_pool(problem, 40, 7)
    with torch.no_grad():
        plain = float(block_pde_term(networks, problem, sample))
        problem.anchor, problem.anchor_weight = pools, config.method.tfi_anchor
        anchored = float(block_pde_term(networks, problem, sample))
        distances = []
        for net, pool, boundary in zip(networks, pools, problem.boundaries):
            points = pool["points"].double().numpy()
            image = net(torch.from_numpy(points)).numpy()
            distances.append(np.mean(np.sum((image - transfinite(boundary, list(points.T))) ** 2, axis=1)))
    assert anchored - plain == pytest.approx(weight * np.mean(distances), rel=1e-5, abs=1e-12)


def test_init_from_a_pipe_model_of_3d_networks_is_a_one_line_error(tiny_pipe, run_cli, tmp_path):
    """A pipe model from before the section training (one 3D network per block) cannot start a run
    of the pipe, whose networks now map its 2D section (design notes §20)."""
    checkpoint = load_checkpoint(tiny_pipe)
    model = {k: v for k, v in checkpoint["model"].items() if k != "extruded"}
    model.update(dim=3, center=[0.0, 0.0, 2.0], scale=4.0, state_dict=BlockNetworks(3, [16, 16], 5).state_dict())
    old = tmp_path / "old.pt"
    torch.save({**checkpoint, "model": model}, old)
    result = run_cli("train", "-g", "pipe", "--init", str(old), "--set", "model.widths=[16,16]", "--set", "pretrain.steps=0",
                     "--out", tmp_path / "run", "--quiet")  # fmt: skip
    assert result.returncode == 2, result.stdout
    assert "holds 3D networks, and 'pipe' is extruded" in result.stderr and len(result.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "run").exists()

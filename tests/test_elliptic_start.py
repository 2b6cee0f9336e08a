"""The elliptic start of a block set's networks (``meshgen.neural.elliptic_start``, design notes
§20): the fine grid (refined nodes, conforming interfaces, gradings kept), the projected fit (its
output layer the least-squares solution, computed here again with NumPy; better than L-BFGS on
every weight), the default run of the pipe meeting its benchmark target (within 0.5 degrees of the
elliptic mesh's mean min angle), the step counts a run takes, and the one-block refusal."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from neural_helpers import tiny_config

import meshgen
from meshgen.geometry.block_nodes import merged_mesh
from meshgen.geometry.blocks import check_interfaces, load_block_set
from meshgen.geometry.extrusion import extrusion_of, section_of
from meshgen.neural.checkpoint import load_checkpoint
from meshgen.neural.config import resolve_config
from meshgen.neural.elliptic_start import FIT_NODES, elliptic_pools, elliptic_targets, refined, refinement
from meshgen.neural.interfaces import BlockNetworks, block_problem
from meshgen.neural.projected_fit import RIDGE, hidden_parameters, projected_fit_step
from meshgen.neural.train import train
from meshgen.quality import quality_report

EXAMPLES = Path(__file__).resolve().parents[1] / "examples" / "topologies"


def pipe_section():
    block_set = load_block_set("pipe", None, (8, 8, 8))
    return section_of(block_set, extrusion_of(block_set))


def test_the_fine_grid_refines_every_axis_keeps_its_nodes_and_conforms():
    graded = load_block_set(str(EXAMPLES / "cylinder-2d.yaml"), None, (1, 1))  # graded towards the cylinder
    factor = refinement(graded)
    assert factor >= 2
    fine = refined(graded, factor)
    check_interfaces(fine)  # matching node counts and coinciding faces after the refinement
    for axes, fine_axes in zip(graded.coords, fine.coords):
        for t, f in zip(axes, fine_axes):
            assert len(f) == (len(t) - 1) * factor + 1
            np.testing.assert_array_equal(f[::factor], t)  # the old nodes stay where they were
            assert np.all(np.diff(f) > 0)
            # between two old nodes the new ones are evenly spaced: the grading is the old one
            spacing = np.diff(f).reshape(len(t) - 1, factor)
            np.testing.assert_allclose(spacing, np.diff(t)[:, None] / factor * np.ones(factor), rtol=1e-12)


def test_the_refinement_aims_at_64_cells_and_caps_the_nodes():
    assert refinement(pipe_section()) == 8  # 8 x 8 cells a block -> 64 x 64
    bend = load_block_set(str(EXAMPLES / "elbow-3d.yaml"), None, (1, 1, 1))

    def nodes(factor):
        return sum(int(np.prod([(n - 1) * factor + 1 for n in shape])) for shape in bend.node_shapes)

    factor = refinement(bend)
    assert factor == 1 or nodes(factor) <= FIT_NODES  # the cap
    assert nodes(factor + 1) > FIT_NODES  # the largest factor under it (the 3D set's 64 cells would exceed it)


@pytest.fixture(scope="module")
def section_pools():
    section = pipe_section()
    fine, Xs, account = elliptic_targets(section, "pipe")
    problem = block_problem(section, torch.device("cpu"))
    return fine, Xs, account, problem, elliptic_pools(fine, Xs, problem.center, problem.scale, "cpu")


def test_the_targets_are_the_elliptic_mesh_of_the_fine_grid_normalised(section_pools):
    fine, Xs, account, problem, pools = section_pools
    assert "elliptic mesh of 64x64 cells a block" in account
    expected, _ = meshgen.methods.elliptic.elliptic_blocks(fine)  # the section's own elliptic mesh
    for X, E, pool in zip(Xs, expected, pools):
        np.testing.assert_allclose(X, E, atol=1e-12)
        assert pool["points"].shape == (65 * 65, 2) and pool["targets"].dtype == torch.float32
        back = pool["targets"].double().numpy() * problem.scale + problem.center
        np.testing.assert_allclose(back, X.reshape(-1, 2), atol=1e-6 * problem.scale)  # float32 targets


def _numpy_features(net, points):
    hidden = 2.0 * points.astype(float) - 1.0
    for layer in net.layers[:-1]:
        hidden = np.tanh(hidden @ layer.weight.detach().double().numpy().T + layer.bias.detach().double().numpy())
    return np.hstack([hidden, np.ones((len(hidden), 1))])


def test_the_projected_fit_sets_the_least_squares_output_layer_and_beats_plain_lbfgs(section_pools):
    pools = section_pools[-1]
    torch.manual_seed(0)
    projected = BlockNetworks(2, [16, 16], len(pools)).double()
    torch.manual_seed(0)
    plain = BlockNetworks(2, [16, 16], len(pools)).double()
    options = {"lr": 1.0, "max_iter": 10, "history_size": 50, "line_search_fn": "strong_wolfe"}
    options.update(tolerance_grad=0.0, tolerance_change=0.0)
    optimizer = torch.optim.LBFGS(hidden_parameters(projected.networks), **options)
    for _ in range(4):
        row = projected_fit_step(projected.networks, optimizer, pools)
    for net, pool in zip(projected.networks, pools):  # the output layer: NumPy's ridged least squares
        features = _numpy_features(net, pool["points"].numpy())
        count, width = features.shape
        rows = np.vstack([features, np.sqrt(RIDGE * count) * np.eye(width)])
        wanted = np.vstack([pool["targets"].double().numpy(), np.zeros((width, 2))])
        solved = np.linalg.lstsq(rows, wanted, rcond=None)[0]
        np.testing.assert_allclose(net.layers[-1].weight.detach().numpy(), solved[:-1].T, rtol=1e-6, atol=1e-8)
        np.testing.assert_allclose(net.layers[-1].bias.detach().numpy(), solved[-1], rtol=1e-6, atol=1e-8)
    misfits = [
        float(((net(p["points"].double()) - p["targets"].double()) ** 2).sum(-1).mean())
        for net, p in zip(projected.networks, pools)
    ]
    assert float(row["total"]) == pytest.approx(np.mean(misfits), rel=1e-6)  # the row is the networks' own misfit

    optimizer = torch.optim.LBFGS(plain.parameters(), **options)
    points, targets = [p["points"].double() for p in pools], [p["targets"].double() for p in pools]

    def closure():
        optimizer.zero_grad()
        value = torch.stack([((n(x) - t) ** 2).sum(-1).mean() for n, x, t in zip(plain.networks, points, targets)]).mean()
        value.backward()
        return value

    for _ in range(4):
        optimizer.step(closure)
    assert float(row["total"]) < 0.1 * float(closure())


@pytest.fixture(scope="module")
def pipe_run(tmp_path_factory):
    """``meshgen train -g pipe`` with the default configuration (the elliptic start, no Winslow steps)."""
    run_dir = tmp_path_factory.mktemp("pipe-default")
    block_set = load_block_set("pipe", None, (8, 8, 8))
    result = train(resolve_config("default", None, []), block_set, run_dir, summary=False, geometry_spec="pipe")
    return result.checkpoint_path


def test_the_default_pipe_model_is_within_half_a_degree_of_the_elliptic_mesh(pipe_run):
    """The benchmark's target: mean min angle within 0.5 deg of the multi-block elliptic mesh's at 8 4 4 and
    16 8 4, no inverted cell, identical interface nodes."""
    checkpoint = load_checkpoint(pipe_run)
    assert checkpoint["step"] == 20  # the fit alone: adam and lbfgs take their block_steps, 0
    assert checkpoint["model"]["state_dict"]["networks.0.layers.0.weight"].dtype == torch.float64
    # a finished run keeps no optimiser state (no stage reads it back): the file is the weights
    assert checkpoint["optimizer"] == {} and Path(pipe_run).stat().st_size < 1_000_000
    for dims in [(8, 4, 4), (16, 8, 4)]:
        angles = []
        for method, options in (("elliptic", {}), ("neural", {"model": str(pipe_run)})):
            made = meshgen.mesh("pipe", dims, method=method, **options)
            points, cells, _ = merged_mesh(made.geometry, made.blocks)
            report = quality_report((points, cells))
            assert report["inverted"]["count"] == 0
            angles.append(report["metrics"]["min_angle"]["mean"])
        assert abs(angles[1] - angles[0]) <= 0.5, (dims, angles)


def test_block_steps_apply_after_the_elliptic_fit_only():
    """adam/lbfgs.block_steps replace steps after the elliptic fit; with the TFI start, or no fit
    (an --init run), the stages take their steps."""
    from meshgen.neural.interface_stages import block_steps

    class Run:
        def __init__(self, *overrides):
            self.config = tiny_config("adam.steps=7", "lbfgs.steps=5", *overrides)

    assert block_steps(Run(), "adam") == 0 and block_steps(Run(), "lbfgs") == 0
    assert block_steps(Run("adam.block_steps=3"), "adam") == 3
    assert block_steps(Run("adam.block_steps=null"), "adam") == 7
    assert block_steps(Run("pretrain.target=tfi"), "adam") == 7 and block_steps(Run("pretrain.target=tfi"), "lbfgs") == 5
    assert block_steps(Run("pretrain.steps=0"), "lbfgs") == 5


def test_one_block_refuses_the_elliptic_target_in_one_line(run_cli):
    done = run_cli("train", "-g", "semicylinder", "--set", "pretrain.target=elliptic", "--out", "run")
    assert done.returncode == 2
    assert "pretrain.target=elliptic applies to block sets only" in done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and not Path("run").exists()
    done = run_cli("train", "-g", "semicylinder", "--set", "pretrain.target=sideways", "--out", "run")
    assert done.returncode == 2 and "must be one of auto, tfi, elliptic" in done.stderr


def test_winslow_steps_after_the_elliptic_fit_run_in_float64(tmp_path):
    """``adam.block_steps`` and ``lbfgs.block_steps`` set: the run goes on from the fit (whose
    networks are float64) through Adam and L-BFGS on the Winslow loss, every row finite."""
    config = tiny_config("pretrain.steps=2", "adam.block_steps=2", "lbfgs.block_steps=1", "model.widths=[8,8]")
    result = train(config, load_block_set("pipe", None, (4, 2, 4)), tmp_path, summary=False, geometry_spec="pipe")
    checkpoint = load_checkpoint(result.checkpoint_path)
    assert checkpoint["step"] == 5 and checkpoint["stage"] == "done"
    rows = (tmp_path / "history.csv").read_text().splitlines()[1:]
    assert [row.split(",")[0] for row in rows] == ["pretrain"] * 2 + ["adam"] * 2 + ["lbfgs"]
    assert all(np.isfinite(float(row.split(",")[4])) for row in rows)  # the total of every row
    assert all(np.isfinite(checkpoint["test_loss"][key]) for key in ("pde", "boundary"))

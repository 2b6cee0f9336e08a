"""Training: a short 2D run lowers both losses; the divergence guard; the final summary."""

import json
import math

import numpy as np
import pytest
import torch
from neural_helpers import Recorder, tiny_config

import meshgen.neural.problem as problem_module
import meshgen.neural.steps as steps
from meshgen.neural.checkpoint import load_checkpoint
from meshgen.neural.problem import evaluate_losses, lbfgs_points
from meshgen.neural.stages import TrainingDiverged
from meshgen.neural.train import train


@pytest.mark.parametrize("derivatives", ["fd", "autograd"])
def test_a_short_2d_run_from_random_weights_lowers_both_losses(tmp_path, semidisk, derivatives):
    config = tiny_config(
        "model.widths=[16,16]",
        "points.interior=400",
        "points.boundary=200",
        "pretrain.steps=0",
        "adam.steps=150",
        "adam.lr=1e-2",
        "lbfgs.steps=0",
        "method.balance_start=false",
        f"method.derivatives={derivatives}",
    )
    recorder = Recorder()
    result = train(config, semidisk, tmp_path, reporter=recorder, summary=False)
    first, last = recorder.rows[:5], recorder.rows[-5:]
    for loss in ("L1", "L2"):
        before, after = np.mean([r[loss] for r in first]), np.mean([r[loss] for r in last])
        assert after < before / 10, (loss, before, after)
    assert any(r["conflict"] for r in recorder.rows)  # PDE and boundary did pull apart at times
    assert result.test_loss["boundary"] < 0.01  # the held-out boundary points agree: mean squared distance


def test_lbfgs_lowers_the_weighted_loss_on_its_fixed_points(tmp_path, semidisk):
    config = tiny_config("adam.steps=20", "lbfgs.steps=5", "lbfgs.max_iter=10")
    recorder = Recorder()
    train(config, semidisk, tmp_path, reporter=recorder, summary=False)
    lbfgs = [r for r in recorder.rows if r["stage"] == "lbfgs"]
    assert len(lbfgs) == 5 and lbfgs[-1]["total"] < lbfgs[0]["total"]
    assert [r["stage"] for r in recorder.rows] == ["pretrain"] * 2 + ["adam"] * 20 + ["lbfgs"] * 5


def test_pretraining_fits_tfi(tmp_path, semidisk):
    recorder = Recorder()
    train(tiny_config("pretrain.steps=8", "adam.steps=0", "lbfgs.steps=0"), semidisk, tmp_path, reporter=recorder, summary=False)
    fits = [r["total"] for r in recorder.rows]
    assert fits[-1] < fits[0] / 10


def test_a_non_finite_loss_restores_the_last_good_state_and_lowers_the_learning_rate(tmp_path, semidisk, monkeypatch):
    calls = {"n": 0}
    real = problem_module.pde_term

    def sometimes_nan(*args):
        calls["n"] += 1
        loss = real(*args)
        return loss * math.nan if calls["n"] in (4, 5) else loss

    for module in (problem_module, steps):  # the steps and the balance start
        monkeypatch.setattr(module, "pde_term", sometimes_nan)
    recorder = Recorder()
    config = tiny_config("lbfgs.steps=0", "adam.lr=1e-3")
    result = train(config, semidisk, tmp_path, reporter=recorder, summary=False)
    assert not result.interrupted and result.step == 2 + 10
    restores = [m for m in recorder.messages if "non-finite loss" in m]
    assert len(restores) == 2 and f"learning rate lowered to {config.adam.lr * 0.5:.3g}" in restores[0]
    assert f"learning rate lowered to {config.adam.lr * 0.25:.3g}" in restores[1]
    assert all(math.isfinite(r["total"]) for r in recorder.rows)
    assert recorder.rows[-1]["lr"] == pytest.approx(config.adam.lr * 0.25)
    assert result.checkpoint["guard"]["lr_reductions"] == 2


def test_repeated_failure_stops_and_keeps_the_last_good_checkpoint(tmp_path, semidisk, monkeypatch):
    real = problem_module.pde_term
    calls = {"n": 0}

    def nan_after_a_while(*args):
        calls["n"] += 1
        loss = real(*args)
        return loss * math.nan if calls["n"] > 7 else loss

    for module in (problem_module, steps):  # the steps and the balance start
        monkeypatch.setattr(module, "pde_term", nan_after_a_while)
    config = tiny_config("lbfgs.steps=0", "guard.max_retries=3")
    with pytest.raises(TrainingDiverged, match="diverged.*after 3 learning-rate reductions.*checkpoint.pt"):
        train(config, semidisk, tmp_path, summary=False)
    saved = load_checkpoint(tmp_path / "checkpoint.pt")
    assert saved["stage"] == "adam" and saved["step"] == 2 + 6  # balance_start evaluated once, then 6 good steps
    assert all(bool(torch.isfinite(t).all()) for t in saved["model"]["state_dict"].values())


def test_final_summary_compares_the_network_with_tfi(tmp_path, semidisk):
    from meshgen.methods.tfi import parametric_grid
    from meshgen.neural.model import mesh_from_checkpoint
    from meshgen.quality import quality_report

    result = train(tiny_config(), semidisk, tmp_path)
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary == json.loads(json.dumps(result.summary))
    assert summary["dims"] == [30, 30] and summary["network"]["cells"] == 900
    assert summary["tfi"]["inverted"]["count"] == 0 and summary["tfi"]["boundary_deviation"]["max"] < 1e-12
    # the network's figures are those of its 30 x 30 mesh, deviation from the boundary included
    X = mesh_from_checkpoint(result.checkpoint, parametric_grid((30, 30)), semidisk)
    expected = json.loads(json.dumps(quality_report(X, semidisk)))
    assert summary["network"]["metrics"] == expected["metrics"]
    assert summary["network"]["boundary_deviation"]["max"] == expected["boundary_deviation"]["max"] > 0
    # and of its corrected mesh (what meshgen mesh writes): on the boundary to round-off
    assert summary["corrected"]["boundary_deviation"]["max"] < 1e-12
    assert summary["corrected"]["cells"] == 900


def test_correction_of_a_shifted_mesh_shifts_it_back(semidisk):
    """An error field that is the same at every boundary node: its TFI is that constant, so the
    correction moves every node, not only the boundary ones, back by the shift."""
    from meshgen.methods.tfi import parametric_grid, tfi
    from meshgen.neural.train import corrected

    coords = parametric_grid((6, 4))
    exact = tfi(semidisk, None, coords)
    np.testing.assert_allclose(corrected(exact + 0.01, semidisk, coords), exact, rtol=0, atol=1e-14)


def test_losses_at_fixed_points_are_reproducible(semidisk):
    from meshgen.neural.model import MLP, normalisation, normalised_boundary
    from meshgen.neural.problem import Problem

    config = tiny_config()
    center, scale = normalisation(semidisk)
    problem = Problem(2, normalised_boundary(semidisk, center, scale), center, scale, False, torch.device("cpu"))
    torch.manual_seed(0)
    network = MLP(2, [8])
    first = evaluate_losses(network, problem, config, lbfgs_points(problem, config))
    again = evaluate_losses(network, problem, config, lbfgs_points(problem, config))
    assert first == again and first["L1"] > 0 and first["L2"] > 0


def test_the_same_seed_repeats_a_cpu_run_and_another_seed_does_not(tmp_path, semidisk):
    runs = {}
    for name, seed in (("a", 3), ("b", 3), ("c", 4)):
        (tmp_path / name).mkdir()
        runs[name] = train(tiny_config(f"seed={seed}"), semidisk, tmp_path / name, summary=False).checkpoint
    same = runs["a"]["model"]["state_dict"], runs["b"]["model"]["state_dict"]
    assert all(torch.equal(same[0][k], same[1][k]) for k in same[0])
    other = runs["c"]["model"]["state_dict"]
    assert not torch.equal(same[0]["layers.0.weight"], other["layers.0.weight"])


def test_boundary_local_size_is_the_shortest_tangent_along_the_face(semidisk):
    """Closed forms: the semidisk's edges are its diameter (x = 2 xi - 1: tangent 2 R) and arcs of
    pi/4, pi/2, pi/4 (tangent pi/4 R, pi/2 R, pi/4 R); a corner may move along both of its edges.
    A box [0, a] x [0, b] x [0, c]: on a face the shorter of its two sides, on an edge all three."""
    from meshgen.neural.losses import boundary_local_size

    radius = 1.0
    points = np.array([[0.3, 0.0], [0.0, 0.6], [1.0, 0.2], [0.5, 1.0], [0.0, 0.0], [0.0, 1.0]])
    expected = np.array([2.0, np.pi / 4, np.pi / 4, np.pi / 2, np.pi / 4, np.pi / 4]) * radius
    np.testing.assert_allclose(boundary_local_size(semidisk.boundary, points), expected, rtol=1e-6)

    sides = np.array([3.0, 0.5, 2.0])
    box = np.array([[0.2, 0.7, 0.0], [1.0, 0.4, 0.9], [0.3, 0.0, 0.8], [0.0, 0.0, 0.4]])
    np.testing.assert_allclose(boundary_local_size(lambda p: p * sides, box), [0.5, 0.5, 2.0, 0.5], rtol=1e-12)


def test_the_relative_boundary_error_is_scale_free():
    """L2 with the error divided by the local size: the same for a geometry scaled by k (error and
    size scale alike), where the absolute L2 scales by k^2."""
    from meshgen.neural.losses import boundary_loss

    generator = torch.Generator().manual_seed(0)
    target, size = torch.rand((50, 3), generator=generator), 0.1 + torch.rand(50, generator=generator)
    predicted = target + 0.01 * torch.randn((50, 3), generator=generator)
    relative, distance = boundary_loss(predicted, target, 1.0, size)
    scaled, _ = boundary_loss(7.0 * predicted, 7.0 * target, 1.0, 7.0 * size)
    absolute, _ = boundary_loss(7.0 * predicted, 7.0 * target, 0.0)
    torch.testing.assert_close(scaled, relative)
    expected = ((predicted - target).norm(dim=1) / size).square().mean()
    assert relative > expected  # the point weights 1 + |e| only add
    assert math.isclose(float(absolute), 49.0 * float((predicted - target).square().sum(1).mean()), rel_tol=1e-5)
    torch.testing.assert_close(distance, (predicted - target).norm(dim=1) / size)

"""Section models: an extruded one-block geometry trained under the exact boundary is trained as the
2D network of its section, and its mesh is the section's extruded (``meshgen.neural.network_map``)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from neural_helpers import tiny_config

from meshgen.geometry.extrusion import geometry_extrusion, section_geometry
from meshgen.geometry.layout import smoothed
from meshgen.methods.tfi import parametric_grid, tfi
from meshgen.methods.winslow import winslow_residual
from meshgen.neural.checkpoint_data import CheckpointError
from meshgen.neural.model import MLP, describe, normalisation
from meshgen.neural.network_map import mesh_from_model, model_boundary_errors
from meshgen.run.chunked import neural_array

DIMS = (7, 6, 9)


def section_model(geometry, seed: int = 0) -> dict:
    """A section model of ``geometry`` (smoothed layout) with random weights: N of size ~0.05."""
    extrusion = geometry_extrusion(geometry)
    section = section_geometry(smoothed(geometry), extrusion)
    torch.manual_seed(seed)
    network = MLP(2, [10, 10])
    torch.nn.init.normal_(network.layers[-1].weight, std=0.05)
    center, scale = normalisation(section)
    return {**describe(network, [10, 10], True, center, scale), "extruded": extrusion.describe()}, network, section


def test_a_section_model_meshes_the_extrusion_of_its_section(semicylinder):
    """Every zeta layer is the zeta = 0 layer moved by zeta v (round-off), and that layer is the
    laid-out cap C + scale b N, N from torch in float64 (float32 precision: the mesh's forward pass
    is float32); with N = 0 the mesh is the 3D TFI of the smoothed layout (the cap extruded)."""
    model, network, section = section_model(semicylinder)
    coords = parametric_grid(DIMS)
    X = mesh_from_model(model, coords, smoothed(semicylinder))
    assert X.shape == tuple(n + 1 for n in DIMS) + (3,)
    direction = np.array(model["extruded"]["direction"])
    layers = X - coords[2][None, None, :, None] * direction
    np.testing.assert_allclose(layers, np.broadcast_to(layers[:, :, :1], layers.shape), rtol=0, atol=1e-15)
    assert np.all(X[:, :, 0, 2] == 0.0)  # the zeta = 0 cap in its plane (semicylinder: z = 0)
    grid = np.stack(np.meshgrid(*coords[:2], indexing="ij"), axis=-1)
    with torch.no_grad():
        N = network.double()(torch.from_numpy(grid.reshape(-1, 2))).numpy().reshape(grid.shape)
    bubble = 16 * grid[..., 0] * (1 - grid[..., 0]) * grid[..., 1] * (1 - grid[..., 1])
    cap = smoothed(semicylinder).boundary(np.column_stack([grid.reshape(-1, 2), np.zeros(grid[..., 0].size)]))
    expected = cap.reshape(grid.shape[:2] + (3,))[..., :2] + model["scale"] * bubble[..., None] * N
    np.testing.assert_allclose(X[:, :, 0, :2], expected, rtol=0, atol=1e-6 * model["scale"])
    assert np.abs(model["scale"] * bubble[..., None] * N).max() > 1e-3  # the network moves the nodes
    # the side faces are the geometry's (the section's edges are met exactly); the caps lie in their planes
    errors = model_boundary_errors(model, smoothed(semicylinder), coords)
    assert max(np.abs(e).max() for e in errors[:4]) < 1e-11  # the side faces' layout: solved to ~1e-13
    assert all(np.abs(e[..., 2]).max() < 1e-14 for e in errors[4:]) and np.abs(errors[4]).max() > 1e-4
    # a sub-grid that does not span the cube: the same nodes as the whole grid's
    sub = [coords[0][2:5], coords[1][1:], coords[2][3:]]
    np.testing.assert_allclose(mesh_from_model(model, sub, smoothed(semicylinder)), X[2:5, 1:, 3:], rtol=0, atol=1e-14)
    zero = {**model, "state_dict": {k: v * 0 if k.startswith("layers.2") else v for k, v in model["state_dict"].items()}}
    untrained = mesh_from_model(zero, coords, smoothed(semicylinder))
    np.testing.assert_allclose(untrained, tfi(smoothed(semicylinder), DIMS), rtol=0, atol=1e-11)


@pytest.mark.parametrize("block_nodes", [37, 257])
def test_a_section_models_chunked_mesh_is_its_in_memory_mesh_bit_for_bit(semicylinder, block_nodes):
    from meshgen.methods.correction import correct_boundary

    model, _, _ = section_model(semicylinder, seed=1)
    geometry, coords = smoothed(semicylinder), parametric_grid(DIMS)
    whole = mesh_from_model(model, coords, geometry)
    correct_boundary(whole, geometry, coords)
    chunked, info = neural_array(model, geometry, coords, block_nodes=block_nodes)
    assert np.array_equal(chunked.compute(), whole) and info["error_before"]["max"] > 0


def test_the_extruded_meshs_3d_winslow_residual_is_its_sections_2d_one_scaled(semicylinder):
    """With x = s(xi, eta) + zeta v, v square to s, the 3D metric has g33 = |v|^2, g13 = g23 = 0 and
    x_zeta zeta = x_xi zeta = 0, so the normalised 3D residual is the 2D one times
    g33 (g11 + g22) / (g33 (g11 + g22) + g11 g22 - g12^2), g from the central differences; its
    zeta component vanishes."""
    model, _, section = section_model(semicylinder, seed=2)
    coords = parametric_grid(DIMS)
    X = mesh_from_model(model, coords, smoothed(semicylinder))
    S = X[:, :, 0, :2]
    r3, r2 = winslow_residual(X), winslow_residual(S)
    h1, h2 = 1.0 / DIMS[0], 1.0 / DIMS[1]
    s1 = (S[2:, 1:-1] - S[:-2, 1:-1]) / (2 * h1)
    s2 = (S[1:-1, 2:] - S[1:-1, :-2]) / (2 * h2)
    g11, g22, g12 = (s1 * s1).sum(-1), (s2 * s2).sum(-1), (s1 * s2).sum(-1)
    g33 = float(np.sum(np.square(model["extruded"]["direction"])))
    ratio = g33 * (g11 + g22) / (g33 * (g11 + g22) + g11 * g22 - g12**2)
    expected = ratio[..., None] * r2
    assert np.abs(r2).max() > 1e-3  # a random network's section is no Winslow grid
    for k in range(DIMS[2] - 1):
        np.testing.assert_allclose(r3[:, :, k, :2], expected, rtol=0, atol=1e-11 * np.abs(expected).max())
    assert np.abs(r3[..., 2]).max() < 1e-12


def test_a_section_model_refuses_a_geometry_that_is_not_its_extrusion(semicylinder):
    from meshgen.geometry import load_geometry

    model, _, _ = section_model(semicylinder)
    longer = semicylinder.with_params(length=semicylinder.values["length"] * 2)
    for other in (longer, load_geometry("canal")):
        with pytest.raises(CheckpointError, match="not that extrusion"):
            mesh_from_model(model, parametric_grid(DIMS), smoothed(other))


def test_only_an_extruded_geometry_under_the_exact_boundary_trains_its_section(semicylinder):
    from meshgen.geometry import load_geometry
    from meshgen.neural.train import section_extrusion

    exact, soft = tiny_config(preset="exact"), tiny_config()
    assert section_extrusion(exact, semicylinder) is not None and section_extrusion(soft, semicylinder) is None
    assert exact.adam.section_steps == 0 and exact.lbfgs.section_steps == 0 and soft.adam.section_steps is None
    for name in ("canal", "flower", "topcurve", "semidisk"):
        assert section_extrusion(exact, load_geometry(name)) is None
    three_d = {"model": {"dim": 3}}
    assert section_extrusion(exact, semicylinder, resume=three_d) is None  # a 3D run resumes as 3D


def test_the_exact_preset_trains_the_section_and_meshes_through_the_cli(run_cli, tmp_path, semicylinder):
    """``meshgen train --preset exact`` on the semicylinder: a 2D network and the extrusion in the
    checkpoint, no step taken (``section_steps`` 0: N = 0 is the lattice solution: its 3D Winslow
    residual on the lattice is round-off); ``meshgen mesh``
    meshes an exact extrusion from it, the smoothed layout's TFI, in memory and chunked alike."""
    import meshio

    from meshgen.neural.checkpoint import load_checkpoint

    run = tmp_path / "run"
    result = run_cli("train", "-g", "semicylinder", "--preset", "exact", "--set", "test.interior=50", "--out", run)
    assert result.returncode == 0, result.stderr
    assert "the networks map its 2D section" in result.stdout and "for 0 steps" in result.stdout
    checkpoint = load_checkpoint(run / "checkpoint.pt")
    model = checkpoint["model"]
    assert model["dim"] == 2 and checkpoint["geometry"]["dim"] == 3 and model["extruded"]["direction"] == [0.0, 0.0, 2.0]
    # on the layout's lattice (64 x 64 section cells) the 3D Winslow residual is the lattice solve's round-off
    from meshgen.neural.model import mesh_from_checkpoint

    lattice = parametric_grid((64, 64, 4))
    assert np.abs(winslow_residual(mesh_from_checkpoint(checkpoint, lattice, semicylinder))).max() < 1e-8
    assert np.abs(winslow_residual(tfi(semicylinder, (64, 64, 4)))).max() > 1e-3  # the fixed layout's TFI: no solution
    dims = (10, 8, 6)
    mesh = ["mesh", "--method", "neural", "--checkpoint", run / "checkpoint.pt", "--dims", *map(str, dims)]
    assert run_cli(*mesh, "--no-correct", "-o", tmp_path / "raw.vtu").returncode == 0
    assert run_cli(*mesh, "-o", tmp_path / "m.vtu").returncode == 0
    assert run_cli(*mesh, "--chunked", "-o", tmp_path / "m.vts").returncode == 0
    shape = tuple(n + 1 for n in dims) + (3,)
    laid_out = tfi(smoothed(semicylinder), dims)
    for name in ("raw.vtu", "m.vtu"):
        np.testing.assert_allclose(meshio.read(tmp_path / name).points.reshape(shape), laid_out, rtol=0, atol=1e-11)
    vtk = pytest.importorskip("vtk")
    from vtk.util.numpy_support import vtk_to_numpy

    reader = vtk.vtkXMLStructuredGridReader()
    reader.SetFileName(str(tmp_path / "m.vts"))
    reader.Update()
    chunked = vtk_to_numpy(reader.GetOutput().GetPoints().GetData())  # VTK's order: i fastest
    corrected = meshio.read(tmp_path / "m.vtu").points.reshape(shape)
    assert np.array_equal(chunked, np.transpose(corrected, (2, 1, 0, 3)).reshape(-1, 3))


def test_section_steps_train_the_section_from_the_lattice_solution(run_cli, tmp_path, semicylinder):
    """With ``section_steps`` set the section is trained: the lattice loss at N = 0 (the smoothed
    layout's cap) is round-off, Adam moves it away, L-BFGS brings it down again; --no-correct meshes
    the network's own section, extruded exactly; the corrected mesh pins the caps to the layout's."""
    import csv

    import meshio

    sets = ["adam.section_steps=6", "lbfgs.section_steps=2", "lbfgs.max_iter=4", "model.widths=[12,12]", "test.interior=50"]
    args = [a for o in sets for a in ("--set", o)]
    assert run_cli("train", "-g", "semicylinder", "--preset", "exact", *args, "--out", tmp_path / "run").returncode == 0
    with open(tmp_path / "run" / "history.csv") as handle:
        rows = list(csv.DictReader(handle))
    losses = [float(row["L1"]) for row in rows]
    assert [row["stage"] for row in rows] == ["adam"] * 6 + ["lbfgs"] * 2
    assert losses[0] < 1e-13 and max(losses) > 1e3 * losses[0] and losses[-1] < max(losses)
    dims = (10, 8, 6)
    mesh = ["mesh", "--method", "neural", "--checkpoint", tmp_path / "run" / "checkpoint.pt", "--dims", *map(str, dims)]
    assert run_cli(*mesh, "--no-correct", "-o", tmp_path / "raw.vtu").returncode == 0
    shape = tuple(n + 1 for n in dims) + (3,)
    X = meshio.read(tmp_path / "raw.vtu").points.reshape(shape)
    layers = X - parametric_grid(dims)[2][None, None, :, None] * np.array([0.0, 0.0, 2.0])
    np.testing.assert_allclose(layers, np.broadcast_to(layers[:, :, :1], shape), rtol=0, atol=1e-14)
    laid_out = tfi(smoothed(semicylinder), dims)
    assert 1e-9 < np.abs(X - laid_out).max() < 1e-2  # the network moved the section's nodes, a little
    assert run_cli(*mesh, "-o", tmp_path / "m.vtu").returncode == 0
    corrected = meshio.read(tmp_path / "m.vtu").points.reshape(shape)
    for cap in (0, -1):  # X + C[g - X] with the (1 - t)^p blending: the caps on the layout's nodes
        np.testing.assert_allclose(corrected[:, :, cap], laid_out[:, :, cap], rtol=0, atol=1e-11)


def test_on_the_fixed_layout_the_exact_preset_trains_its_section(run_cli, tmp_path):
    """The preset's ``section_steps`` (0) hold on the smoothed layout only, whose cap solves the
    lattice equations; the fixed layout's cap is a Coons patch: the section trains its ``steps``
    and the loss falls from where it starts."""
    import csv

    sets = [
        "boundary_layout=fixed",
        "adam.steps=8",
        "lbfgs.steps=2",
        "lbfgs.max_iter=4",
        "model.widths=[12,12]",
        "test.interior=50",
    ]
    args = [a for o in sets for a in ("--set", o)]
    assert run_cli("train", "-g", "semicylinder", "--preset", "exact", *args, "--out", tmp_path / "run").returncode == 0
    with open(tmp_path / "run" / "history.csv") as handle:
        rows = list(csv.DictReader(handle))
    assert [row["stage"] for row in rows] == ["adam"] * 8 + ["lbfgs"] * 2
    assert float(rows[-1]["L1"]) < float(rows[0]["L1"])


def test_an_interrupted_section_run_resumes_through_the_cli_as_the_uninterrupted_one(run_cli, tmp_path, semicylinder):
    """A section run stopped in its Adam stage goes on with ``meshgen train --resume`` (its 2D
    network on the 3D geometry) to the weights of the run that was never stopped."""
    from neural_helpers import Recorder

    from meshgen.neural.checkpoint import load_checkpoint
    from meshgen.neural.train import train

    config = tiny_config("pretrain.steps=0", "adam.section_steps=8", "lbfgs.section_steps=2", preset="exact")
    for name in ("straight", "stopped"):
        (tmp_path / name).mkdir()
    straight = train(config, semicylinder, tmp_path / "straight", summary=False)
    assert straight.step == 10 and straight.checkpoint["model"]["dim"] == 2
    recorder = Recorder(stop_after=5)
    train(config, semicylinder, tmp_path / "stopped", reporter=recorder, stop=recorder.should_stop, summary=False)
    assert load_checkpoint(tmp_path / "stopped" / "checkpoint.pt")["stage"] == "adam"
    result = run_cli("train", "--resume", tmp_path / "stopped" / "checkpoint.pt", "-q")
    assert result.returncode == 0, result.stderr
    resumed = load_checkpoint(tmp_path / "stopped" / "checkpoint.pt")
    assert resumed["stage"] == "done" and resumed["step"] == 10
    for key, tensor in straight.checkpoint["model"]["state_dict"].items():
        assert torch.equal(tensor, resumed["model"]["state_dict"][key]), key

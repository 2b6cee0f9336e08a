"""Training grids on the smoothed layout's fine lattice (``points.lattice``) and the exact-boundary
residual with TFI's differences in float64 (design notes §18).

The smoothed layout's faces solve the discrete Winslow equations on a lattice of spacing
1/RESOLUTION; the semicylinder is an extrusion, so its TFI is the extrusion of its cap and solves
the 3D discrete equations on that lattice too. Checked here against an independent float64
computation of the residual of TFI + b N from the boundary map.
"""

from __future__ import annotations

import numpy as np
import pytest
import torch
from neural_helpers import Recorder, tiny_config

from meshgen.geometry.layout import RESOLUTION, with_layout
from meshgen.geometry.plugins import load_geometry
from meshgen.methods.tfi import parametric_grid, transfinite
from meshgen.neural.checkpoint import load_checkpoint
from meshgen.neural.config import ConfigError, from_dict, resolve_config
from meshgen.neural.derivatives import grid_derivatives, grid_points, lattice_grid_from_draws, training_grid
from meshgen.neural.model import MLP, bubble, mesh_from_checkpoint, normalisation, normalised_boundary
from meshgen.neural.problem import (
    Problem,
    grid_residual,
    lattice_blocks,
    lattice_tfi_derivatives,
    lbfgs_points,
    make_test_set,
    sample_pde_points,
    sample_step,
)
from meshgen.neural.problem import (
    test_loss as held_out_loss,
)
from meshgen.neural.train import train
from meshgen.neural.winslow import winslow_residual


@pytest.fixture(scope="module")
def problem():
    geometry = with_layout(load_geometry("semicylinder"), "smoothed")
    center, scale = normalisation(geometry)
    return Problem(3, normalised_boundary(geometry, center, scale), center, scale, True, torch.device("cpu"))


def zero_network():
    network = MLP(3, [8, 8])
    torch.nn.init.zeros_(network.layers[-1].weight)
    torch.nn.init.zeros_(network.layers[-1].bias)
    return network


def test_lattice_grids_lie_on_the_lattice_inside_the_cube():
    draws = torch.rand((50, 6), generator=torch.Generator().manual_seed(0), dtype=torch.float64)
    axes, spacing = lattice_grid_from_draws(draws, 16, RESOLUTION)
    assert [tuple(a.shape) for a in axes] == [(50, 18)] * 3 and all(float(h) == 1.0 / RESOLUTION for h in spacing)
    for axis in axes:
        steps = axis * RESOLUTION
        assert torch.equal(steps, steps.round()) and float(axis.min()) >= 0.0 and float(axis.max()) <= 1.0
        torch.testing.assert_close(axis[:, 1:] - axis[:, :-1], torch.full((50, 17), 1.0 / RESOLUTION, dtype=torch.float64))
    ends = lattice_grid_from_draws(torch.tensor([0.0, 0.0, 0.5, 0.999999], dtype=torch.float64), 16, RESOLUTION)[0]
    assert float(ends[0][0]) == 0.0 and float(ends[1][-1]) == 1.0  # the first and the last lattice position
    # a batch of grids: each the tensor grid of its own axes
    nodes = grid_points(axes)
    assert torch.equal(nodes[7], grid_points([a[7] for a in axes]))


def test_lattice_tfi_differences_are_those_of_tfi_at_the_grid_nodes(problem):
    """The Adam step's TFI differences sliced from the whole lattice's (computed once) are the
    central differences of TFI evaluated point by point at the grid's nodes, in NumPy float64:
    at random lattice grids and at the cube's two far corners."""
    draws = torch.rand((4, 6), generator=torch.Generator().manual_seed(5), dtype=torch.float64)
    draws = torch.cat([draws, torch.zeros((1, 6), dtype=torch.float64), torch.full((1, 6), 0.999999, dtype=torch.float64)])
    h = 1.0 / RESOLUTION
    for batch in draws:
        axes, spacing = lattice_grid_from_draws(batch, 6, RESOLUTION)
        first, second = lattice_tfi_derivatives(problem, axes, spacing)
        nodes = np.stack(np.meshgrid(*[a.numpy() for a in axes], indexing="ij"), axis=-1)  # (8, 8, 8, 3)
        X = transfinite(problem.boundary, list(nodes.reshape(-1, 3).T)).reshape(8, 8, 8, 3)
        inner = slice(1, -1)
        x_i = (X[2:, inner, inner] - X[:-2, inner, inner]) / (2 * h)  # d r / d xi_1
        x_ii = (X[2:, inner, inner] - 2 * X[inner, inner, inner] + X[:-2, inner, inner]) / h**2
        x_23 = (X[inner, 2:, 2:] - X[inner, 2:, :-2] - X[inner, :-2, 2:] + X[inner, :-2, :-2]) / (4 * h * h)
        assert (
            first.dtype == torch.float32 and tuple(first.shape) == (6, 6, 6, 3, 3) and tuple(second.shape) == (6, 6, 6, 3, 3, 3)
        )
        np.testing.assert_allclose(first[..., 0, :].numpy(), x_i, rtol=1e-6, atol=1e-6 * np.abs(x_i).max())
        np.testing.assert_allclose(second[..., 0, 0, :].numpy(), x_ii, rtol=1e-5, atol=1e-5 * np.abs(x_ii).max())
        np.testing.assert_allclose(second[..., 1, 2, :].numpy(), x_23, rtol=1e-5, atol=1e-5 * np.abs(x_23).max() + 1e-6)


def test_adam_step_inputs_on_the_lattice_carry_the_grids_tfi_differences(problem):
    config = resolve_config("exact", None, [], None, 0)
    inputs = sample_step(config, problem, torch.Generator().manual_seed(2))
    axes, _ = lattice_grid_from_draws(inputs["grid"], 16, RESOLUTION)
    nodes = np.stack(np.meshgrid(*[a.numpy() for a in axes], indexing="ij"), axis=-1)
    X = transfinite(problem.boundary, list(nodes.reshape(-1, 3).T)).reshape(18, 18, 18, 3)
    x_k = (X[1:-1, 1:-1, 2:] - X[1:-1, 1:-1, :-2]) * (RESOLUTION / 2)  # d r / d xi_3
    np.testing.assert_allclose(inputs["tfi_first"][..., 2, :].numpy(), x_k, rtol=1e-6, atol=1e-6 * np.abs(x_k).max())


def test_held_out_loss_keeps_tfi_not_the_network_between_checkpoints(problem):
    """test_loss keeps TFI at its held-out points from its first call: a second network's loss on
    the same test set equals its loss on a fresh one, and differs from the first network's."""
    config = from_dict({"test": {"interior": 50, "boundary": 40}})
    first, second = zero_network(), MLP(3, [8, 8])
    torch.nn.init.normal_(second.layers[-1].weight, std=0.05)
    shared = make_test_set(problem, config)
    before = held_out_loss(first, problem, shared)
    assert set(shared["tfi"]) == {"stencils", "boundary"}
    after = held_out_loss(second, problem, shared)
    assert after == held_out_loss(second, problem, make_test_set(problem, config))
    assert after["pde"] != before["pde"] and after["boundary"] < 1e-28  # the bubble keeps the boundary either way


def test_tfi_of_an_extruded_shape_solves_the_lattice_equations_and_not_others(problem):
    network = zero_network()  # N = 0: the map is TFI of the smoothed layout
    generator = torch.Generator().manual_seed(1)
    axes, spacing = lattice_blocks(resolve_config("exact"), 3, generator)
    shifted, shifted_spacing = training_grid(3, 16, generator, 0.8)  # the grids of points.lattice: false
    with torch.no_grad():
        assert float(grid_residual(network, problem, axes, spacing).abs().max()) < 1e-6
        assert float(grid_residual(network, problem, shifted, shifted_spacing).abs().max()) > 1e-3


def test_split_residual_equals_the_float64_residual_of_tfi_plus_bubble_network(problem):
    torch.manual_seed(0)
    network = MLP(3, [8, 8])
    with torch.no_grad():
        for tensor in network.layers[-1].parameters():  # N ~ 1e-4: a trained exact network's size on this shape
            tensor.mul_(1e-4)
    config = resolve_config("exact")
    axes, spacing = sample_pde_points(config, 3, torch.Generator().manual_seed(2))
    with torch.no_grad():
        ours = grid_residual(network, problem, axes, spacing)
        nodes = grid_points(axes)
        flat = nodes.reshape(-1, 3)
        tfi = torch.from_numpy(transfinite(problem.boundary, list(flat.numpy().T)))
        values = tfi + bubble(flat)[:, None] * network.double()(flat)
        _, first, second = grid_derivatives(values.reshape(nodes.shape), spacing)
        reference = winslow_residual(first, second)
        # the same in float32 throughout: TFI's own differences lose digits to cancellation
        _, first, second = grid_derivatives(values.float().reshape(nodes.shape), [float(h) for h in spacing])
        plain = winslow_residual(first, second)
    assert float(reference.abs().max()) > 1e-5  # a residual the comparison can see
    error = float((ours.double() - reference).abs().max())
    assert error < 1e-2 * float(reference.abs().max())
    assert error < 0.01 * float((plain.double() - reference).abs().max())  # float32 alone: above the residual itself


def float64_reference(network, problem, axes, spacing):
    """The Winslow residual of TFI + b N at the interior nodes of the grid ``axes``, float64 from
    the boundary map: TFI evaluated directly, the differences of the whole map."""
    nodes = grid_points(axes)
    flat = nodes.reshape(-1, 3)
    tfi = torch.from_numpy(transfinite(problem.boundary, list(flat.numpy().T)))
    values = tfi + bubble(flat)[:, None] * network.double()(flat)
    _, first, second = grid_derivatives(values.reshape(nodes.shape), spacing)
    return winslow_residual(first, second)


def test_lbfgs_float64_points_give_the_float64_residual(problem):
    torch.manual_seed(0)
    network = MLP(3, [8, 8])
    with torch.no_grad():
        for tensor in network.layers[-1].parameters():
            tensor.mul_(1e-4)
    config = resolve_config("exact")
    assert config.lbfgs.float64
    axes, spacing, tfi_derivatives = lbfgs_points(problem, config)["pde"]
    assert all(t.dtype == torch.float64 for t in tfi_derivatives)
    with torch.no_grad():
        network.double()
        ours = grid_residual(network, problem, axes, spacing, tfi_derivatives)
        reference = float64_reference(network, problem, axes, spacing)
    assert ours.dtype == torch.float64 and float(reference.abs().max()) > 1e-5
    # float64 round-off of second differences over h^2 = 1/64^2 (float32: 1e-2 of the residual, above)
    assert float((ours - reference).abs().max()) < 1e-8 * float(reference.abs().max())


@pytest.mark.parametrize("stop_after", [None, 13])  # the whole run, and stopped inside the float64 L-BFGS stage
def test_lbfgs_float64_run_keeps_float64_weights_meshes_and_resumes_exactly(tmp_path, semidisk, stop_after):
    config = tiny_config(preset="exact")  # 2 pretrain, 10 Adam and 2 L-BFGS steps
    assert config.lbfgs.float64
    (tmp_path / "straight").mkdir()
    straight = train(config, semidisk, tmp_path / "straight", summary=False)
    weights = straight.checkpoint["model"]["state_dict"]
    assert all(tensor.dtype == torch.float64 for tensor in weights.values())
    if stop_after is None:
        # the mesh path rounds the weights to float32: the map moves by far less than a solver sees
        coords = parametric_grid([6, 5])
        X = mesh_from_checkpoint(straight.checkpoint, coords, semidisk)
        model = straight.checkpoint["model"]
        network = MLP(2, model["widths"]).double()
        network.load_state_dict(model["state_dict"])
        xi = torch.stack(torch.meshgrid(*[torch.from_numpy(c) for c in coords], indexing="ij"), -1).reshape(-1, 2)
        with torch.no_grad():
            move = (bubble(xi)[:, None] * network(xi)).numpy().reshape(X.shape) * model["scale"]
        tfi = transfinite(with_layout(semidisk, "smoothed").boundary, np.meshgrid(*coords, indexing="ij"))
        np.testing.assert_allclose(X, tfi + move, rtol=0, atol=1e-6 * np.abs(move).max() + 1e-15)
        return
    (tmp_path / "resumed").mkdir()
    recorder = Recorder(stop_after=stop_after)
    first = train(config, semidisk, tmp_path / "resumed", reporter=recorder, stop=recorder.should_stop, summary=False)
    saved = load_checkpoint(first.checkpoint_path)
    assert saved["stage"] == "lbfgs" and saved["model"]["state_dict"]["layers.0.weight"].dtype == torch.float64
    second = train(from_dict(saved["config"]), semidisk, tmp_path / "resumed", resume=saved, summary=False)
    for key, tensor in weights.items():
        assert torch.equal(tensor, second.checkpoint["model"]["state_dict"][key]), key


def test_lattice_needs_finite_differences():
    with pytest.raises(ConfigError, match="'points.lattice' needs method.derivatives fd"):
        resolve_config("pinn", None, ["points.lattice=true"])

"""The neural method for block sets: one tiny training run of the pipe (a few dozen steps), meshed
through the request path, checked against closed forms (the wall is the circle of radius R, the
inlet and outlet the planes z = 0 and z = L), an independent Jacobian computation
(``mesh_checks.corner_jacobians``) and the blocks' own interface nodes compared pairwise."""

import numpy as np
import pytest
from mesh_checks import corner_jacobians
from neural_helpers import TINY, tiny_config

import meshgen
from meshgen.errors import MeshgenError
from meshgen.formats.multiblock import read_zones
from meshgen.geometry.block_nodes import face_index
from meshgen.geometry.blocks import load_block_set
from meshgen.geometry.extrusion import extrusion_of, section_of
from meshgen.neural.checkpoint import load_checkpoint
from meshgen.neural.train import train
from meshgen.run.request import MeshRequest, carry_out

RADIUS, LENGTH = 0.5, 4.0  # the pipe's defaults


TINY_BLOCKS = ("pretrain.steps=20", "pretrain.points=300", "lbfgs.max_iter=10", "adam.steps=20", "model.widths=[16,16]")


@pytest.fixture(scope="module")
def pipe_checkpoint(tmp_path_factory):
    """A pipe model after 20 TFI-fit, 20 Adam and 2 L-BFGS steps (about 4 s of CPU): every stage of
    the Winslow training from the TFI (``pretrain.target=tfi``; the default starts from the
    elliptic mesh and stops there, ``test_elliptic_start.py``)."""
    run_dir = tmp_path_factory.mktemp("pipe-run")
    config = tiny_config(*TINY_BLOCKS, "pretrain.target=tfi")
    block_set = load_block_set("pipe", None, (4, 2, 4))
    result = train(config, block_set, run_dir, summary=False, geometry_spec="pipe")
    return result.checkpoint_path


def test_tiny_training_writes_a_block_checkpoint(pipe_checkpoint):
    checkpoint = load_checkpoint(pipe_checkpoint)  # the restricted loader: plain data only
    assert checkpoint["stage"] == "done" and checkpoint["step"] == 20 + 20 + 2
    assert checkpoint["model"]["blocks"] == ["core", "east", "north", "west", "south"]
    assert checkpoint["geometry"]["blocks"] == checkpoint["model"]["blocks"]
    weights = checkpoint["model"]["state_dict"]
    assert {key.split(".")[1] for key in weights} == {"0", "1", "2", "3", "4"}  # one network per block


@pytest.mark.parametrize("dims, polish", [((4, 2, 3), None), ((6, 3, 5), None), ((4, 2, 3), True)])
def test_neural_pipe_is_conforming_exact_on_its_boundary_and_valid(pipe_checkpoint, dims, polish):
    made = meshgen.mesh("pipe", dims, method="neural", model=str(pipe_checkpoint), polish=polish)
    assert ("polish" in made.info) == bool(polish)  # polished only when asked
    assert made.method == "neural" and made.X is None
    block_set = made.geometry
    assert made.info["correction"]["interface_gap_before"] > 0  # the networks alone do not conform
    for interface in block_set.interfaces:  # interface nodes: the same numbers in both blocks
        index_a, index_b = face_index(block_set, interface)
        nodes_a = made.blocks[interface.a].reshape(-1, 3)[index_a]
        nodes_b = made.blocks[interface.b].reshape(-1, 3)[index_b]
        assert np.array_equal(nodes_a, nodes_b)
    for block, X in zip(block_set.names, made.blocks):
        assert np.all(corner_jacobians(X) > 0), block  # no inverted (or degenerate) cell
        np.testing.assert_allclose(X[..., 0, 2], 0.0, atol=1e-12)  # inlet plane
        np.testing.assert_allclose(X[..., -1, 2], LENGTH, rtol=1e-13)  # outlet plane
        if block != "core":  # xi = 1 of every wall block is on the wall
            np.testing.assert_allclose(np.hypot(X[-1, ..., 0], X[-1, ..., 1]), RADIUS, rtol=1e-13)
    inlet = np.concatenate([X[..., 0, :2].reshape(-1, 2) for X in made.blocks])
    assert np.hypot(*inlet.T).max() <= RADIUS * (1 + 1e-13)  # sliding nodes stay inside the disc


def test_interface_stencil_is_the_winslow_residual_of_one_smooth_map():
    """Two blocks of a box split at x = 1 (b twice as long, its xi reversed or not): the residual
    on the glued stencil equals the single map's Winslow residual on an ordinary stencil."""
    import torch

    from meshgen.geometry import cube
    from meshgen.neural.derivatives import stencil_derivatives
    from meshgen.neural.interfaces import INTERFACE_STEP, BlockProblem, interface_stencil
    from meshgen.neural.winslow import winslow_residual

    def smooth(p):
        x, y, z = p.unbind(-1)
        return torch.stack([x + 0.1 * torch.sin(y) * x**2, y + 0.2 * x * z + 0.1 * y**2, z + 0.05 * x**2 * y], -1)

    problem = BlockProblem(3, ("a", "b"), [], [], [], np.zeros(3), 1.0, torch.device("cpu"))
    tangent = 0.1 + 0.8 * torch.rand(6, 2, generator=torch.Generator().manual_seed(0))
    _, first, second = stencil_derivatives(smooth, torch.cat([torch.ones(6, 1), tangent], 1), INTERFACE_STEP)
    expected = winslow_residual(first, second)
    block_a = smooth
    forward = lambda xi: smooth(torch.stack([1 + 2 * xi[..., 0], xi[..., 1], xi[..., 2]], -1))  # noqa: E731
    reversed_ = lambda xi: smooth(torch.stack([3 - 2 * xi[..., 0], 1 - xi[..., 1], xi[..., 2]], -1))  # noqa: E731
    xi0, xi1 = cube.face_named("xi0", 3), cube.face_named("xi1", 3)
    for block_b, face_b, transform in ((forward, xi0, (1, 2, 3)), (reversed_, xi1, (-1, -2, 3))):
        residual, _, _ = interface_stencil([block_a, block_b], problem, (0, xi1, 1, face_b, transform, 0.5), tangent)
        torch.testing.assert_close(residual, expected, atol=2e-5, rtol=1e-4)


def test_train_the_pipe_through_the_cli_and_mesh_the_newest_run(run_cli, tmp_path, monkeypatch):
    shorter = ("pretrain.steps=3", "adam.steps=3")  # the command's path, not the training, is under test
    tiny = [f"--set={item}" for item in (*TINY, *TINY_BLOCKS, *shorter)]
    trained = run_cli("train", "-g", "pipe", "--out", "runs/pipe-1", "--quiet", *tiny)
    assert trained.returncode == 0, trained.stderr
    # the fit to the elliptic mesh alone: a block set started from it takes adam/lbfgs.block_steps (0)
    assert "Trained pipe for 3 steps" in trained.stdout
    assert "'pipe' is an extrusion along (0, 0, 4): the networks map its 2D section" in trained.stdout
    monkeypatch.chdir(tmp_path)  # auto: the newest run of the pipe under ./runs
    made = meshgen.mesh("pipe", (4, 2, 3))
    assert made.method == "neural" and "runs/pipe-1/checkpoint.pt" in made.notes[0]
    made.write(tmp_path / "pipe.cgns")
    zones = read_zones(tmp_path / "pipe.cgns")
    assert [zone["name"] for zone in zones] == list(made.geometry.names)
    for zone, X in zip(zones, made.blocks):  # the file holds the mesh
        np.testing.assert_array_equal(zone["X"], X)
    assert all(len(zone["connections"]) >= 3 for zone in zones)  # every interface, from both sides


def test_block_model_refused_for_a_single_block_geometry(pipe_checkpoint):
    with pytest.raises(MeshgenError, match="trained on 'pipe', not on 'semicylinder'"):
        meshgen.mesh("semicylinder", (4, 4, 4), method="neural", model=str(pipe_checkpoint))


def test_checkpoint_alone_names_its_block_set(pipe_checkpoint):
    made = carry_out(MeshRequest((4, 2, 3), checkpoint=str(pipe_checkpoint), quality=False))  # no geometry given
    assert made.method == "neural" and made.geometry.name == "pipe" and len(made.blocks) == 5


def test_neural_without_a_model_is_one_clear_error(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # no runs/ here
    with pytest.raises(MeshgenError, match="no trained model for pipe"):
        meshgen.mesh("pipe", (4, 2, 3), method="neural")


@pytest.mark.parametrize(
    "args, named",
    [
        (["--preset", "exact"], "model.exact_boundary=True, points.lattice=True"),
        (["--set", "points.lattice=true", "--set", "adam.lr=1e-3"], "points.lattice=True"),
        (["--set", "method.derivatives=autograd"], "method.derivatives=autograd"),
        (["--set", "points.boundary_pool=0"], "points.boundary_pool=0"),
    ],
)
def test_configuration_keys_a_block_set_cannot_use_are_a_one_line_error(tmp_path, capsys, args, named):
    from meshgen.cli import cli

    out = tmp_path / "run"
    with pytest.raises(SystemExit) as stopped:
        cli.main(["train", "-g", "pipe", *args, "--out", str(out)])
    err = capsys.readouterr().err
    assert stopped.value.code == 2 and not out.exists()  # refused before any training or folder
    lines = err.strip().splitlines()
    assert len(lines) == 1 and f"block set 'pipe' cannot use {named} (" in lines[0], err
    assert "adam.lr" not in lines[0]  # a key the block set uses is not named


def test_a_block_run_honours_lbfgs_float64_and_its_float64_terms_agree_with_float32(tmp_path):
    """lbfgs.float64: the networks (and so the checkpoint's weights) go to float64 for the L-BFGS
    stage; the terms computed in float64 agree with the float32 ones to float32's precision."""
    import torch

    from meshgen.neural.interfaces import (
        BlockNetworks,
        block_boundary_term,
        block_pde_term,
        block_problem,
        block_samples,
        fixed_block_points,
        patch_pool,
    )

    config = tiny_config(*TINY_BLOCKS, "adam.steps=2", "pretrain.steps=2", "lbfgs.max_iter=3", "lbfgs.float64=true")
    block_set = load_block_set("pipe", None, (4, 2, 4))
    result = train(config, block_set, tmp_path, summary=False, geometry_spec="pipe")
    checkpoint = load_checkpoint(result.checkpoint_path)
    weights = checkpoint["model"]["state_dict"]
    assert {value.dtype for value in weights.values()} == {torch.float64}
    made = meshgen.mesh("pipe", (4, 2, 3), method="neural", model=str(result.checkpoint_path))  # float64 weights load
    assert all(np.isfinite(X).all() for X in made.blocks)

    section = section_of(block_set, extrusion_of(block_set))  # what the pipe's networks are trained on
    problem = block_problem(section, torch.device("cpu"), checkpoint["model"]["center"], checkpoint["model"]["scale"])
    networks = BlockNetworks(2, [16, 16], 5)
    networks.load_state_dict(weights)
    pool = patch_pool(problem, 64, 1)
    pde_sample, boundary_sample = block_samples(config, problem, fixed_block_points(problem, config, 64, 2), random=False)
    terms = {}
    for dtype in (torch.float64, torch.float32):
        nets = networks.to(dtype).networks
        with torch.no_grad():
            terms[dtype] = (
                block_pde_term(nets, problem, pde_sample),
                block_boundary_term(nets, problem, config, pool, boundary_sample),
            )
    assert all(value.dtype == torch.float64 for value in terms[torch.float64])
    for high, low in zip(terms[torch.float64], terms[torch.float32]):
        assert float(high) > 0 and float(low) == pytest.approx(float(high), rel=1e-2)


def test_junction_edges_of_the_pipe_and_their_weights():
    """The pipe's junction edges are the core's four long edges (three blocks around each): on a
    core face, both ends of its tangent across the section; on a face between two wall blocks, the
    end at the core (xi = 0), not the one on the wall. Weights: (d / margin)^2, capped at 1."""
    import torch

    from meshgen.neural.interfaces import JUNCTION_MARGIN, block_problem, junction_weights

    block_set = load_block_set("pipe", None, (4, 2, 4))
    problem = block_problem(block_set, torch.device("cpu"))
    for (a, face_a, *_), ends in zip(problem.interfaces, problem.junctions):
        across = face_a.tangent_axes.index(1 if face_a.axis == 0 else 0)  # the tangent in the section
        if problem.names[a] == "core":
            assert sorted(ends) == [(across, 0), (across, 1)]
        else:
            assert ends == [(0, 0)] and face_a.tangent_axes[0] == 0  # xi = 0: the core's corner
    tangent = torch.tensor([[0.0, 0.5], [0.1, 0.3], [0.5, 0.01], [0.9, 0.9], [1.0, 0.0]], dtype=torch.float64)
    d = np.array([0.0, 0.1, 0.5, 0.1, 0.0])  # distance from the tangent-0 ends (both junctions)
    expected = np.minimum(d / JUNCTION_MARGIN, 1.0) ** 2
    np.testing.assert_allclose(junction_weights(tangent, [(0, 0), (0, 1)]).numpy(), expected, rtol=1e-12)
    one_end = np.minimum(tangent[:, 0].numpy() / JUNCTION_MARGIN, 1.0) ** 2
    np.testing.assert_allclose(junction_weights(tangent, [(0, 0)]).numpy(), one_end, rtol=1e-12)
    assert torch.all(junction_weights(tangent, []) == 1.0)


def test_the_pull_towards_the_tfi_adds_its_weighted_distance_to_l1():
    """L1 with the problem's pool of TFI points is L1 without it plus TFI_ANCHOR times the mean over
    blocks of the mean squared distance of each network from the pool's targets (NumPy here)."""
    import torch

    from meshgen.methods.tfi import transfinite
    from meshgen.neural.interfaces import (
        TFI_ANCHOR,
        BlockNetworks,
        block_pde_term,
        block_problem,
        block_samples,
        fixed_block_points,
        tfi_anchor_pool,
    )

    config = tiny_config(*TINY_BLOCKS)
    problem = block_problem(load_block_set("pipe", None, (4, 2, 4)), torch.device("cpu"))
    torch.manual_seed(0)
    networks = BlockNetworks(3, [8], 5).double().networks
    sample, _ = block_samples(config, problem, fixed_block_points(problem, config, 32, 1), random=False)
    pools = tfi_anchor_pool(problem, 40, 7)
    for boundary, pool in zip(problem.boundaries, pools):  # the targets: each block's TFI at the points
        points = pool["points"].double().numpy()
        np.testing.assert_allclose(pool["targets"].numpy(), transfinite(boundary, list(points.T)), atol=1e-7)
    with torch.no_grad():
        plain = float(block_pde_term(networks, problem, sample))
        problem.anchor = pools
        anchored = float(block_pde_term(networks, problem, sample))
        distances = [
            np.mean(np.sum((net(p["points"].double()).numpy() - p["targets"].double().numpy()) ** 2, axis=1))
            for net, p in zip(networks, pools)
        ]
    assert anchored - plain == pytest.approx(TFI_ANCHOR * np.mean(distances), rel=1e-9)
    assert anchored > plain

"""Training on a GPU: the Adam step's device part replayed as one CUDA graph computes what the eager
step computes, for new inputs at every replay, and a whole run on CUDA (rows read a block at a time)
trains, checkpoints and resumes. Skipped where torch sees no CUDA device (CI has none; these ran on
an H100, see the README's training-speed table)."""

import numpy as np
import pytest
import torch
from neural_helpers import Recorder, tiny_config

from meshgen.neural.checkpoint import load_checkpoint
from meshgen.neural.cudagraph import CapturedFunction
from meshgen.neural.model import MLP, normalisation, normalised_boundary
from meshgen.neural.problem import Problem, boundary_pool, sample_step
from meshgen.neural.reweighting import UncertaintyWeights
from meshgen.neural.steps import DEVICE_BLOCK, TermRunner, Training, adam_gradients
from meshgen.neural.train import train

pytestmark = pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device is available to torch here")


def training_on(device, geometry, config):
    center, scale = normalisation(geometry)
    problem = Problem(
        geometry.dim,
        normalised_boundary(geometry, center, scale),
        center,
        scale,
        config.model.exact_boundary,
        torch.device(device),
    )
    torch.manual_seed(0)
    network = MLP(geometry.dim, config.model.widths).to(device)
    weights = UncertaintyWeights(learned=config.method.reweighting).to(device)
    return Training(network, weights, problem, config, torch.Generator().manual_seed(0), TermRunner(False))


@pytest.mark.parametrize("preset", ["default", "exact", "pinn"])
def test_the_captured_step_equals_the_eager_step_at_every_replay(semicylinder, preset):
    config = tiny_config("model.widths=[24,24]", "points.interior=512", "points.boundary=300", preset=preset)
    training = training_on("cuda", semicylinder, config)
    pool = boundary_pool(training.problem, config)
    captured = CapturedFunction(lambda inputs: adam_gradients(training, inputs, pool), torch.device("cuda"))
    for _ in range(4):  # new draws each time: the graph must read its inputs, not the first ones
        inputs = sample_step(config, training.problem, training.generator, pool)
        replayed = {k: v.clone() for k, v in captured(inputs).items()}
        eager = adam_gradients(training, {k: v.cuda() for k, v in inputs.items()}, pool)
        assert replayed.keys() == eager.keys()
        for name in eager:
            torch.testing.assert_close(replayed[name], eager[name], rtol=1e-5, atol=1e-7)
        with torch.no_grad():  # move the weights in place, as Adam does: the graph must see them
            for parameter in training.network.parameters():
                parameter.add_(1e-2 * torch.randn_like(parameter))


def test_a_run_on_cuda_trains_checkpoints_and_resumes_on_the_cpu(tmp_path, semicylinder):
    steps = 2 * DEVICE_BLOCK + 30  # whole blocks and a part block
    config = tiny_config(
        "model.widths=[24,24]", f"adam.steps={steps}", "adam.lr=3e-3", "lbfgs.steps=2", f"checkpoint.every={DEVICE_BLOCK}"
    )
    recorder = Recorder(stop_after=DEVICE_BLOCK + 50)  # polled between blocks: stops after the second
    first = train(config, semicylinder, tmp_path, device="cuda", reporter=recorder, stop=recorder.should_stop, summary=False)
    assert first.interrupted and first.step == 2 * DEVICE_BLOCK  # 2 pretrain steps, then blocks to a checkpoint
    adam = [row for row in recorder.rows if row["stage"] == "adam"]
    assert [row["step"] for row in recorder.rows] == list(range(first.step))
    assert all(np.isfinite(row["total"]) for row in adam)
    assert np.mean([r["L1"] + r["L2"] for r in adam[-20:]]) < np.mean([r["L1"] + r["L2"] for r in adam[:20]])
    saved = load_checkpoint(first.checkpoint_path)
    assert saved["device"] == "cuda" and saved["stage"] == "adam" and saved["step"] == first.step
    # a GPU run's checkpoint goes on on the CPU, to the end of its schedule
    second = train(config, semicylinder, tmp_path, device="cpu", resume=saved, summary=False)
    assert not second.interrupted and second.step == 2 + steps + 2
    assert second.test_loss["total"] < saved["test_loss"]["total"]


def test_a_family_step_captured_equals_the_eager_step_at_every_replay():
    """The family's Adam step goes through the same capture: the replayed gradients are the eager
    ones for new members and grids at every replay."""
    from meshgen.geometry.plugins import load_geometry
    from meshgen.neural.config import resolve_config
    from meshgen.neural.family import FamilyMLP, family_scale, make_family
    from meshgen.neural.family_train import FamilyProblem, family_gradients, family_sample

    family = make_family(load_geometry("semicylinder"), "semicylinder", {"radius": (0.5, 2.0)})
    config = resolve_config("family", None, ["model.widths=[16,16]", "points.interior=216"])
    center, scale = family_scale(family)
    problem = FamilyProblem(family, center, scale, torch.device("cuda"))
    torch.manual_seed(0)
    network = FamilyMLP(3, 1, config.model.widths).cuda()
    weights = UncertaintyWeights(0.5, 0.5, learned=False).cuda()
    training = Training(network, weights, problem, config, torch.Generator().manual_seed(0), TermRunner(False))
    captured = CapturedFunction(lambda inputs: family_gradients(training, inputs), torch.device("cuda"))
    for _ in range(3):
        inputs = family_sample(training)
        replayed = {k: v.clone() for k, v in captured(inputs).items()}
        eager = family_gradients(training, {k: v.cuda() for k, v in inputs.items()})
        for name in eager:
            torch.testing.assert_close(replayed[name], eager[name], rtol=1e-5, atol=1e-7)
        with torch.no_grad():
            for parameter in network.parameters():
                parameter.add_(1e-2 * torch.randn_like(parameter))

"""The Adam step's device part must be capturable as a CUDA graph (``meshgen.neural.cudagraph``):
it may not make a tensor from host data (``torch.tensor(x, device=...)`` is a host-to-device copy,
which capture refuses: torch 2.11 on an H200 stopped ``meshgen train --preset exact --device cuda``
so). Checked here on the CPU, where the same code runs: no ``aten.lift_fresh`` (what
``torch.tensor`` dispatches to) in the step, for every kind of training grid and derivative."""

import pytest
import torch
from neural_helpers import tiny_config
from torch.utils._python_dispatch import TorchDispatchMode

from meshgen.neural.model import MLP, normalisation, normalised_boundary
from meshgen.neural.problem import Problem, boundary_pool, sample_step
from meshgen.neural.reweighting import UncertaintyWeights
from meshgen.neural.steps import TermRunner, Training, adam_gradients


class Operations(TorchDispatchMode):
    """The aten operations run inside the mode."""

    def __init__(self):
        super().__init__()
        self.names = []

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        self.names.append(str(func))
        return func(*args, **(kwargs or {}))


@pytest.mark.parametrize(
    "preset, overrides",
    [("default", []), ("exact", []), ("exact", ["points.lattice=false"]), ("pinn", []), ("default", ["points.lattice=true"])],
)
def test_the_adam_step_makes_no_tensor_from_host_data(semicylinder, preset, overrides):
    config = tiny_config("model.widths=[8,8]", "points.interior=64", "points.boundary=64", *overrides, preset=preset)
    center, scale = normalisation(semicylinder)
    boundary = normalised_boundary(semicylinder, center, scale)
    problem = Problem(3, boundary, center, scale, config.model.exact_boundary, torch.device("cpu"))
    torch.manual_seed(0)
    weights = UncertaintyWeights(learned=config.method.reweighting)
    training = Training(
        MLP(3, config.model.widths), weights, problem, config, torch.Generator().manual_seed(0), TermRunner(False)
    )
    pool = boundary_pool(problem, config)
    inputs = sample_step(config, problem, training.generator, pool)  # the host's part, outside the graph
    with Operations() as seen:
        gradients = adam_gradients(training, inputs, pool)
    assert torch.isfinite(gradients["update"]).all()
    assert "aten.lift_fresh.default" not in seen.names

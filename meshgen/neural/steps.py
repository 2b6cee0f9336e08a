"""One step of each training stage (design notes §6), for any network a stage table trains.

The Adam step has one path: the host draws the step's inputs (CPU tensors), a gradients function
turns them into the update on the device without reading anything back (eagerly on a CPU, as one
replayed CUDA graph on a GPU: :mod:`meshgen.neural.cudagraph`), and :func:`apply_adam` takes the
step. L-BFGS steps (the TFI fit, the last stage) run their closure eagerly. Each step returns the
history row's numbers, those computed on the device as 0-d tensors there (the runner reads them a
block at a time, in one transfer).
"""

from __future__ import annotations

from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import torch

from meshgen.neural.config import TrainConfig
from meshgen.neural.cudagraph import CapturedFunction
from meshgen.neural.pcgrad import assign, flatten, project_conflicting
from meshgen.neural.problem import boundary_term, pde_term, step_samples
from meshgen.neural.reweighting import UncertaintyWeights

__all__ = [
    "combined_gradients",
    "DEVICE_BLOCK",
    "AdamSteps",
    "TermRunner",
    "Training",
    "adam_gradients",
    "apply_adam",
    "lbfgs_optimizer",
    "lbfgs_step",
    "make_optimizer",
    "pretrain_step",
    "term_gradients",
]

# Adam steps on a GPU between two reads of their history rows: the device runs a block behind the
# host instead of idling at each step's read (about 0.2 s of steps for the paper's network on an H100)
DEVICE_BLOCK = 100


class TermRunner:
    """Runs the PDE and the boundary term of a step (two disjoint forward and backward passes) side
    by side on a CPU with ``parallel`` set, one in a worker thread, each with a single-threaded
    torch: the networks are too small for torch to split one product well over two cores (measured:
    2 threads per product gave no gain), but two independent passes keep both cores busy. Else (one
    core, or a GPU, which queues both anyway) one after the other. The same arithmetic either way,
    so a run repeats bit for bit with the same seed and threads."""

    def __init__(self, parallel: bool):
        self.pool = ThreadPoolExecutor(max_workers=1) if parallel else None

    def __call__(self, first, second):
        """(first(), second()): ``first`` in the worker thread when parallel."""
        if self.pool is None:
            return first(), second()
        pending = self.pool.submit(first)
        result = second()
        return pending.result(), result

    def close(self):
        if self.pool is not None:
            self.pool.shutdown()


@dataclass
class Training:
    """What the stages' steps work on: the network, the reweighting weights (fixed ones where a
    problem has one loss), the problem (``meshgen.neural.problem.Problem``, or a family's), the
    configuration, the sampler's generator and the term runner."""

    network: torch.nn.Module
    weights: UncertaintyWeights
    problem: object
    config: TrainConfig
    generator: torch.Generator
    terms: TermRunner


def pretrain_step(network, problem, optimizer, pool) -> dict:
    """One L-BFGS step on the mean squared distance from TFI at the fixed pool of points."""

    def closure():
        optimizer.zero_grad(set_to_none=True)
        loss = (network(pool["points"]) - pool["targets"]).square().sum(-1).mean()
        if torch.isfinite(loss):
            loss.backward()
        return loss

    optimizer.step(closure)
    with torch.no_grad():
        return {"total": (network(pool["points"]) - pool["targets"]).square().sum(-1).mean()}


def term_gradients(training: Training, pde_sample, boundary_points, factors):
    """L1 and L2 on one sample each, and g1, g2: the gradients of the weighted terms on the
    network's weights (flat), computed side by side (``Training.terms``)."""
    network, problem, config = training.network, training.problem, training.config
    parameters = list(network.parameters())

    def pde_part():
        pde = pde_term(network, problem, config, pde_sample)
        # materialize_grads: with autograd derivatives the output bias does not enter L1 at all.
        return pde, flatten(torch.autograd.grad(factors[0] * pde, parameters, allow_unused=True, materialize_grads=True))

    def boundary_part():
        if problem.exact:
            zero = torch.zeros((), device=problem.device)
            return zero, torch.zeros(sum(p.numel() for p in parameters), device=problem.device)
        boundary = boundary_term(network, problem, config, boundary_points)
        return boundary, flatten(torch.autograd.grad(factors[1] * boundary, parameters))

    (pde, g1), (boundary, g2) = training.terms(pde_part, boundary_part)
    return pde, boundary, g1, g2


def adam_gradients(training: Training, inputs: dict, pool=None) -> dict:
    """The device part of one step of the method, from the step's ``meshgen.neural.problem.sample_step`` inputs (on
    the device): L1, L2, their gradients g1, g2 combined into the update of the network's weights
    (PCGrad or the sum; zero when a loss is not finite, and the loop restores the last good state),
    L and its gradient on the reweighting parameters (``a_gradient``, learned weights only), and
    whether g1 and g2 conflict. Reads nothing back to the host and changes nothing, so that it can
    be captured into a CUDA graph (:mod:`meshgen.neural.cudagraph`)."""
    weights, config = training.weights, training.config
    pde_sample, boundary_points = step_samples(config, training.problem, inputs, pool)
    factors = weights.factors().detach()
    pde, boundary, g1, g2 = term_gradients(training, pde_sample, boundary_points, factors)
    return combined_gradients(weights, config.method.pcgrad, pde, boundary, g1, g2)


def combined_gradients(weights, pcgrad: bool, pde, boundary, g1, g2) -> dict:
    """The step's update from the two terms' flat gradients ``g1``, ``g2`` (PCGrad when ``pcgrad``),
    zero where a loss is not finite, with the losses, the conflict flag and (learned weights) the
    weights' own gradient: the dict :func:`apply_adam` takes."""
    finite = torch.isfinite(pde) & torch.isfinite(boundary)
    update, conflict = project_conflicting(g1, g2) if pcgrad else (g1 + g2, (g1 @ g2) < 0)
    total = weights.objective(pde.detach(), boundary.detach())
    gradients = {
        "update": torch.where(finite, update, torch.zeros_like(update)),
        "L1": pde.detach(),
        "L2": boundary.detach(),
        "total": torch.where(finite, total.detach(), torch.nan),
        "conflict": conflict.int(),
    }
    if weights.learned:  # the a take their gradient from L itself, outside the projection
        (gradients["a_gradient"],) = torch.autograd.grad(total, weights.log_a)
    return gradients


def apply_adam(training: Training, optimizer, scheduler, gradients: dict) -> dict:
    """Give the network and the reweighting parameters their gradients from :func:`adam_gradients`
    and take the Adam step with its decay; returns the history row's numbers (0-d tensors, copied
    out of ``gradients``, which a CUDA graph overwrites at its next replay)."""
    weights = training.weights
    lr = optimizer.param_groups[0]["lr"]  # the rate of this step, before the decay
    assign(list(training.network.parameters()), gradients["update"])
    if weights.learned:
        weights.log_a.grad = gradients["a_gradient"].clone()
    losses = torch.stack([gradients["L1"], gradients["L2"], gradients["total"]])  # one copy
    conflict = gradients["conflict"].clone()
    optimizer.step()
    scheduler.step()
    a = weights.a().detach()
    return {"L1": losses[0], "L2": losses[1], "total": losses[2], "a1": a[0], "a2": a[1], "conflict": conflict, "lr": lr}


class AdamSteps:
    """The Adam stage's steps for one run: each draws its inputs on the host (``sample()``: a dict
    of CPU tensors), runs ``gradients(inputs)`` on the device (a dict as :func:`adam_gradients`
    returns: ``update``, ``L1``, ``L2``, ``total``, ``conflict`` and, for learned weights,
    ``a_gradient``), eagerly on a CPU, as one replayed CUDA graph on a GPU, then :func:`apply_adam`."""

    def __init__(self, training: Training, sample: Callable[[], dict], gradients: Callable[[dict], dict]):
        self.training, self.sample = training, sample
        device = training.problem.device
        if device.type == "cuda":
            self.gradients = CapturedFunction(gradients, device)
        else:
            self.gradients = lambda inputs: gradients({k: v.to(device) for k, v in inputs.items()})

    def __call__(self, optimizer, scheduler) -> dict:
        return apply_adam(self.training, optimizer, scheduler, self.gradients(self.sample()))


def lbfgs_step(training: Training, optimizer, fixed) -> dict:
    """One L-BFGS step (``lbfgs.max_iter`` iterations) on the fixed points, a1 and a2 frozen."""
    parameters = list(training.network.parameters())
    weights = training.weights
    factors = weights.factors().detach()
    last = {}

    def closure():
        pde, boundary, g1, g2 = term_gradients(training, fixed["pde"], fixed["boundary"], factors)
        assign(parameters, g1 + g2)
        last.update(L1=pde.detach(), L2=boundary.detach())
        return (factors[0] * pde + factors[1] * boundary).detach()

    optimizer.step(closure)
    total = weights.objective(last["L1"], last["L2"]).detach()
    a = weights.a().detach()
    return {**last, "total": total, "a1": a[0], "a2": a[1], "lr": optimizer.param_groups[0]["lr"]}


def make_optimizer(stage: str, network, weights, config: TrainConfig, parameters=None):
    """The optimiser (and scheduler, or None) of ``stage``: L-BFGS for the TFI fit (a least-squares
    fit, where it converges in a fraction of Adam's time) and for the last stage, Adam between.
    ``parameters``: the L-BFGS stages' parameters (default every one of ``network``'s)."""
    if stage == "adam":
        groups = [{"params": list(network.parameters())}]
        if weights.learned:
            groups.append({"params": [weights.log_a], "lr": config.adam.weights_lr or config.adam.lr})
        optimizer = torch.optim.Adam(groups, lr=config.adam.lr)
        scheduler = torch.optim.lr_scheduler.StepLR(optimizer, config.adam.decay_every, gamma=config.adam.decay)
        return optimizer, scheduler
    lbfgs = config.lbfgs
    optimizer = torch.optim.LBFGS(
        network.parameters() if parameters is None else parameters,
        lr=config.pretrain.lr if stage == "pretrain" else lbfgs.lr,
        max_iter=lbfgs.max_iter,
        history_size=lbfgs.history_size,
        line_search_fn="strong_wolfe",
        # Run every iteration: torch's default tolerances (absolute, 1e-7 on the gradient, 1e-9 on
        # the change) stop it early on our small normalised losses.
        tolerance_grad=0.0,
        tolerance_change=0.0,
    )
    return optimizer, None


def lbfgs_optimizer(training: Training):
    """The L-BFGS stage's optimiser (one block or a block set), the networks first moved to float64
    with ``lbfgs.float64`` (the terms follow the weights' type): in float32 the finite-difference
    residual's round-off stops L-BFGS above what the networks can reach (design notes §18)."""
    if training.config.lbfgs.float64:
        training.network.double()
    return make_optimizer("lbfgs", training.network, training.weights, training.config)

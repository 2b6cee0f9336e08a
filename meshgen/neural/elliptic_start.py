"""The elliptic start of a block set's networks (design notes §20, "The elliptic start"): the set's
multi-block elliptic mesh on a fine grid, the target of the networks' first fit and of the pull
that keeps them near it, in place of the TFI.

The elliptic mesh solves the discrete Winslow equations the networks are trained on, so a network
fitted to it starts where the Winslow loss ends: on the pipe the fit alone meshes within a fraction
of a degree of the elliptic mesh, where the Winslow steps from the TFI took ten minutes and more
(the measured figures are in the design notes). The fine grid refines every block's parametric
nodes by one whole factor (``refinement``), so interfaces stay conforming; an extruded set solves
its section, as meshing does.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from meshgen.geometry.blocks import BlockSet, tfi_blocks
from meshgen.geometry.plugins import plugin_module
from meshgen.methods.elliptic import elliptic_blocks

__all__ = [
    "FIT_CELLS",
    "FIT_NODES",
    "RIDGE",
    "elliptic_pools",
    "elliptic_targets",
    "hidden_parameters",
    "projected_fit_step",
    "refined",
    "refinement",
]

FIT_CELLS = 64  # cells per block axis the fine grid aims at (the pipe's section: 64 x 64 a block)
FIT_NODES = 60_000  # most nodes of the fine grid, all blocks together (a 3D set of 8^3-cell blocks: factor 2)
# The output layer's ridge, relative to the number of points (features are tanh values, of order
# one): without it the fit leans on nearly dependent features and its L-BFGS creeps (the wedge's
# section: 5e-7 after 20 steps, 6e-9 with it after 12).
RIDGE = 1e-10


def refinement(block_set: BlockSet) -> int:
    """The whole factor by which every block axis of ``block_set`` is refined: the one that gives
    the block axes about ``FIT_CELLS`` cells on average, lowered until the fine grid holds at most
    ``FIT_NODES`` nodes, at least 1."""
    cells = [n - 1 for shape in block_set.node_shapes for n in shape]
    factor = max(1, math.ceil(FIT_CELLS / (sum(cells) / len(cells))))
    while factor > 1 and sum(math.prod((n - 1) * factor + 1 for n in shape) for shape in block_set.node_shapes) > FIT_NODES:
        factor -= 1
    return factor


def refined(block_set: BlockSet, factor: int) -> BlockSet:
    """``block_set`` with each block's parametric nodes along every axis refined ``factor`` times
    (``factor - 1`` nodes evenly between neighbours in node index, so a graded axis keeps its
    grading and matching interfaces keep matching node counts)."""

    def finer(t: np.ndarray) -> np.ndarray:
        return np.interp(np.linspace(0.0, len(t) - 1.0, (len(t) - 1) * factor + 1), np.arange(len(t)), t)

    coords = tuple(tuple(finer(np.asarray(t, dtype=float)) for t in axes) for axes in block_set.coords)
    return BlockSet(**{**block_set.__dict__, "coords": coords})


def elliptic_targets(block_set: BlockSet, spec: str | None = None) -> tuple[BlockSet, list[np.ndarray], str]:
    """(the fine block set, its node arrays as ``--method elliptic`` makes them, a one-line account)
    of ``block_set``, the set the networks are trained on (an extruded set's section), refined by
    ``refinement``. ``spec``: the plugin the set came from, whose ``elliptic_options`` (a swept CAD
    cap's ``slide_section``, ``keep_tfi``) apply as they do when meshing."""
    module = plugin_module(spec)[0] if spec else None
    options = dict(getattr(module, "elliptic_options", {}) or {})
    factor = refinement(block_set)
    fine = refined(block_set, factor)
    shape = " + ".join("x".join(str(n - 1) for n in s) for s in dict.fromkeys(fine.node_shapes))
    if options.get("keep_tfi"):
        return fine, tfi_blocks(fine), f"the TFI mesh of {shape} cells a block (the plugin keeps the TFI for elliptic)"
    if block_set.dim == 2 and "slide_section" in options:  # an extruded set's section: the section's options
        options = {"slide": options.pop("slide_section")}
    options.pop("slide_section", None)
    Xs, info = elliptic_blocks(fine, **options)
    return fine, Xs, f"the elliptic mesh of {shape} cells a block ({info.get('sweeps', 0)} cycles)"


def elliptic_pools(fine: BlockSet, Xs, center, scale: float, device, count: int | None = None, seed: int = 0) -> list[dict]:
    """Per block, {"points" (K, d) float32, "targets" (K, d) float32} on ``device``: the fine grid's
    parametric nodes and its elliptic nodes in the networks' normalised units ((X - center) / scale);
    every node, or ``count`` drawn without replacement (a fixed draw of ``seed``)."""
    generator = np.random.default_rng(seed)
    pools = []
    for axes, X in zip(fine.coords, Xs):
        points = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, fine.dim)
        targets = (np.asarray(X, dtype=float).reshape(-1, fine.dim) - np.asarray(center)) / scale
        if count is not None and count < len(points):
            keep = np.sort(generator.choice(len(points), size=count, replace=False))
            points, targets = points[keep], targets[keep]
        pools.append(
            {
                "points": torch.from_numpy(points).float().to(device),
                "targets": torch.from_numpy(targets).float().to(device),
            }
        )
    return pools


def hidden_parameters(networks) -> list:
    """The weights and biases of every network's hidden layers: what the projected fit's L-BFGS
    moves (the output layer is solved, ``projected_fit_step``)."""
    return [p for net in networks for layer in net.layers[:-1] for p in layer.parameters()]


def _features(net, points: torch.Tensor) -> torch.Tensor:
    """The last hidden layer of ``net`` (``meshgen.neural.model.MLP``) at ``points`` (K, d), with a
    column of ones for the output bias: (K, width + 1), float64."""
    hidden = 2.0 * points.to(net.layers[0].weight.dtype) - 1.0
    for layer in net.layers[:-1]:
        hidden = torch.tanh(layer(hidden))
    hidden = hidden.double()
    return torch.cat([hidden, torch.ones((len(hidden), 1), dtype=hidden.dtype, device=hidden.device)], dim=1)


def _ridged(features: torch.Tensor, targets: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The least-squares problem of the output layer with its ridge (``RIDGE`` times the number of
    points K on the diagonal of the features' Gram matrix) as extra rows: ((K + w + 1, w + 1)
    features, (K + w + 1, d) targets), float64."""
    count, width = features.shape
    ridge = (RIDGE * count) ** 0.5 * torch.eye(width, dtype=features.dtype, device=features.device)
    zeros = torch.zeros((width, targets.shape[1]), dtype=torch.float64, device=targets.device)
    return torch.cat([features, ridge]), torch.cat([targets.double(), zeros])


def _projected_misfit(features: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
    """Mean over the K points of the squared distance of ``targets`` (K, d) from the best output
    layer's image of ``features`` (K, w + 1) (ridged, ``_ridged``): through the QR factors, as
    accurate as the features are (the normal equations square their condition number, and the
    misfit's round-off then stalls L-BFGS's line search: the pipe at 1.6e-8)."""
    rows, wanted = _ridged(features, targets)
    q = torch.linalg.qr(rows)[0]
    return (wanted - q @ (q.T @ wanted))[: len(features)].square().sum(-1).mean()


def _solved_output(features: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
    """That best output layer, (w + 1, d): R W = Q^T T of the ridged problem."""
    rows, wanted = _ridged(features, targets)
    q, r = torch.linalg.qr(rows)
    return torch.linalg.solve_triangular(r, q.T @ wanted, upper=True)


def projected_fit_step(networks, optimizer, pools) -> dict:
    """One L-BFGS step of the least-squares fit of every network to its pool ({"points",
    "targets"}, ``elliptic_pools``) with the output layer projected out (variable projection):
    the misfit is that of the best output layer for the hidden layers' features, so L-BFGS moves
    the hidden layers alone (``optimizer`` over ``hidden_parameters``), and the output layers are
    set to their solution after the step. On the pipe's section it reaches a misfit 200 times
    smaller than plain L-BFGS on every weight in a tenth of the steps (design notes §20).
    Returns the history row: {"total": mean squared distance, normalised units}."""

    def misfit() -> torch.Tensor:
        return torch.stack(
            [_projected_misfit(_features(net, pool["points"]), pool["targets"]) for net, pool in zip(networks, pools)]
        ).mean()

    def closure():
        optimizer.zero_grad(set_to_none=True)
        value = misfit()
        if torch.isfinite(value):
            value.backward()
        return value

    optimizer.step(closure)
    with torch.no_grad():
        for net, pool in zip(networks, pools):
            solved = _solved_output(_features(net, pool["points"]), pool["targets"])
            last = net.layers[-1]
            last.weight.copy_(solved[:-1].T.to(last.weight.dtype))
            last.bias.copy_(solved[-1].to(last.bias.dtype))
        return {"total": misfit()}

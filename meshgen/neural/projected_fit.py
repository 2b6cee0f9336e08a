"""Least-squares fits of tanh networks with the output layer projected out (variable projection;
design notes §20, "The elliptic start"): a block set's networks fitted to its elliptic mesh
(``meshgen.neural.elliptic_start``).

A network's output is linear in its last hidden layer's features, so for given hidden layers the
best output layer is a linear least-squares solution; the misfit taken at that solution depends on
the hidden layers alone, and L-BFGS moves only them (``hidden_parameters``), the output layer set to
its solution after every step. Measured on the pipe's section: 1.6e-8 mean squared misfit after 3
steps, where plain L-BFGS on every weight had 1.4e-6 after 100. A network takes part through its
``hidden(points)`` method (the last hidden layer, before the output layer ``layers[-1]``).

One thread: the products are small (a block's 4,225 rows by 48, its 49-column QR factors), and
torch's two threads on a busy 2-core machine made a step 20 times slower than one (by hand, a
fit of 10,000 rows: 23-32 s against 1.2 s, the QR 0.31 s against 0.011 s, L-BFGS's dot products
5 ms each).
"""

from __future__ import annotations

import torch

__all__ = ["RIDGE", "hidden_parameters", "projected_fit_step"]

# The output layer's ridge, relative to the number of points (features are tanh values, of order
# one): without it the fit leans on nearly dependent features and its L-BFGS creeps (the wedge's
# section: 5e-7 after 20 steps, 6e-9 with it after 12).
RIDGE = 1e-10


def hidden_parameters(networks) -> list:
    """The weights and biases of every network's hidden layers: what the projected fit's L-BFGS
    moves (the output layer is solved, ``projected_fit_step``)."""
    return [p for net in networks for layer in net.layers[:-1] for p in layer.parameters()]


def _features(net, pool: dict) -> torch.Tensor:
    """The last hidden layer of ``net`` at the pool's points (K, inputs), with a column of ones for
    the output bias: (K, width + 1), float64."""
    hidden = net.hidden(pool["points"].to(net.layers[0].weight.dtype)).double()
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
    "targets"}: ``elliptic_pools``) with the output layer projected out (variable projection):
    the misfit is that of the best output layer for the hidden layers' features, so L-BFGS moves
    the hidden layers alone (``optimizer`` over ``hidden_parameters``), and the output layers are
    set to their solution after the step. Returns the history row: {"total": the networks'
    mean squared distance from their targets, averaged over the networks}."""

    def misfit() -> torch.Tensor:
        return torch.stack(
            [_projected_misfit(_features(net, pool), pool["targets"]) for net, pool in zip(networks, pools)]
        ).mean()

    def closure():
        optimizer.zero_grad(set_to_none=True)
        value = misfit()
        if torch.isfinite(value):
            value.backward()
        return value

    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # small products and QR factors: threads cost more than they give
    try:
        optimizer.step(closure)
    finally:
        torch.set_num_threads(threads)
    with torch.no_grad():
        for net, pool in zip(networks, pools):
            solved = _solved_output(_features(net, pool), pool["targets"])
            last = net.layers[-1]
            last.weight.copy_(solved[:-1].T.to(last.weight.dtype))
            last.bias.copy_(solved[-1].to(last.bias.dtype))
        return {"total": misfit()}

"""Gradient projection between the PDE and boundary gradients (PCGrad; design notes §6).

If g1 . g2 < 0 the two objectives conflict: each gradient is projected onto the normal plane of
the other's original gradient, g1' = g1 - (g1.g2 / |g2|^2) g2 and g2' = g2 - (g1.g2 / |g1|^2) g1,
and the update uses g1' + g2'. Otherwise the update is g1 + g2. Only the network's weights take
part; the reweighting parameters take their own gradient.
"""

from __future__ import annotations

import torch

__all__ = ["project_conflicting", "flatten", "assign"]


def project_conflicting(g1: torch.Tensor, g2: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Combine two flat gradients (P,) as PCGrad does. Returns (update (P,), conflict: 0-d bool).
    Branch-free, so that it never waits for the device."""
    dot = g1 @ g2
    tiny = torch.finfo(g1.dtype).tiny
    projected = g1 - dot / (g2 @ g2).clamp_min(tiny) * g2 + g2 - dot / (g1 @ g1).clamp_min(tiny) * g1
    conflict = dot < 0
    return torch.where(conflict, projected, g1 + g2), conflict


def flatten(gradients) -> torch.Tensor:
    """Tensors of any shapes -> one flat vector."""
    return torch.cat([g.reshape(-1) for g in gradients])


def assign(parameters, flat: torch.Tensor) -> None:
    """Write the flat vector ``flat`` into the ``.grad`` of ``parameters`` (their shapes, in order)."""
    start = 0
    for parameter in parameters:
        size = parameter.numel()
        parameter.grad = flat[start : start + size].view_as(parameter).clone()
        start += size

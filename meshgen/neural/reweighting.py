"""Uncertainty reweighting of the two losses (design notes §6).

    L = L1 / (2 a1^2) + L2 / (2 a2^2) + log(1 + a1^2 + a2^2)

with learned a1, a2 > 0 stored as log a. The log(1 + ...) term keeps the weights from growing
without bound (the plain log a1 + log a2 of uncertainty weighting goes to -inf as a -> 0). With
learning switched off the a are constants and the regulariser is dropped: a fixed weighting
w_k = 1 / (2 a_k^2).
"""

from __future__ import annotations

import math

import torch

__all__ = ["UncertaintyWeights"]


class UncertaintyWeights(torch.nn.Module):
    """a1, a2 (PDE, boundary), learned or fixed, started from the weights w_k = 1 / (2 a_k^2)."""

    def __init__(self, pde_weight: float = 1.0, boundary_weight: float = 1.0, learned: bool = True):
        super().__init__()
        log_a = [-0.5 * math.log(2.0 * w) for w in (pde_weight, boundary_weight)]
        self.learned = learned
        self.log_a = torch.nn.Parameter(torch.tensor(log_a), requires_grad=learned)

    def balance(self, pde: float, boundary: float, iterations: int = 20) -> None:
        """Move (a1, a2) to the stationary point of L for the losses ``pde``, ``boundary``:
        a_k^4 = L_k (1 + a1^2 + a2^2) / 2, solved by fixed-point iteration (it contracts fast for
        the small losses of a pretrained network). Weights then start balanced instead of
        spending the first thousands of Adam steps (log a moves by about lr per step) getting there."""
        losses = torch.tensor([pde, boundary], dtype=torch.float64).clamp_min(1e-30)
        a_squared = torch.ones(2, dtype=torch.float64)
        for _ in range(iterations):
            a_squared = torch.sqrt(losses * (1.0 + a_squared.sum()) / 2.0)
        with torch.no_grad():
            self.log_a.copy_(0.5 * torch.log(a_squared))

    def a(self) -> torch.Tensor:
        """(a1, a2), shape (2,)."""
        return self.log_a.exp()

    def factors(self) -> torch.Tensor:
        """The loss weights 1 / (2 a_k^2), detached: (2,)."""
        return 0.5 * torch.exp(-2.0 * self.log_a.detach())

    def objective(self, pde: torch.Tensor, boundary: torch.Tensor) -> torch.Tensor:
        """L as a function of the a (and of the losses given)."""
        a_squared = torch.exp(2.0 * self.log_a)
        total = pde / (2.0 * a_squared[0]) + boundary / (2.0 * a_squared[1])
        if self.learned:
            total = total + torch.log1p(a_squared.sum())
        return total

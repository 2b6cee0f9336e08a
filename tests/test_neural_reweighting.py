"""Uncertainty reweighting: the gradient of L in a1, a2 against the closed form, the balance point,
fixed weights."""

import math

import torch

from meshgen.neural.reweighting import UncertaintyWeights


def test_gradient_of_L_with_respect_to_log_a_matches_the_closed_form():
    weights = UncertaintyWeights(pde_weight=3.0, boundary_weight=0.2)
    a1, a2 = weights.a().tolist()
    assert math.isclose(1 / (2 * a1**2), 3.0, rel_tol=1e-6) and math.isclose(1 / (2 * a2**2), 0.2, rel_tol=1e-6)
    L1, L2 = 0.37, 1.9
    (gradient,) = torch.autograd.grad(weights.objective(torch.tensor(L1), torch.tensor(L2)), weights.log_a)
    # L = L1/(2 a1^2) + L2/(2 a2^2) + log(1 + a1^2 + a2^2); dL/d log a = a dL/da
    s = 1 + a1**2 + a2**2
    expected = [-L1 / a1**2 + 2 * a1**2 / s, -L2 / a2**2 + 2 * a2**2 / s]
    torch.testing.assert_close(gradient, torch.tensor(expected), rtol=1e-5, atol=1e-6)


def test_objective_value():
    weights = UncertaintyWeights()
    a1, a2 = weights.a().tolist()
    value = weights.objective(torch.tensor(0.5), torch.tensor(0.25)).item()
    assert math.isclose(value, 0.5 / (2 * a1**2) + 0.25 / (2 * a2**2) + math.log(1 + a1**2 + a2**2), rel_tol=1e-6)


def test_balance_is_a_stationary_point_of_L():
    weights = UncertaintyWeights()
    weights.balance(0.17, 3.6e-7)
    (gradient,) = torch.autograd.grad(weights.objective(torch.tensor(0.17), torch.tensor(3.6e-7)), weights.log_a)
    assert float(gradient.abs().max()) < 1e-5
    # the smaller loss gets the larger weight: w2 / w1 = (a1 / a2)^2 ~ sqrt(L1 / L2)
    a1, a2 = weights.a().tolist()
    assert math.isclose((a1 / a2) ** 2, math.sqrt(0.17 / 3.6e-7), rel_tol=0.02)


def test_fixed_weights_have_no_regulariser_and_no_gradient():
    weights = UncertaintyWeights(pde_weight=1.0, boundary_weight=100.0, learned=False)
    assert not weights.log_a.requires_grad
    torch.testing.assert_close(weights.factors(), torch.tensor([1.0, 100.0]))
    value = weights.objective(torch.tensor(2.0), torch.tensor(0.5)).item()
    assert math.isclose(value, 2.0 + 50.0, rel_tol=1e-6)

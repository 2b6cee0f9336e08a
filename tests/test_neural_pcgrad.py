"""PCGrad on hand-made gradients, and the flat-vector helpers."""

import torch

from meshgen.neural.pcgrad import assign, flatten, project_conflicting


def test_conflicting_gradients_are_projected_onto_each_others_normal_plane():
    g1 = torch.tensor([1.0, 0.0, 2.0])
    g2 = torch.tensor([-1.0, 1.0, 0.0])  # g1 . g2 = -1 < 0
    update, conflict = project_conflicting(g1, g2)
    # by hand: g1' = g1 - (-1 / 2) g2 = (0.5, 0.5, 2); g2' = g2 - (-1 / 5) g1 = (-0.8, 1, 0.4)
    torch.testing.assert_close(update, torch.tensor([-0.3, 1.5, 2.4]))
    assert bool(conflict)
    g1_projected = g1 + 0.5 * g2
    g2_projected = g2 + 0.2 * g1
    assert abs(float(g1_projected @ g2)) < 1e-6 and abs(float(g2_projected @ g1)) < 1e-6
    # the projected update no longer increases either loss to first order
    assert float(update @ g1) >= 0 and float(update @ g2) >= 0


def test_agreeing_gradients_are_summed():
    g1 = torch.tensor([1.0, 0.0, 2.0])
    g2 = torch.tensor([1.0, 1.0, -0.2])  # g1 . g2 = 0.6 > 0
    update, conflict = project_conflicting(g1, g2)
    torch.testing.assert_close(update, g1 + g2)
    assert not bool(conflict)


def test_orthogonal_gradients_do_not_count_as_a_conflict():
    update, conflict = project_conflicting(torch.tensor([1.0, 0.0]), torch.tensor([0.0, 3.0]))
    torch.testing.assert_close(update, torch.tensor([1.0, 3.0]))
    assert not bool(conflict)


def test_a_zero_gradient_is_harmless():
    update, conflict = project_conflicting(torch.tensor([1.0, -2.0]), torch.zeros(2))
    torch.testing.assert_close(update, torch.tensor([1.0, -2.0]))
    assert torch.isfinite(update).all()


def test_flatten_and_assign_round_trip_through_parameter_gradients():
    network = torch.nn.Sequential(torch.nn.Linear(3, 4), torch.nn.Tanh(), torch.nn.Linear(4, 2))
    parameters = list(network.parameters())
    flat = torch.arange(sum(p.numel() for p in parameters), dtype=torch.float32)
    assign(parameters, flat)
    assert [p.grad.shape for p in parameters] == [p.shape for p in parameters]
    torch.testing.assert_close(flatten([p.grad for p in parameters]), flat)
    torch.testing.assert_close(parameters[0].grad[1], torch.tensor([3.0, 4.0, 5.0]))

"""The Winslow residual and its derivatives: finite differences against autograd, affine maps,
the cofactor formula against det(g) g^-1, 2D against an extruded 3D map, scaling."""

import numpy as np
import pytest
import torch

from meshgen.neural.derivatives import (
    autograd_derivatives,
    grid_derivatives,
    grid_points,
    stencil_derivatives,
    training_grid,
)
from meshgen.neural.winslow import cofactors, winslow_residual


def smooth_map(points):
    """A curved, non-polynomial map of the unit square or cube (float64 torch)."""
    x = points.unbind(-1)
    if len(x) == 2:
        u, v = x
        return torch.stack([u + 0.2 * torch.sin(2 * v) * u, v + 0.3 * u * u + 0.1 * torch.cos(3 * u * v)], -1)
    u, v, w = x
    return torch.stack([u + 0.1 * torch.sin(2 * v) * w, v * v + 0.3 * u + 0.5 * v, w + 0.2 * torch.cos(u * v) + 0.1 * u * w], -1)


def affine_map(points):
    dim = points.shape[-1]
    A = torch.tensor([[2.0, 0.3, 0.1], [0.2, 1.5, -0.4], [0.0, 0.5, 3.0]], dtype=points.dtype)[:dim, :dim]
    return points @ A.T + 0.7


def residuals_on_grid(function, dim, nodes, generator=None, min_scale=1.0):
    """(finite-difference residual, autograd residual) at the interior nodes of a training grid."""
    axes, spacing = training_grid(dim, nodes, generator, min_scale)
    grid = grid_points(axes)
    values = function(grid.reshape(-1, dim)).reshape(grid.shape)
    _, first, second = grid_derivatives(values, spacing)
    interior = grid[(slice(1, -1),) * dim].reshape(-1, dim)
    _, first_ad, second_ad = autograd_derivatives(function, interior)
    fd = winslow_residual(first.reshape(-1, dim, dim), second.reshape(-1, dim, dim, dim))
    return fd.detach(), winslow_residual(first_ad, second_ad).detach(), max(spacing)


@pytest.mark.parametrize("dim", [2, 3])
def test_finite_difference_residual_converges_to_autograd_at_second_order(dim):
    """Grids with h = 1/8, 1/16, 1/32 share the coarse nodes; halving h there divides the error by 4."""
    errors = []
    for level, nodes in enumerate((7, 15, 31)):
        fd, ad, h = residuals_on_grid(smooth_map, dim, nodes)
        error = (fd - ad).abs().reshape(*([nodes] * dim), dim)
        stride = 2**level  # the nodes of the h = 1/8 grid
        errors.append(float(error[(slice(stride - 1, None, stride),) * dim].max()))
    orders = np.log2(np.array(errors[:-1]) / errors[1:])
    assert np.all(orders > 1.9) and np.all(orders < 2.1), orders
    assert errors[-1] < 1e-2 * float(ad.abs().max())


def test_shifted_and_rescaled_grid_gives_the_same_residual_as_autograd():
    generator = torch.Generator().manual_seed(3)
    fd, ad, h = residuals_on_grid(smooth_map, 3, 24, generator, min_scale=0.7)
    assert float((fd - ad).abs().max()) < 5 * h**2


@pytest.mark.parametrize("dim", [2, 3])
def test_residual_of_an_affine_map_is_zero(dim):
    fd, ad, _ = residuals_on_grid(affine_map, dim, 6, torch.Generator().manual_seed(0), min_scale=0.8)
    assert float(fd.abs().max()) < 1e-12
    assert float(ad.abs().max()) < 1e-12


def test_the_residual_is_not_zero_for_a_curved_map():
    fd, ad, _ = residuals_on_grid(smooth_map, 3, 6)
    assert float(ad.abs().max()) > 1e-2


def metric(first):
    """g_ij = r_i . r_j as a matrix product: first (N, i, c) times its transpose."""
    return first @ first.transpose(-1, -2)


def test_cofactors_equal_det_times_inverse():
    rng = np.random.default_rng(1)
    for dim in (2, 3):
        first = torch.from_numpy(rng.normal(size=(50, dim, dim)))
        g = metric(first)
        expected = torch.linalg.det(g)[:, None, None] * torch.linalg.inv(g)
        torch.testing.assert_close(cofactors(first), expected, rtol=1e-10, atol=1e-10)


def test_2d_residual_equals_the_3d_residual_of_the_extruded_map():
    """For r(xi, eta, zeta) = (x(xi, eta), y(xi, eta), zeta) the 3D cofactor form reduces to
    g22 r_xixi - 2 g12 r_xieta + g11 r_etaeta; the scales differ by the factor g11 g22 - g12^2 + ..."""
    rng = torch.Generator().manual_seed(2)
    points = torch.rand((40, 3), generator=rng, dtype=torch.float64)

    def extruded(p):
        return torch.cat([smooth_map(p[:, :2]), p[:, 2:]], dim=1)

    _, first3, second3 = autograd_derivatives(extruded, points)
    _, first2, second2 = autograd_derivatives(smooth_map, points[:, :2])
    g = metric(first2)
    raw2 = g[:, 1, 1, None] * second2[:, 0, 0] - 2 * g[:, 0, 1, None] * second2[:, 0, 1] + g[:, 0, 0, None] * second2[:, 1, 1]
    # 3D: C = cofactors of blockdiag(g, 1) = blockdiag(cof(g), det g); trace = g11 + g22 + det g.
    trace3 = g[:, 0, 0] + g[:, 1, 1] + torch.linalg.det(g)
    residual3 = winslow_residual(first3, second3)
    torch.testing.assert_close(residual3[:, :2], raw2 / (trace3 + 1e-6)[:, None], rtol=1e-9, atol=1e-12)
    torch.testing.assert_close(residual3[:, 2], torch.zeros(40, dtype=torch.float64), atol=1e-12, rtol=0)
    # and the 2D residual is the same numerator over g11 + g22
    torch.testing.assert_close(winslow_residual(first2, second2), raw2 / (g[:, 0, 0] + g[:, 1, 1] + 1e-6)[:, None])


def test_residual_scales_linearly_with_the_map():
    """The raw residual grows like length^5; divided by the cofactor trace (length^4) it is
    homogeneous of degree one, so training on the unit-size geometry makes it scale-free."""
    points = torch.rand((30, 3), generator=torch.Generator().manual_seed(5), dtype=torch.float64)
    _, first, second = autograd_derivatives(smooth_map, points)
    base = winslow_residual(first, second)
    _, first, second = autograd_derivatives(lambda p: 10.0 * smooth_map(p) + 3.0, points)
    torch.testing.assert_close(winslow_residual(first, second), 10.0 * base, rtol=1e-5, atol=0)


def test_per_point_stencil_matches_autograd():
    points = 0.1 + 0.8 * torch.rand((20, 3), generator=torch.Generator().manual_seed(4), dtype=torch.float64)
    _, first, second = stencil_derivatives(smooth_map, points, 1e-3)
    _, first_ad, second_ad = autograd_derivatives(smooth_map, points)
    torch.testing.assert_close(first, first_ad, atol=1e-5, rtol=0)
    torch.testing.assert_close(second, second_ad, atol=1e-5, rtol=0)


def test_training_grid_stays_inside_the_cube_and_moves():
    generator = torch.Generator().manual_seed(0)
    seen = []
    for _ in range(20):
        axes, spacing = training_grid(3, 10, generator, min_scale=0.8)
        for axis, h in zip(axes, spacing):
            assert len(axis) == 12
            assert float(axis.min()) >= 0.0 and float(axis.max()) <= 1.0
            torch.testing.assert_close(axis[1:] - axis[:-1], torch.full((11,), h, dtype=torch.float64))
            assert 0.8 / 11 - 1e-12 <= h <= 1 / 11 + 1e-12
        seen.append(float(axes[0][0]))
    assert len(set(seen)) == 20  # shifted every time
    fixed, spacing = training_grid(2, 4)
    torch.testing.assert_close(fixed[0], torch.linspace(0, 1, 6, dtype=torch.float64))

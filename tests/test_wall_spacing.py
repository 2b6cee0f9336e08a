"""Wall spacing: first-cell height from y+ and Re, and wall-normal distances under a growth cap."""

import math

import numpy as np
import pytest

from meshgen.errors import ParameterError
from meshgen.geometry.wall_spacing import (
    cut_normal_distances,
    first_cell_height,
    minimal_cell_count,
    skin_friction,
    spacing_summary,
    wall_normal_distances,
)


def test_skin_friction_is_near_other_flat_plate_correlations():
    for reynolds in (1e6, 1e7, 1e8, 1e9):
        assert skin_friction(reynolds) == pytest.approx(0.026 / reynolds ** (1 / 7), rel=0.05)  # White's
    for reynolds in (1e6, 1e7):  # Prandtl's 1/5-power law, stated for Re up to 1e7
        assert skin_friction(reynolds) == pytest.approx(0.0592 / reynolds**0.2, rel=0.1)
    assert skin_friction(1e6) == pytest.approx(0.003745, rel=1e-3)  # (12 - 0.65)^-2.3 by hand


def test_first_cell_height_from_the_friction_velocity():
    # dimensional route: U = 50 m/s, nu = 1.5e-5 m^2/s, L = 2 m -> Re = 6.67e6; the wall shear
    # stress tau = rho U^2 Cf / 2 gives u_tau = sqrt(tau / rho) and y = y+ nu / u_tau
    speed, nu, length, rho = 50.0, 1.5e-5, 2.0, 1.2
    reynolds = speed * length / nu
    first = first_cell_height(1.0, reynolds, length)
    tau = 0.5 * rho * speed**2 * first.cf
    u_tau = math.sqrt(tau / rho)
    assert first.cf == skin_friction(reynolds)
    assert first.height == pytest.approx(1.0 * nu / u_tau, rel=1e-12)
    assert first_cell_height(30.0, reynolds, length).height == pytest.approx(30 * first.height, rel=1e-12)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"y_plus": 0.0, "reynolds": 1e6}, "y_plus 0 is outside"),
        ({"y_plus": -1.0, "reynolds": 1e6}, "outside \\(0, 1000\\]"),
        ({"y_plus": 1001.0, "reynolds": 1e6}, "outside"),
        ({"y_plus": float("nan"), "reynolds": 1e6}, "outside"),
        ({"y_plus": 1.0, "reynolds": 50.0}, "reynolds 50 is outside \\[100, 1e\\+10\\]"),
        ({"y_plus": 1.0, "reynolds": 1e11}, "outside"),
        ({"y_plus": 1.0, "reynolds": -1e6}, "outside"),
        ({"y_plus": 1.0, "reynolds": 1e6, "length": 0.0}, "must be positive"),
    ],
)
def test_absurd_y_plus_or_reynolds_is_refused(kwargs, message):
    with pytest.raises(ParameterError, match=message):
        first_cell_height(**kwargs)


def brute_force_count(first, distance, cap, layers):
    """The fewest cells h, ..., h (layers), h cap, h cap^2, ... whose sum reaches distance (a loop)."""
    total, width, count = 0.0, first, 0
    while total < distance * (1 - 1e-14):
        count += 1
        if count > layers:
            width *= cap
        total += width
    return count


@pytest.mark.parametrize("first, distance, cap, layers", [(4.46e-6, 100.0, 1.15, 2), (1e-3, 1.0, 1.2, 1), (2e-5, 50.0, 1.1, 4)])
def test_distances_under_the_cap(first, distance, cap, layers):
    nodes, ratio = wall_normal_distances(first, distance, cap, layers)
    widths = np.diff(nodes)
    assert nodes[0] == 0.0 and nodes[-1] == distance
    np.testing.assert_allclose(widths[:layers], first, rtol=1e-12)
    ratios = widths[1:] / widths[:-1]
    assert ratios.max() <= cap + 1e-12
    np.testing.assert_allclose(ratios[layers - 1 :], ratio, rtol=1e-9)  # one growth ratio past the wall layers
    np.testing.assert_allclose(ratios[: layers - 1], 1.0, rtol=1e-12)
    assert len(widths) == brute_force_count(first, distance, cap, layers) == minimal_cell_count(first, distance, cap, layers)
    with pytest.raises(ParameterError, match=f"smallest count that works is {len(widths)}"):
        wall_normal_distances(first, distance, cap, layers, cells=len(widths) - 1)


def test_a_given_count_forces_its_ratio():
    first, distance = 1e-5, 100.0
    minimal, _ = wall_normal_distances(first, distance)
    nodes, ratio = wall_normal_distances(first, distance, cells=len(minimal) + 19)
    widths = np.diff(nodes)
    assert len(widths) == len(minimal) + 19 and nodes[-1] == distance
    assert widths[0] == pytest.approx(first, rel=1e-12) and widths[1] == pytest.approx(first, rel=1e-12)
    np.testing.assert_allclose(widths[2:] / widths[1:-1], ratio, rtol=1e-9)
    # the geometric series closes: 2 h + h (q + ... + q^(m-2)) = D
    m = len(widths)
    assert first * (2 + ratio * (ratio ** (m - 2) - 1) / (ratio - 1)) == pytest.approx(distance, rel=1e-10)
    assert (
        spacing_summary(nodes, ratio) == f"{m} cells to 100: first cell 1e-05, 2 constant layers, then growth ratio {ratio:.6g}"
    )
    uniform, one = wall_normal_distances(0.5, 10.0, cells=20)
    assert one == 1.0
    np.testing.assert_allclose(uniform, np.linspace(0, 10, 21))


@pytest.mark.parametrize(
    "args, kwargs, message",
    [
        ((1e-5, 100.0), {"ratio_cap": 1.0}, "cap must be a number > 1"),
        ((1e-5, 100.0), {"ratio_cap": 0.9}, "cap must be a number > 1"),
        ((1e-5, 100.0), {"layers": 0}, "whole number >= 1"),
        ((0.0, 100.0), {}, "must be positive"),
        ((1.0, 1.5), {}, "must exceed the 2 constant wall layers"),
        ((0.5, 10.0), {"cells": 21}, "at most 20 fit"),
    ],
)
def test_bad_distances_are_refused(args, kwargs, message):
    with pytest.raises(ParameterError, match=message) as caught:
        wall_normal_distances(*args, **kwargs)
    assert "\n" not in str(caught.value)


def test_cut_normal_distances_grow_the_first_cell_and_keep_the_growth():
    d, _ = wall_normal_distances(4.46e-6, 1000.0, 1.1425, 2, cells=131)
    spacing = np.geomspace(1e-4, 120.0, 60)  # a wake cut's streamwise cells, trailing edge to outflow
    lines = cut_normal_distances(d, spacing, 224.0)
    assert lines.shape == (60, 132)
    kept = spacing / 224.0 <= 4.46e-6
    assert 0 < kept.sum() < 60 and np.array_equal(lines[kept], np.broadcast_to(d, (kept.sum(), 132)))  # bit for bit
    cells = np.diff(lines, axis=1)
    assert np.all(cells > 0) and np.all(lines[:, 0] == 0) and np.all(lines[:, -1] == 1000.0)
    wall_ratio = (np.diff(d)[1:] / np.diff(d)[:-1]).max()
    assert (cells[:, 1:] / cells[:, :-1]).max() <= wall_ratio * (1 + 1e-12)
    # The first cell: the streamwise cell over 224, less the scaling back to 1000 chords (at most
    # the 131 raised cells' share of the line).
    want = np.maximum(spacing / 224.0, 4.46e-6)
    assert np.all(cells[:, 0] <= want * (1 + 1e-12))
    assert np.all(cells[:, 0] >= want * 1000.0 / (1000.0 + 131 * want))
    # Outwards the raise fades: the last cells are the wall's to within the scaling.
    np.testing.assert_allclose(cells[:, -1], np.diff(d)[-1], rtol=0.1)

"""Expansion ratio and grid-line smoothness against closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from meshgen.quality.smoothness import expansion_ratio, grid_smoothness, node_smoothness, smoothness_figures


def graded_box(q: float, cells=(6, 3, 4)) -> np.ndarray:
    """A box graded geometrically by q along x (spacing h q^i), uniform along y and z."""
    x = np.concatenate([[0.0], np.cumsum(0.1 * q ** np.arange(cells[0]))])
    y, z = np.linspace(0.0, 1.0, cells[1] + 1), np.linspace(0.0, 2.0, cells[2] + 1)
    return np.stack(np.meshgrid(x, y, z, indexing="ij"), axis=-1)


@pytest.mark.parametrize("q", [1.0, 1.2, 0.7, 3.0])
def test_expansion_ratio_of_a_geometric_box_is_the_grading_ratio(q):
    ratio = expansion_ratio(graded_box(q))
    assert ratio.shape == (6, 3, 4)
    np.testing.assert_allclose(ratio, max(q, 1.0 / q), rtol=1e-12)


def test_smoothness_of_a_geometric_box_is_the_closed_form():
    q = 1.5
    nodes = node_smoothness(graded_box(q))
    # interior nodes along x: |h q - h| / ((h q + h) / 2) = 2 (q - 1) / (q + 1); ends of x lines: 0
    np.testing.assert_allclose(nodes[1:-1], 2 * (q - 1) / (q + 1), rtol=1e-12)
    np.testing.assert_allclose(nodes[[0, -1]], 0.0, atol=1e-15)


def test_smoothness_of_a_polar_grid_is_the_chord_formula():
    # An annulus sampled every dtheta along circles: second difference / chord = 2 sin(dtheta / 2);
    # the radial lines are straight and evenly spaced (0).
    dtheta = np.pi / 10
    theta, r = np.arange(8) * dtheta, np.linspace(1.0, 2.0, 5)
    T, R = np.meshgrid(theta, r, indexing="ij")
    X = np.stack([R * np.cos(T), R * np.sin(T)], axis=-1)
    nodes = node_smoothness(X)
    np.testing.assert_allclose(nodes[1:-1], 2 * np.sin(dtheta / 2), rtol=1e-12)
    cells = grid_smoothness(X)
    np.testing.assert_allclose(cells, 2 * np.sin(dtheta / 2), rtol=1e-12)


def test_expansion_ratio_of_a_polar_grid_along_the_radius():
    # Along theta every cell has the same size; along r the mean edge along theta grows with the
    # radius: cell j spans r_j .. r_j+1, its theta-edges average dtheta (r_j + r_j+1) / 2, the radial
    # edges are all dr: the ratio across a face normal to theta is 1, across one normal to r it is
    # the ratio of the two cells' radial sizes (1) -- so the figure is 1 everywhere.
    dtheta = np.pi / 10
    theta, r = np.arange(8) * dtheta, np.linspace(1.0, 2.0, 5)
    T, R = np.meshgrid(theta, r, indexing="ij")
    X = np.stack([R * np.cos(T), R * np.sin(T)], axis=-1)
    np.testing.assert_allclose(expansion_ratio(X), 1.0, rtol=1e-12)


def test_figures_name_the_worst_cell():
    X = graded_box(1.0)
    X[3, 2, 1, 0] += 0.03  # one node moved along x: the cells around it get the largest figures
    figures = smoothness_figures(X)
    worst = figures["expansion_ratio"]["worst_cell"]
    assert worst[0] in (2, 3) and worst[1] in (1, 2) and worst[2] in (0, 1)
    worst = figures["grid_smoothness"]["worst_cell"]
    assert worst[0] in (2, 3) and worst[1] in (1, 2) and worst[2] in (0, 1)
    assert figures["grid_smoothness"]["max"] == pytest.approx(0.06 / 0.1, rel=1e-12)


def test_smoothness_by_axis_separates_the_lines():
    dtheta = np.pi / 10
    theta, r = np.arange(8) * dtheta, np.linspace(1.0, 2.0, 5)
    T, R = np.meshgrid(theta, r, indexing="ij")
    X = np.stack([R * np.cos(T), R * np.sin(T)], axis=-1)
    by_axis = smoothness_figures(X)["grid_smoothness"]["max_by_axis"]
    assert by_axis[0] == pytest.approx(2 * np.sin(dtheta / 2), rel=1e-12) and by_axis[1] < 1e-12

"""Hyperbolic marching (meshgen.methods.hyperbolic): closed forms (a circle, a straight wall), and the
near-wall requirements of airfoil O- and C-grids on the TMR NACA 0012 (sharp trailing edge) to y+ 1."""

from __future__ import annotations

import numpy as np
import pytest

from meshgen.errors import GeometryError, ParameterError
from meshgen.methods.hyperbolic import cell_areas, march


def naca0012(x):
    """Half thickness of the TMR NACA 0012 (sharp trailing edge at x = 1)."""
    return 0.594689181 * (
        0.298222773 * np.sqrt(x) - 0.127125232 * x - 0.357907906 * x**2 + 0.291984971 * x**3 - 0.105174606 * x**4
    )


def naca_normals(beta, upper):
    """Unit outward normals of the section at cosine parameter beta (x = (1 + cos beta) / 2), from the
    derivative of the closed form."""
    x = 0.5 * (1 + np.cos(beta))
    dx = -0.5 * np.sin(beta)
    dt = 0.594689181 * (
        0.5 * 0.298222773 / np.sqrt(np.maximum(x, 1e-300))
        - 0.127125232
        - 2 * 0.357907906 * x
        + 3 * 0.291984971 * x**2
        - 4 * 0.105174606 * x**3
    )
    dy = dt * dx * (1 if upper else -1)
    # dt dx = dt/dx dx/dbeta; at the leading edge (beta = pi) the limit is finite: use the closed form
    with np.errstate(invalid="ignore"):
        dy = np.where(x == 0, 0.5 * 0.594689181 * 0.298222773 * (1 if upper else -1) * -1, dy)
    n = np.stack([dy, -dx], 1) * (1 if upper else -1)
    n[x == 0] = [-1.0, 0.0]  # the leading edge
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def o_curve(n_side=200):
    """Clockwise: trailing edge, lower side, leading edge, upper side (trailing edge not repeated); the
    analytic outward normals, and the index of the trailing edge (0)."""
    beta = np.linspace(0, np.pi, n_side + 1)
    x = 0.5 * (1 + np.cos(beta))
    lower = np.stack([x, -naca0012(x)], 1)
    upper = np.stack([x[::-1], naca0012(x[::-1])], 1)
    curve = np.concatenate([lower, upper[1:-1]])
    normals = np.concatenate([naca_normals(beta, False), naca_normals(beta[::-1], True)[1:-1]])
    return curve, normals


def c_curve(n_side=130, n_wake=40, length=10.0):
    """Wake cut lower side (x = 1 + length .. 1), lower side, leading edge, upper side, wake upper side;
    geometric wake spacing from the trailing edge's. Returns curve, normals (NaN at the trailing edges:
    corners), and the trailing edges' indices."""
    o, on = o_curve(n_side)
    first = np.linalg.norm(o[1] - o[0])
    g = 1.2
    for _ in range(200):  # fixed point of first (g^n - 1) / (g - 1) = length
        g = (length * (g - 1) / first + 1) ** (1 / n_wake)
    xw = 1 + np.concatenate([[0.0], np.cumsum(first * g ** np.arange(n_wake))])
    xw[-1] = 1 + length
    wake = np.stack([xw, np.zeros_like(xw)], 1)
    curve = np.concatenate([wake[::-1][:-1], o, o[:1], wake[1:]])
    wn = np.zeros((n_wake, 2))
    normals = np.concatenate([wn + [0, -1], np.full((1, 2), np.nan), on[1:], np.full((1, 2), np.nan), wn + [0, 1]])
    return curve, normals, (n_wake, len(curve) - 1 - n_wake)


def geometric(first, growth, far):
    steps = first * growth ** np.arange(400)
    d = np.concatenate([[0.0], np.cumsum(steps)])
    return d[: np.searchsorted(d, far) + 1]


DISTANCES = geometric(1e-6, 1.15, 100.0)  # first cell 1e-6 chord, growth 1.15, to ~100 chords


def angles_deg(a, b):
    cosine = (a * b).sum(-1) / (np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1))
    return np.degrees(np.arccos(np.clip(cosine, -1, 1)))


@pytest.mark.parametrize("clockwise", [True, False])
def test_circle_marches_to_concentric_circles(clockwise):
    theta = np.linspace(0, 2 * np.pi, 96, endpoint=False) * (-1 if clockwise else 1)
    radius = 2.0
    curve = radius * np.stack([np.cos(theta), np.sin(theta)], 1)
    nodes = march(curve, DISTANCES, closed=True)
    assert nodes.shape == (96, len(DISTANCES), 2) and (nodes[:, 0] == curve).all()
    r = np.linalg.norm(nodes, axis=-1)
    np.testing.assert_allclose(r, np.broadcast_to(radius + DISTANCES, r.shape), rtol=1e-12)
    phi = np.arctan2(nodes[..., 1], nodes[..., 0])
    assert np.abs(np.angle(np.exp(1j * (phi - theta[:, None])))).max() < 1e-12
    areas = cell_areas(nodes, closed=True)
    assert (areas > 0).all() if clockwise else (areas < 0).all()


def test_straight_wall_marches_straight_normal_lines():
    x = np.concatenate([[0.0], np.cumsum(1e-3 * 1.1 ** np.arange(40))])  # clustered at x = 0
    curve = np.stack([x, np.zeros_like(x)], 1)
    nodes = march(curve, DISTANCES, ends=("constant_x", "constant_x"))
    np.testing.assert_allclose(nodes[..., 0], np.broadcast_to(x[:, None], nodes.shape[:2]), atol=1e-12)
    np.testing.assert_allclose(nodes[..., 1], np.broadcast_to(DISTANCES, nodes.shape[:2]), rtol=1e-12, atol=1e-15)


def check_near_wall(nodes, normals, skip=()):
    """First layer along the analytic normal within 2 degrees, first cell height within 2 %."""
    first = nodes[:, 1] - nodes[:, 0]
    keep = np.isfinite(normals[:, 0])
    keep[list(skip)] = False
    angle = angles_deg(first[keep], normals[keep])
    height = (first[keep] * normals[keep]).sum(1)
    assert angle.max() < 2.0, angle.max()
    np.testing.assert_allclose(height, DISTANCES[1], rtol=0.02)
    return angle.max()


def test_naca0012_o_grid():
    curve, normals = o_curve()
    nodes = march(curve, DISTANCES, closed=True)
    assert (nodes[:, 0] == curve).all()
    areas = cell_areas(nodes, closed=True)
    assert (areas > 0).all()  # clockwise: no inverted cell anywhere
    check_near_wall(nodes, normals, skip=(0,))  # the trailing edge is a corner: its normal is the bisector
    assert angles_deg(nodes[0, 1] - nodes[0, 0], np.array([1.0, 0.0])) < 1e-6
    # aspect ratio at the wall: along-wall spacing over first height
    spacing = np.linalg.norm(np.roll(curve, -1, 0) - curve, axis=1)
    assert spacing.max() / DISTANCES[1] > 5e3
    radius = np.linalg.norm(nodes[:, -1] - [0.5, 0.0], axis=1)
    assert np.abs(radius / DISTANCES[-1] - 1).max() < 0.01  # measured 0.45 %
    # symmetric section: node i and its mirror (index -i) are mirror images
    mirror = nodes[(-np.arange(len(curve))) % len(curve)] * [1, -1]
    assert np.abs(mirror - nodes).max() < 1e-8  # measured 3e-10 at 112 chords


def test_naca0012_c_grid():
    curve, normals, te = c_curve()
    nodes = march(curve, DISTANCES, ends=("constant_x", "constant_x"))
    assert (nodes[:, 0] == curve).all()
    assert (cell_areas(nodes) > 0).all()
    check_near_wall(nodes, normals)
    # at the trailing edge the first line lies between the wake's normal and the surface's
    for i, sign in zip(te, (-1, 1)):
        a = angles_deg(nodes[i, 1] - nodes[i, 0], np.array([0.0, sign]))
        assert a < 10.0
    # the outflow ends keep x, the wake cut's two sides stay mirror images
    assert (nodes[0, :, 0] == curve[0, 0]).all() and (nodes[-1, :, 0] == curve[-1, 0]).all()
    mirror = np.abs(nodes[::-1] * [1, -1] - nodes)
    near = DISTANCES < 1.0  # within a chord of the wall: to 1e-10 of the chord
    assert mirror[:, near].max() < 1e-10
    assert mirror.max() < 1e-8  # roundoff relative to coordinates of ~100 chords: measured 8e-10
    # aspect ratio 1e5: the last wake cells are 0.3 chord long, 1e-6 high
    assert np.linalg.norm(curve[1] - curve[0]) / DISTANCES[1] > 1e5
    # the far layer: the semicircle ahead of x = 1 lies at distance D from the section
    far = nodes[:, -1]
    front = far[:, 0] < 0.5
    radius = np.linalg.norm(far[front] - [0.5, 0.0], axis=1)
    assert np.abs(radius / DISTANCES[-1] - 1).max() < 0.03  # measured 1.9 %


def test_concave_corners_do_not_fold():
    # concave corners take more smoothing than the default (0.05, for airfoils): 0.5
    # an inner right angle: down the y axis to the origin, along the x axis: marches into x, y > 0
    s = np.linspace(0, 1, 41)[1:]
    curve = np.concatenate([np.stack([0 * s[::-1], s[::-1]], 1), [[0.0, 0.0]], np.stack([s, 0 * s], 1)])
    nodes = march(curve, geometric(1e-4, 1.1, 0.3), ends=("constant_y", "constant_x"), smoothing=0.5)
    assert (cell_areas(nodes) > 0).all()
    # a closed star with 5 concave notches
    t = np.linspace(0, 2 * np.pi, 200, endpoint=False)
    r = 1 + 0.3 * np.cos(5 * t)
    star = np.stack([r * np.cos(-t), r * np.sin(-t)], 1)
    nodes = march(star, geometric(1e-4, 1.15, 5.0), closed=True, smoothing=0.5)
    assert (cell_areas(nodes, closed=True) > 0).all()


def test_a_400_by_130_o_grid_to_aspect_ratios_of_1e5_has_no_inverted_cell():
    """The size of a y+ 1 airfoil grid (its time is a benchmark row, not a test)."""
    curve, _ = o_curve(200)
    distances = np.concatenate([[0.0], np.cumsum(1e-6 * 1.1385 ** np.arange(129))])
    assert len(curve) == 400 and len(distances) == 130
    nodes = march(curve, distances, closed=True)
    assert (cell_areas(nodes, closed=True) > 0).all()


@pytest.mark.parametrize(
    "curve, distances, kwargs, error, match",
    [
        ([[0, 0], [1, 0]], [0, 1], {}, GeometryError, "at least 3 points"),
        ([[0, 0], [1, np.nan], [2, 0]], [0, 1], {}, GeometryError, "NaN"),
        ([[0, 0], [1, 0], [1, 1], [0.5, -1]], [0, 1], {}, GeometryError, "crosses itself"),
        ([[0, 0], [1, 0], [1, 0], [2, 0]], [0, 1], {}, GeometryError, "coincide"),
        ([[0, 0], [1, 0], [2, 0]], [0, 1, 1], {}, ParameterError, "increase strictly"),
        ([[0, 0], [1, 0], [2, 0]], [0.1, 1], {}, ParameterError, "start at 0"),
        ([[0, 0], [1, 0], [2, 0]], [0, np.nan], {}, ParameterError, "NaN"),
        ([[0, 0], [1, 0], [2, 0]], [0, 1], {"ends": ("sideways", "free")}, ParameterError, "unknown end"),
        ([[0, 0], [1, 0], [2, 0]], [0, 1], {"ends": ((0, -1), "free")}, GeometryError, "marching side"),
        ([[0, 0], [1, 0], [1, 1]], [0, 1], {"closed": True, "ends": ("free", "free")}, ParameterError, "open curve"),
    ],
)
def test_bad_input_is_refused_in_one_line(curve, distances, kwargs, error, match):
    with pytest.raises(error, match=match) as caught:
        march(np.array(curve, dtype=float), distances, **kwargs)
    assert "\n" not in str(caught.value)

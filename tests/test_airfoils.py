"""Airfoil sections: the NACA and TMR formulas, coordinate files, the section curve and the
chordwise node distribution, against published values and independent computations."""

import numpy as np
import pytest
from scipy.integrate import quad

from meshgen.errors import GeometryError, ParameterError
from meshgen.geometry.airfoil_curve import (
    analytic_section,
    chord_length,
    chordwise_distribution,
    leading_edge_arc,
    normals_at,
    parameters_at,
    points_at,
    tangents_at,
    trailing_edge,
    vinokur,
)
from meshgen.geometry.airfoils import (
    data_section,
    load_section,
    naca4_section,
    naca_camber,
    naca_constants,
    naca_section,
    parse_section_text,
    read_section,
    tmr0012_section,
)


def tmr_formula(x):
    """The TMR NACA 0012 upper surface, written out from the NASA TMR page."""
    return 0.594689181 * (
        0.298222773 * np.sqrt(x) - 0.127125232 * x - 0.357907906 * x**2 + 0.291984971 * x**3 - 0.105174606 * x**4
    )


def test_tmr_nodes_lie_on_the_formula_and_the_trailing_edge_is_closed():
    section = tmr0012_section()
    s = np.linspace(0.0, section.length, 4001)
    p = points_at(section, s)
    upper = s > leading_edge_arc(section)
    assert np.all((p[:, 0] >= 0) & (p[:, 0] <= 1))
    np.testing.assert_allclose(p[:, 1], np.where(upper, 1, -1) * tmr_formula(p[:, 0]), rtol=0, atol=2e-16)
    assert abs(tmr_formula(1.0)) < 1e-15
    te = trailing_edge(section)
    assert te.sharp and te.gap < 1e-15
    np.testing.assert_allclose([te.lower, te.upper], [[1, 0], [1, 0]], atol=1e-15)
    # its thickness: the classic NACA 0012 runs on to close at x = 1.00893; scaled to chord 1 it
    # keeps 0.12 / 1.00893 of chord
    x = np.linspace(0, 1, 200001)
    assert 2 * tmr_formula(x).max() == pytest.approx(0.12 / 1.00893, rel=5e-4)


def half_sections(section, n=200001):
    """Upper and lower points at the same chord station x_c (parameters t and 1 - t)."""
    t = np.linspace(0.5, 1.0, n)
    return section.shape(t), section.shape(1.0 - t), np.sin(0.5 * np.pi * (2 * t - 1)) ** 2


def test_naca_2412_thickness_and_camber_are_the_published_ones():
    upper, lower, x = half_sections(naca_section("2412"))
    thickness = np.linalg.norm(upper - lower, axis=1)
    camber = 0.5 * (upper + lower)
    np.testing.assert_allclose(camber[:, 0], x, atol=1e-15)  # the midpoint is the camber point
    assert thickness.max() == pytest.approx(0.12, abs=2e-4) and x[thickness.argmax()] == pytest.approx(0.30, abs=0.01)
    assert camber[:, 1].max() == pytest.approx(0.02, abs=1e-12) and x[camber[:, 1].argmax()] == pytest.approx(0.4, abs=1e-4)
    # thickness applied perpendicular to the camber line: the upper point minus the camber point is
    # normal to the camber line's tangent (finite differences of the midpoints)
    tangent = np.gradient(camber, axis=0)
    inside = slice(10, -10)
    cosine = np.sum((upper - camber)[inside] * tangent[inside], axis=1) / (
        thickness[inside] / 2 * np.linalg.norm(tangent[inside], axis=1)
    )
    assert np.abs(cosine).max() < 1e-4


def test_naca_23012_constants_and_camber():
    constants = naca_constants("NACA 23012")
    assert constants["m"] == 0.2025 and constants["k1"] == 15.957
    upper, lower, x = half_sections(naca_section("23012"))
    camber = 0.5 * (upper + lower)
    assert camber[:, 1].max() == pytest.approx(0.0184, abs=1e-4) and x[camber[:, 1].argmax()] == pytest.approx(0.15, abs=1e-3)
    np.testing.assert_allclose(naca_camber("23012", [0.0, 1.0])[0], 0.0, atol=1e-15)


def thin_airfoil(designation):
    """(ideal lift coefficient pi A1, moment about the quarter chord pi/4 (A2 - A1)) of a camber
    line by thin-airfoil theory, A_n = 2/pi int dy_c/dx cos(n theta) dtheta, x = (1 - cos theta)/2."""
    m = naca_constants(designation)["m"]
    kink = np.arccos(1 - 2 * m)

    def coefficient(n):
        def f(th):
            return naca_camber(designation, 0.5 * (1 - np.cos(th)))[1] * np.cos(n * th)

        return 2 / np.pi * (quad(f, 0, kink, epsabs=1e-13)[0] + quad(f, kink, np.pi, epsabs=1e-13)[0])

    a1, a2 = coefficient(1), coefficient(2)
    return np.pi * a1, np.pi / 4 * (a2 - a1)


@pytest.mark.parametrize("designation", ["22112", "23112", "24112", "25112", "23012", "24012", "33012"])
def test_naca_5_digit_camber_lines_meet_their_definition(designation):
    lift, moment = thin_airfoil(designation)
    constants = naca_constants(designation)
    assert lift == pytest.approx(0.15 * int(designation[0]), rel=3e-4)
    x = np.linspace(0, 1, 400001)
    assert x[np.argmax(naca_camber(designation, x)[0])] == pytest.approx(int(designation[1]) / 20, abs=2e-3)
    if constants["reflex"]:
        assert abs(moment) < 1e-8  # the reflex: no pitching moment about the quarter chord
    else:
        assert moment < -0.005


@pytest.mark.parametrize(
    "digit, published", [(2, (0.1300, 51.990)), (3, (0.2170, 15.793)), (4, (0.3180, 6.520)), (5, (0.4410, 3.191))]
)
def test_reflex_constants_are_close_to_the_published_table(digit, published):
    constants = naca_constants(f"2{digit}112")
    assert constants["m"] == pytest.approx(published[0], rel=0.01)
    assert constants["k1"] == pytest.approx(published[1], rel=0.02)


def test_naca_trailing_edge_open_and_closed_and_symmetric_0012():
    classic, closed = naca_section("0012"), naca_section("0012", closed_te=True)
    te = trailing_edge(classic)
    assert not te.sharp and te.gap == pytest.approx(2 * 5 * 0.12 * (0.2969 - 0.1260 - 0.3516 + 0.2843 - 0.1015), rel=1e-12)
    np.testing.assert_allclose([te.lower, te.upper], [[1, -0.00126], [1, 0.00126]], atol=1e-15)
    assert trailing_edge(closed).sharp and trailing_edge(closed).gap < 1e-12
    s = np.linspace(0, classic.length, 101)
    np.testing.assert_allclose(points_at(classic, s), points_at(classic, classic.length - s) * [1, -1], atol=1e-12)
    assert chord_length(classic) == pytest.approx(1.0, abs=1e-15)


def naca_points(designation, n=41):
    """Upper and lower surfaces of a NACA section at cosine-spaced chord stations (LE -> TE)."""
    section = naca_section(designation)
    t = 0.5 + 0.5 * np.linspace(0, 1, n)
    return section.shape(t), section.shape(1 - t)


def selig_text(name, upper, lower):
    rows = np.concatenate([upper[::-1], lower[1:]])
    return name + "\n" + "\n".join(f"{x:.17g} {y:.17g}" for x, y in rows) + "\n"


def lednicer_text(name, upper, lower):
    def block(points):
        return "\n".join(f"  {x:.17g}  {y:.17g}" for x, y in points)

    return f"{name}\n{len(upper)}.  {len(lower)}.\n\n{block(upper)}\n\n{block(lower)}\n"


def test_selig_and_lednicer_files_give_the_same_curve(tmp_path):
    upper, lower = naca_points("2412")
    (tmp_path / "a.dat").write_text(selig_text("NACA 2412 Selig", upper, lower))
    (tmp_path / "b.dat").write_text(lednicer_text("NACA 2412 Lednicer", upper, lower))
    selig, lednicer = read_section(tmp_path / "a.dat"), read_section(tmp_path / "b.dat")
    assert selig.name == "NACA 2412 Selig" and lednicer.name == "NACA 2412 Lednicer"
    assert selig.length == pytest.approx(lednicer.length, rel=1e-15)
    s = np.linspace(0, selig.length, 333)
    np.testing.assert_allclose(points_at(selig, s), points_at(lednicer, s), atol=1e-14)
    # the spline of 41 points per surface follows the formula it was sampled from
    assert selig.length == pytest.approx(naca_section("2412").length, rel=1e-4)
    # a Selig file that runs under the lower surface first is turned round
    reversed_text = selig_text("reversed", lower, upper)
    _, u, low = parse_section_text(reversed_text)
    np.testing.assert_array_equal(u, upper)
    np.testing.assert_array_equal(low, lower)


def test_a_sharp_trailing_edge_file_closes_its_spline(tmp_path):
    x = 0.5 * (1 - np.cos(np.linspace(0, np.pi, 61)))
    upper = np.stack([x, tmr_formula(x)], axis=1)
    lower = upper * [1, -1]
    (tmp_path / "tmr.dat").write_text(selig_text("TMR 0012 points", upper, lower))
    section = load_section(tmp_path / "tmr.dat")
    te = trailing_edge(section)
    assert te.sharp and te.gap < 1e-15 and not section.analytic
    np.testing.assert_allclose(points_at(section, [0.0, section.length]), [[1, 0], [1, 0]], atol=1e-15)
    assert section.length == pytest.approx(tmr0012_section().length, rel=1e-5)
    s = chordwise_distribution(section, 100, 1e-3, 1e-3)
    p = points_at(section, s)  # between data points the spline lies close to the formula
    np.testing.assert_allclose(np.abs(p[:, 1]), tmr_formula(np.clip(p[:, 0], 0, 1)), atol=2e-5)


def test_spline_passes_through_the_data_and_is_curvature_continuous():
    upper, lower = naca_points("4415", n=31)
    _, u, low = parse_section_text(selig_text("4415", upper, lower))
    section = data_section("4415", u, low)
    np.testing.assert_array_equal(section.points, np.concatenate([lower[::-1], upper[1:]]))
    np.testing.assert_allclose(section.shape(section.knots), section.points, rtol=0, atol=1e-15)
    spline = section.shape  # scipy CubicSpline: piecewise cubics c[k] (x - knot)^(3-k)
    c, h = spline.c, np.diff(section.knots)
    left = 6 * c[0, :-1] * h[:-1, None] + 2 * c[1, :-1]  # second derivative at each interior knot, from the left
    right = 2 * c[1, 1:]  # and from the right
    scale = np.abs(right).max()
    assert np.abs(left - right).max() < 1e-9 * scale
    jump = np.abs(c[0, 1:] - c[0, :-1]).max()  # the third derivative does jump: a real test
    assert jump > 1e-3 * np.abs(c[0]).max()
    # at the nodes of the arc-length map, the points are the data
    arcs = section.knot_arcs
    np.testing.assert_allclose(points_at(section, arcs), section.points, atol=1e-12)


@pytest.mark.parametrize("name", ["tmr0012", "2412", "23112"])
def test_arc_length_against_a_fine_polyline(name):
    section = load_section(name)
    t = np.sin(0.5 * np.pi * np.linspace(-1, 1, 400001)) * 0.5 + 0.5
    polyline = np.linalg.norm(np.diff(section.shape(t), axis=0), axis=1).sum()
    assert section.length == pytest.approx(polyline, rel=1e-9)
    s_le = leading_edge_arc(section)
    np.testing.assert_allclose(points_at(section, [s_le])[0], [0, 0], atol=1e-12)


@pytest.mark.parametrize(
    "section",
    [naca4_section(0.04, 0.3, 0.12), naca_section("23012"), naca_section("23112"), tmr0012_section()],
    ids=lambda section: section.name,
)
def test_analytic_derivatives_are_the_complex_step_of_the_shape(section):
    """The sections' chain-rule derivative against the complex step of their own shape, which is
    exact to rounding (the same section made without a derivative uses it)."""
    t = np.linspace(0.0, 1.0, 20001)
    reference = analytic_section("complex step", section.shape, 0.5).derivative(t)
    np.testing.assert_allclose(section.derivative(t), reference, rtol=0, atol=1e-13 * np.abs(reference).max())


@pytest.mark.parametrize("name", ["2412", "tmr0012"])
def test_arc_lengths_invert_to_their_parameters_at_the_trailing_edges(name):
    """Where the sine parameter's speed vanishes (s ~ t^2 at the trailing edges) too: the arc
    length from 0 to each found t, by adaptive quadrature, is the asked one."""
    section = load_section(name)
    length = section.length
    s = np.concatenate(
        [[1e-9, 1e-7, 1e-5, 1e-3], np.linspace(0.01, length - 0.01, 7), length - np.array([1e-3, 1e-5, 1e-7, 1e-9])]
    )
    t = parameters_at(section, s)

    def speed(u):
        return float(np.linalg.norm(section.derivative(np.array([u]))[0]))

    knots = section.knots
    pieces = [quad(speed, a, b, epsabs=1e-16, epsrel=1e-14)[0] for a, b in zip(knots[:-1], knots[1:])]
    at_knots = np.concatenate([[0.0], np.cumsum(pieces)])
    start = np.searchsorted(knots, t, side="right") - 1
    found = [at_knots[k] + quad(speed, knots[k], u, epsabs=1e-16, epsrel=1e-14)[0] for k, u in zip(start, t)]
    np.testing.assert_allclose(found, s, rtol=0, atol=1e-13 * length)


def test_tangents_and_normals():
    section = naca_section("2412")
    s = np.linspace(0.01, section.length - 0.01, 200)
    step = 1e-6
    difference = (points_at(section, s + step) - points_at(section, s - step)) / (2 * step)
    tangent, normal = tangents_at(section, s), normals_at(section, s)
    np.testing.assert_allclose(tangent, difference, atol=1e-6)
    np.testing.assert_allclose(np.sum(tangent * normal, axis=1), 0, atol=1e-15)
    # at the leading edge the thickness is applied along the camber line's normal, so the surface
    # normal there points back along the camber line: -(1, dy_c/dx(0)) = -(1, 2 m / p)
    np.testing.assert_allclose(
        normals_at(section, [leading_edge_arc(section)])[0], -np.array([1, 0.1]) / np.hypot(1, 0.1), atol=1e-9
    )
    upper = s > leading_edge_arc(section) + 0.2
    lower = s < leading_edge_arc(section) - 0.2
    assert np.all(normal[upper, 1] > 0) and np.all(normal[lower, 1] < 0)


@pytest.mark.parametrize(
    "name, cells, le, te", [("2412", 200, 1e-3, 5e-4), ("tmr0012", 128, 2e-3, 1e-3), ("23012", 300, 5e-4, 2e-3)]
)
def test_chordwise_distribution_meets_the_asked_spacings(name, cells, le, te):
    section = load_section(name)
    s = chordwise_distribution(section, cells, le, te)
    assert s.shape == (cells + 1,) and s[0] == 0 and s[-1] == section.length and np.all(np.diff(s) > 0)
    k = int(np.flatnonzero(np.isclose(s, leading_edge_arc(section), rtol=0, atol=1e-13))[0])
    p = points_at(section, s)
    gaps = np.linalg.norm(np.diff(p, axis=0), axis=1)  # straight distances between nodes
    np.testing.assert_allclose([gaps[0], gaps[-1]], te, rtol=0.01)
    np.testing.assert_allclose([gaps[k - 1], gaps[k]], le, rtol=0.01)
    assert k == pytest.approx(cells * leading_edge_arc(section) / section.length, abs=1)
    if name == "tmr0012":
        np.testing.assert_allclose(np.abs(p[:, 1]), tmr_formula(p[:, 0]), atol=2e-16)


def test_chordwise_distribution_puts_a_node_on_each_crest():
    # The TMR NACA 0012's crest: where the formula's slope is zero (the thickest point, x about 0.30).
    from scipy.optimize import brentq

    slope = lambda x: (tmr_formula(x + 1e-7) - tmr_formula(x - 1e-7)) / 2e-7  # noqa: E731
    crest_x = brentq(slope, 0.2, 0.4, xtol=1e-12)
    section = load_section("tmr0012")
    plain = chordwise_distribution(section, 274, 1e-3, 1e-3)
    x = points_at(section, plain)[:, 0]
    assert np.abs(x - crest_x).min() > 1e-3  # no node there to start with
    for spacing in (np.inf, 0.0036):
        s = chordwise_distribution(section, 274, 1e-3, 1e-3, crest=(spacing, (0.0, 1.0)))
        p = points_at(section, s)
        assert s.shape == plain.shape and np.all(np.diff(s) > 0)
        for surface in (p[:138], p[137:]):  # lower, upper (the leading edge is node 137 of both)
            k = int(np.argmin(np.abs(surface[:, 0] - crest_x)))
            assert surface[k, 0] == pytest.approx(crest_x, abs=1e-6)  # a node on the crest
            if spacing < np.inf:  # its cells the asked length
                np.testing.assert_allclose(np.linalg.norm(np.diff(surface[k - 1 : k + 2], axis=0), axis=1), spacing, rtol=0.01)
        gaps = np.linalg.norm(np.diff(p, axis=0), axis=1)
        np.testing.assert_allclose([gaps[0], gaps[136], gaps[137], gaps[-1]], 1e-3, rtol=0.01)  # the edges as before
    # Uncapped, only nodes near the crest move, each by less than its cells; the edges' stay bit for bit.
    moved = chordwise_distribution(section, 274, 1e-3, 1e-3, crest=(np.inf, (0.0, 1.0)))
    shift = np.abs(moved - plain)
    assert np.all(shift[1:-1] < 0.5 * np.minimum(np.diff(plain)[1:], np.diff(plain)[:-1]) + 1e-15)
    assert np.array_equal(moved[np.abs(x - crest_x) > 0.2], plain[np.abs(x - crest_x) > 0.2])
    # A direction whose farthest point is an edge (upstream: the leading edge): nothing moves.
    assert np.array_equal(chordwise_distribution(section, 274, 1e-3, 1e-3, crest=(0.0036, (-1.0, 0.0))), plain)


def test_vinokur_end_spacings_and_refusals():
    s = vinokur(50, 1e-4, 3e-2)
    assert s[0] == 0 and s[-1] == 1 and np.all(np.diff(s) > 0)
    np.testing.assert_allclose([s[1], 1 - s[-2]], [1e-4, 3e-2], rtol=1e-10)
    coarse = vinokur(10, 0.15, 0.12)  # both above the uniform 0.1: the sine branch
    np.testing.assert_allclose([coarse[1], 1 - coarse[-2]], [0.15, 0.12], rtol=1e-10)
    with pytest.raises(ParameterError, match="do not fit"):
        vinokur(10, 0.6, 0.5)
    with pytest.raises(ParameterError, match="at least 2 cells"):
        vinokur(1, 0.1, 0.1)


def selig_rows(text_rows, name="bad"):
    return name + "\n" + "\n".join(text_rows) + "\n"


GOOD = ["1 0.001", "0.5 0.06", "0.2 0.05", "0 0", "0.2 -0.04", "0.5 -0.03", "1 -0.001"]


@pytest.mark.parametrize(
    "rows, message",
    [
        (["1 0.001", "0.2 0.05", "0.5 0.06", "0 0", "0.5 -0.03", "1 -0.001"], "back-tracks"),
        (GOOD[:2] + ["0.5 0.06"] + GOOD[2:], "duplicate point"),
        (
            ["1 -0.01", "0.9 -0.005", "0.5 0.06", "0.2 0.05", "0 0", "0.2 -0.04", "0.5 -0.03", "0.9 0.005", "1 0.01"],
            "self-crossing",
        ),
        (["1 -0.01", "0.5 0.06", "0.2 0.05", "0 0", "0.2 -0.04", "0.5 -0.03", "1 0.01"], "self-crossing.*x = 1"),
        (["1 0.2", "0.5 0.06", "0.2 0.05", "0 0", "0.2 -0.04", "0.5 -0.03", "1 -0.001"], "open contour"),
        (["1 0", "0 0", "0.5 -0.03", "1 -0.001"], "at least 3"),
        (GOOD[:3] + ["nan 0.02"] + GOOD[3:], "finite"),
        (GOOD[:3] + ["0.1 abc"] + GOOD[3:], "expected two numbers"),
        (GOOD[:3] + ["0.1 0.2 0.3"] + GOOD[3:], "expected two numbers"),
        ([], "no coordinates"),
    ],
)
def test_bad_selig_files_are_refused_on_one_line(rows, message):
    with pytest.raises(GeometryError, match=message) as caught:
        parse_section_text(selig_rows(rows))
    assert "\n" not in str(caught.value)


def test_the_good_file_of_those_tests_is_accepted_with_a_blunt_trailing_edge():
    name, upper, lower = parse_section_text(selig_rows(GOOD, "good"))
    section = data_section(name, upper, lower)
    te = trailing_edge(section)
    assert name == "good" and not te.sharp and te.gap == pytest.approx(0.002)


def test_bad_lednicer_files_are_refused_on_one_line():
    upper, lower = naca_points("2412", n=9)
    moved = lower + [0, 0]
    moved[0] = [0.001, -0.002]
    with pytest.raises(GeometryError, match="do not meet at the leading edge"):
        parse_section_text(lednicer_text("x", upper, moved))
    text = lednicer_text("x", upper, lower).replace(f"\n{len(upper)}.", f"\n{len(upper) + 1}.")
    with pytest.raises(GeometryError, match="counts line says 10 upper"):
        parse_section_text(text)


@pytest.mark.parametrize("name", ["2412x", "99", "26012", "23212", "21112", "2400", "2012", "0012345", "naca"])
def test_unknown_naca_designations_say_what_valid_looks_like(name):
    with pytest.raises(ParameterError, match="4 digits.*5 digits") as caught:
        load_section(name)
    assert "\n" not in str(caught.value)


def test_unreadable_file(tmp_path):
    with pytest.raises(GeometryError, match="cannot be read"):
        read_section(tmp_path / "missing.dat")

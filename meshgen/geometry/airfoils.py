"""Airfoil sections: NACA 4- and 5-digit, the NASA TMR NACA 0012, and coordinate files (Selig and
Lednicer formats), as ``meshgen.geometry.airfoil_curve.Section`` curves.

NACA and TMR sections are analytic, chord 1, leading edge at (0, 0), the camber line ending at
(1, 0); their curve parameter t in [0, 1] maps to the chordwise station x = sin^2(theta/2),
theta = pi (2t - 1) (x = 1 at the lower trailing edge t = 0, 0 at the leading edge t = 1/2, 1 at
the upper trailing edge t = 1), and a node is the formula at its x: the thickness y_t(x) applied
perpendicular to the camber line y_c(x) (Abbott and von Doenhoff, *Theory of Wing Sections*, 1959,
§6.4), so on the upper surface (x - y_t sin phi, y_c + y_t cos phi), phi = atan(dy_c/dx).

Coordinate files: Selig (a name line, then "x y" rows from the trailing edge over the upper surface
to the leading edge, the point of least x, and back under the lower surface) or Lednicer (a name
line, a counts line "NU NL", then NU upper rows and NL lower rows, each surface from the leading
edge to the trailing edge, blank lines between). Rules: every row is two finite numbers; each
surface has at least ``MIN_SURFACE_POINTS`` points and x strictly increasing from the leading edge
(no duplicate or back-tracking points); Lednicer's two surfaces start at one leading-edge point
(within ``LE_TOL`` of chord); the upper surface lies above the lower at every station (a file that
lists the lower surface first is turned round; surfaces that cross are refused). The trailing edge
may be open, a blunt base, up to ``MAX_TE_GAP`` of chord; a wider gap is an open contour, refused.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from meshgen.errors import GeometryError, ParameterError, excerpt
from meshgen.geometry.airfoil_curve import Section, analytic_section, spline_section

__all__ = [
    "LE_TOL",
    "MAX_TE_GAP",
    "MIN_SURFACE_POINTS",
    "NACA_5_REFLEX",
    "NACA_5_STANDARD",
    "TMR_0012",
    "MAX_CAMBER",
    "MAX_THICKNESS",
    "CAMBER_POSITIONS",
    "camber_breaks",
    "data_section",
    "load_section",
    "naca4_camber",
    "naca4_section",
    "naca_camber",
    "naca_constants",
    "naca_section",
    "naca_thickness",
    "parse_section_text",
    "read_section",
    "thickness_derivative",
    "thickness_shape",
    "tmr0012_section",
]

MIN_SURFACE_POINTS = 3  # per surface, leading and trailing edge included (5 points in all)
LE_TOL = 1e-4  # Lednicer surfaces' leading-edge points may differ by this fraction of chord
MAX_TE_GAP = 0.05  # the widest blunt trailing edge, as a fraction of chord
MAX_THICKNESS = 0.4  # naca4_section's thickest section (chords)
MAX_CAMBER = 0.095  # its largest camber (chords): the 4-digit designations' 9 %
CAMBER_POSITIONS = (0.1, 0.9)  # where its camber may peak (chords)

# Thickness y_t(x) = scale (a0 sqrt(x) + a1 x + a2 x^2 + a3 x^3 + a4 x^4).
NACA_THICKNESS = (0.2969, -0.1260, -0.3516, 0.2843, -0.1015)
NACA_CLOSED_A4 = -0.1036
# NASA Turbulence Modeling Resource NACA 0012 (sharp trailing edge): (scale, coefficients).
TMR_0012 = (0.594689181, (0.298222773, -0.127125232, -0.357907906, 0.291984971, -0.105174606))

# NACA 5-digit camber constants for the design lift coefficient 0.3: the digit P (max camber at
# x = P/20) -> (m, k1), the standard lines as published (Abbott and von Doenhoff). The reflex lines
# (m, k1, k2/k1) are solved from their definition, max camber at P/20, zero pitching moment about
# the quarter chord and ideal lift 0.3 by thin-airfoil theory: the table usually quoted (231: 0.2170,
# 15.793, 0.00677) misses its zero moment by up to 0.0013 and its lift by up to 1.7 %.
NACA_5_STANDARD = {1: (0.0580, 361.400), 2: (0.1260, 51.640), 3: (0.2025, 15.957), 4: (0.2900, 6.643), 5: (0.3910, 3.230)}
NACA_5_REFLEX = {
    2: (0.1307497584, 51.12024974, 0.0009156648812),
    3: (0.2160145029, 15.69097550, 0.006213413775),
    4: (0.3179188983, 6.507292932, 0.03019517039),
    5: (0.4408303366, 3.175524257, 0.1348777427),
}

_VALID_NACA = (
    "NACA MPTT (4 digits: camber M % at P/10 chord, thickness TT %, e.g. 2412, 0012) or LPSTT (5 digits: design "
    "lift 0.15 L, camber peak at P/20 chord with P 1-5, S 0 standard or 1 reflex, e.g. 23012, 23112)"
)


def naca_constants(designation: str) -> dict:
    """The parameters of a NACA designation ("2412", "NACA 23012", "naca23112"): {"digits",
    "thickness", and "m", "p" (4-digit) or "m", "k1", "k2_k1", "reflex" (5-digit, k1 scaled to
    the design lift)}; ParameterError for anything else."""
    text = re.sub(r"[\s_-]", "", str(designation)).lower().removeprefix("naca")
    bad = ParameterError("naca", f"{{name}} {excerpt(designation)!r} is not a NACA section: expected {_VALID_NACA}")
    if not (text.isdigit() and len(text) in (4, 5)) or int(text[-2:]) == 0:
        raise bad
    found = {"digits": text, "thickness": int(text[-2:]) / 100.0}
    if len(text) == 4:
        m, p = int(text[0]) / 100.0, int(text[1]) / 10.0
        if m > 0 and p == 0:
            raise bad
        return {**found, "m": m, "p": p}
    lift, position, reflex = int(text[0]), int(text[1]), int(text[2])
    table = NACA_5_REFLEX if reflex == 1 else NACA_5_STANDARD
    if lift == 0 or reflex > 1 or position not in table:
        raise bad
    m, k1, *ratio = table[position]
    return {**found, "m": m, "k1": k1 * lift / 2.0, "k2_k1": ratio[0] if ratio else 0.0, "reflex": bool(reflex)}


def naca4_camber(m: float, p: float, x) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The 4-digit camber line of maximum camber ``m`` (chords) at ``p`` (chords, 0 < p < 1), its
    slope and the slope's derivative, at chord stations ``x`` (m,): two parabolas meeting at p (any
    real m, p: a family's)."""
    x = np.asarray(x)
    x = x.astype(complex if np.iscomplexobj(x) else float)  # complex: for complex-step derivatives
    if m == 0:
        return np.zeros_like(x), np.zeros_like(x), np.zeros_like(x)
    front = x.real < p
    scale = np.where(front, m / p**2, m / (1 - p) ** 2)
    yc = np.where(front, scale * (2 * p * x - x**2), scale * (1 - 2 * p + 2 * p * x - x**2))
    return yc, 2 * scale * (p - x), -2 * scale


def naca_camber(designation: str, x) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The camber line y_c(x), its slope dy_c/dx and d^2y_c/dx^2 at chord stations ``x`` (m,) in [0, 1]."""
    c = naca_constants(designation)
    x = np.asarray(x)
    x = x.astype(complex if np.iscomplexobj(x) else float)  # complex: for complex-step derivatives
    if len(c["digits"]) == 4:
        return naca4_camber(c["m"], c["p"], x)
    m, k1, r = c["m"], c["k1"], c["k2_k1"]
    front = x.real < m
    if not c["reflex"]:
        yc = np.where(front, k1 / 6 * (x**3 - 3 * m * x**2 + m**2 * (3 - m) * x), k1 * m**3 / 6 * (1 - x))
        slope = np.where(front, k1 / 6 * (3 * x**2 - 6 * m * x + m**2 * (3 - m)), -k1 * m**3 / 6)
        return yc, slope, np.where(front, k1 * (x - m), 0.0)
    factor = np.where(front, 1.0, r)
    yc = k1 / 6 * (factor * (x - m) ** 3 - r * (1 - m) ** 3 * x - m**3 * x + m**3)
    return yc, k1 / 6 * (3 * factor * (x - m) ** 2 - r * (1 - m) ** 3 - m**3), k1 * factor * (x - m)


def naca_thickness(x, thickness: float, closed_te: bool = False) -> np.ndarray:
    """The NACA half-thickness y_t(x) = 5 t (0.2969 sqrt(x) - 0.1260 x - 0.3516 x^2 + 0.2843 x^3
    + a4 x^4) at ``x`` (m,), a4 = -0.1015 (classic, open trailing edge) or -0.1036 (closed)."""
    a = NACA_THICKNESS[:4] + ((NACA_CLOSED_A4,) if closed_te else NACA_THICKNESS[4:])
    x = np.asarray(x, dtype=float)
    return 5.0 * thickness * (a[0] * np.sqrt(x) + x * (a[1] + x * (a[2] + x * (a[3] + x * a[4]))))


def thickness_shape(scale: float, coefficients, camber=None):
    """The shape t (m,) -> points (m, 2) of a section with half-thickness scale (a0 sqrt(x) + a1 x
    + ... + a4 x^4) applied perpendicular to ``camber`` (x -> (y_c, dy_c/dx); None: symmetric), on
    the parameter of the module docstring; real or complex t alike."""
    a0, a1, a2, a3, a4 = coefficients

    def shape(t):
        theta = np.pi * (2.0 * np.asarray(t) - 1.0)  # complex t: for complex-step derivatives
        root = np.sin(0.5 * theta)  # sqrt(x), negative on the lower surface
        x = root**2
        half = scale * (a0 * root + np.sign(theta.real) * x * (a1 + x * (a2 + x * (a3 + x * a4))))
        if camber is None:
            return np.stack([x, half], axis=1)
        yc, slope = camber(x)[:2]
        phi = np.arctan(slope)
        return np.stack([x - half * np.sin(phi), yc + half * np.cos(phi)], axis=1)

    return shape


def thickness_derivative(scale: float, coefficients, camber=None):
    """The derivative dp/dt (m, 2) of ``thickness_shape(scale, coefficients, camber)`` at t (m,),
    by the chain rule (``camber`` x -> (y_c, dy_c/dx, d^2y_c/dx^2)); real t only (about three times
    faster than the complex step, which the tests check it against)."""
    a0, a1, a2, a3, a4 = coefficients

    def derivative(t):
        theta = np.pi * (2.0 * np.asarray(t, dtype=float) - 1.0)
        root, droot = np.sin(0.5 * theta), np.pi * np.cos(0.5 * theta)
        x = root**2
        dx = 2.0 * root * droot
        sign = np.sign(theta)
        half = scale * (a0 * root + sign * x * (a1 + x * (a2 + x * (a3 + x * a4))))
        dhalf = scale * (a0 * droot + sign * (a1 + x * (2 * a2 + x * (3 * a3 + x * 4 * a4))) * dx)
        if camber is None:
            return np.stack([dx, dhalf], axis=1)
        _, slope, curvature = camber(x)
        phi = np.arctan(slope)
        dphi = curvature / (1.0 + slope * slope) * dx
        sin, cos = np.sin(phi), np.cos(phi)
        return np.stack([dx - dhalf * sin - half * cos * dphi, slope * dx + dhalf * cos - half * sin * dphi], axis=1)

    return derivative


def camber_breaks(x: float) -> tuple[float, float]:
    """The curve parameters (lower, upper) of chordwise station ``x`` in (0, 1), where a camber
    line's two pieces meet (module docstring: x = sin^2(theta / 2), theta = pi (2t - 1))."""
    theta = 2.0 * np.arcsin(np.sqrt(x))
    return 0.5 * (1.0 - theta / np.pi), 0.5 * (1.0 + theta / np.pi)


def naca_section(designation: str, *, closed_te: bool = False) -> Section:
    """The analytic NACA 4- or 5-digit section (chord 1), with the classic open trailing edge or,
    ``closed_te``, the closed one (a4 = -0.1036)."""
    c = naca_constants(designation)
    coefficients = NACA_THICKNESS[:4] + ((NACA_CLOSED_A4,) if closed_te else NACA_THICKNESS[4:])
    cambered = c["m"] > 0

    def camber(x):
        return naca_camber(c["digits"], x)

    parts = (5.0 * c["thickness"], coefficients, camber if cambered else None)
    junction = c["p"] if len(c["digits"]) == 4 else c["m"]  # where the camber line's pieces meet
    breaks = camber_breaks(junction) if cambered else ()
    name = f"NACA {c['digits']}" + (" (closed trailing edge)" if closed_te else "")
    return analytic_section(name, thickness_shape(*parts), 0.5, derivative=thickness_derivative(*parts), breaks=breaks)


def naca4_section(camber: float, position: float, thickness: float, *, closed_te: bool = True) -> Section:
    """The NACA 4-digit section of continuous parameters (chord 1): maximum camber ``camber`` at
    ``position`` (chords), ``thickness`` (chords), closed trailing edge by default (a4 = -0.1036).
    ParameterError (one line, naming the parameter) for a section that is not one."""
    if not 0.0 < thickness <= MAX_THICKNESS:
        raise ParameterError(
            "thickness", f"{{name}} {thickness:g}: a section's thickness must lie in (0, {MAX_THICKNESS:g}] chord"
        )
    if not 0.0 <= camber <= MAX_CAMBER:
        raise ParameterError("camber", f"{{name}} {camber:g}: the camber must lie in [0, {MAX_CAMBER:g}] chord")
    if not CAMBER_POSITIONS[0] <= position <= CAMBER_POSITIONS[1]:
        low, high = CAMBER_POSITIONS
        raise ParameterError("camber_position", f"{{name}} {position:g}: the camber's peak must lie at {low:g} to {high:g} chord")
    coefficients = NACA_THICKNESS[:4] + ((NACA_CLOSED_A4,) if closed_te else NACA_THICKNESS[4:])

    def camber_line(x):
        return naca4_camber(camber, position, x)

    parts = (5.0 * thickness, coefficients, camber_line if camber > 0 else None)
    name = f"NACA 4-digit m={camber:g} p={position:g} t={thickness:g}" + (" (closed trailing edge)" if closed_te else "")
    breaks = camber_breaks(position) if camber > 0 else ()
    return analytic_section(name, thickness_shape(*parts), 0.5, derivative=thickness_derivative(*parts), breaks=breaks)


def tmr0012_section() -> Section:
    """The NASA TMR NACA 0012: y = +-0.594689181 (0.298222773 sqrt(x) - 0.127125232 x - 0.357907906
    x^2 + 0.291984971 x^3 - 0.105174606 x^4), 0 <= x <= 1, sharp trailing edge (y(1) = 0 to rounding)."""
    return analytic_section("TMR NACA 0012", thickness_shape(*TMR_0012), 0.5, derivative=thickness_derivative(*TMR_0012))


def _rows(text: str, source: str) -> tuple[str, list[tuple[int, float, float]], list[int]]:
    """(name, [(line number, x, y)], line numbers of blank lines) of a coordinate file's text."""
    lines = str(text).splitlines()
    name, rows, blanks = "", [], []
    for number, line in enumerate(lines, start=1):
        words = line.replace(",", " ").split()
        if not words:
            blanks.append(number)
            continue
        try:
            values = [float(w) for w in words]
        except ValueError:
            values = None
        if not rows and not name and (values is None or len(values) != 2):
            name = line.strip()
            continue
        if values is None or len(values) != 2:
            raise GeometryError(f"{source}, line {number}: expected two numbers 'x y', got {excerpt(line)!r}")
        if not np.all(np.isfinite(values)):
            raise GeometryError(f"{source}, line {number}: {excerpt(line)!r} is not a pair of finite numbers")
        rows.append((number, *values))
    return name or Path(source).stem, rows, blanks


def parse_section_text(text: str, source: str = "<airfoil>") -> tuple[str, np.ndarray, np.ndarray]:
    """(name, upper (n, 2), lower (k, 2)) of a Selig or Lednicer file's text (format detected: a
    first row of two whole numbers above 1 is Lednicer's counts line), each surface from the
    leading edge to the trailing edge, checked by the rules of the module docstring."""
    name, rows, _ = _rows(text, source)
    source = f"airfoil file {source}"
    if not rows:
        raise GeometryError(f"{source}: no coordinates (Selig or Lednicer rows 'x y')")
    _, n_upper, n_lower = rows[0]
    if n_upper > 1 and n_lower > 1 and n_upper.is_integer() and n_lower.is_integer():  # Lednicer
        data = np.array([row[1:] for row in rows[1:]]).reshape(-1, 2)
        if len(data) != n_upper + n_lower:
            raise GeometryError(
                f"{source}: the counts line says {int(n_upper)} upper and {int(n_lower)} lower points, "
                f"but {len(data)} rows follow"
            )
        upper, lower = data[: int(n_upper)], data[int(n_upper) :]
        _check_counts(upper, lower, source)
        chord = np.linalg.norm(0.5 * (upper[-1] + lower[-1]) - upper[0])
        if np.linalg.norm(upper[0] - lower[0]) > LE_TOL * max(chord, 1e-300):
            raise GeometryError(
                f"{source}: the surfaces do not meet at the leading edge: upper starts at {_point(upper[0])}, "
                f"lower at {_point(lower[0])} (at most {LE_TOL:g} of chord apart)"
            )
        lower = np.concatenate([upper[:1], lower[1:]])
    else:  # Selig: trailing edge, upper surface, leading edge (least x), lower surface
        data = np.array([row[1:] for row in rows])
        le = int(np.argmin(data[:, 0]))
        upper, lower = data[: le + 1][::-1], data[le:]
        _check_counts(upper, lower, source, selig=True)
    upper, lower = _check_surfaces(upper, lower, source)
    return name, upper, lower


def _point(p) -> str:
    return f"({p[0]:.6g}, {p[1]:.6g})"


def _check_counts(upper, lower, source, selig=False):
    for side, points in (("upper", upper), ("lower", lower)):
        if len(points) < MIN_SURFACE_POINTS:
            where = " (the leading edge is the point of least x)" if selig else ""
            raise GeometryError(
                f"{source}: too few points: the {side} surface has {len(points)}{where}; each surface needs at least "
                f"{MIN_SURFACE_POINTS}, leading and trailing edge included ({2 * MIN_SURFACE_POINTS - 1} in all)"
            )


def _check_surfaces(upper: np.ndarray, lower: np.ndarray, source: str) -> tuple[np.ndarray, np.ndarray]:
    """The surfaces (each leading edge -> trailing edge, sharing the first point) checked by the
    rules of the module docstring; the upper one first."""
    for side, points in (("upper", upper), ("lower", lower)):
        steps = np.diff(points, axis=0)
        same = np.flatnonzero(np.all(steps == 0, axis=1))
        if same.size:
            raise GeometryError(f"{source}: duplicate point {_point(points[same[0]])} on the {side} surface")
        back = np.flatnonzero(steps[:, 0] <= 0)
        if back.size:
            raise GeometryError(
                f"{source}: the {side} surface back-tracks at {_point(points[back[0] + 1])} after {_point(points[back[0]])}: "
                "x must increase from the leading edge (least x) to the trailing edge"
            )
    chord = float(np.linalg.norm(0.5 * (upper[-1] + lower[-1]) - upper[0]))
    gap = float(np.linalg.norm(upper[-1] - lower[-1]))
    if gap > MAX_TE_GAP * chord:
        raise GeometryError(
            f"{source}: open contour: the trailing-edge points {_point(upper[-1])} and {_point(lower[-1])} are "
            f"{gap / chord:.3g} of chord apart (a blunt trailing edge may be at most {MAX_TE_GAP:g})"
        )
    end = min(upper[-1, 0], lower[-1, 0])
    stations = np.union1d(upper[1:, 0], lower[1:, 0])
    stations = np.append(stations[stations < end], end)  # the interior stations, then the trailing edge
    thick = np.interp(stations, upper[:, 0], upper[:, 1]) - np.interp(stations, lower[:, 0], lower[:, 1])
    if np.all(thick[:-1] < 0) and thick[-1] <= 0:
        upper, lower, thick = lower, upper, -thick
    # a sharp trailing edge closes: thickness 0, to rounding (1e-9 of chord)
    crossed = np.append(thick[:-1] <= 0, thick[-1] < -1e-9 * chord)
    if np.any(crossed):
        where = stations[np.argmax(crossed)]
        raise GeometryError(f"{source}: self-crossing contour: the upper and lower surfaces cross near x = {where:.6g}")
    return upper, lower


def data_section(name: str, upper, lower) -> Section:
    """A spline ``Section`` through checked surfaces ``upper`` and ``lower`` (each leading edge ->
    trailing edge, sharing the leading-edge point); a sharp trailing edge repeats its point."""
    upper, lower = np.asarray(upper, dtype=float), np.asarray(lower, dtype=float)
    points = np.concatenate([lower[::-1], upper[1:]])
    return spline_section(name, points, len(lower) - 1)


def read_section(path) -> Section:
    """The spline ``Section`` of a Selig or Lednicer coordinate file."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise GeometryError(f"airfoil file {path}: cannot be read ({exc.strerror or exc})") from None
    name, upper, lower = parse_section_text(text, str(path))
    return data_section(name, upper, lower)


def load_section(spec, *, closed_te: bool = False) -> Section:
    """A section by name or file: "tmr0012", a NACA designation ("2412", "naca23012"), or the path
    of a coordinate file; ``closed_te`` applies to NACA sections."""
    text = str(spec).strip()
    if text.lower().replace("-", "").replace("_", "") in ("tmr0012", "tmrnaca0012"):
        return tmr0012_section()
    if Path(text).is_file():
        return read_section(text)
    return naca_section(text, closed_te=closed_te)

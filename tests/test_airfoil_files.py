"""Airfoil coordinate files as geometries (``meshgen mesh -g section.dat``): the built-in airfoil
plugin's copy for the file (geometries/airfoil.py ``file_module``). Checked through the command
line: the wall nodes of the written .cgns lie on the file's C2 spline (rebuilt here with scipy from
the file's rows) and near the NACA formula the rows were sampled from; bad files are one line,
exit 2, nothing written."""

import numpy as np
import pytest
from scipy.interpolate import CubicSpline
from scipy.spatial import cKDTree

from meshgen.formats._cgns import read_zones

SMALL = ["--param", "farfield=10", "--param", "first_height=0.001", "--dims", "128", "60", "-m", "elliptic"]


def naca4(digits: str, n: int = 61, closed: bool = False):
    """Upper and lower surfaces (n, 2) of NACA ``digits`` (4-digit) at cosine stations, LE -> TE,
    from the formula of Abbott and von Doenhoff written out here."""
    m, p, t = int(digits[0]) / 100, int(digits[1]) / 10, int(digits[2:]) / 100
    x = 0.5 * (1 - np.cos(np.linspace(0, np.pi, n)))
    a4 = -0.1036 if closed else -0.1015
    yt = 5 * t * (0.2969 * np.sqrt(x) - 0.1260 * x - 0.3516 * x**2 + 0.2843 * x**3 + a4 * x**4)
    if m:
        yc = np.where(x < p, m / p**2 * (2 * p * x - x**2), m / (1 - p) ** 2 * (1 - 2 * p + 2 * p * x - x**2))
        phi = np.arctan(np.where(x < p, 2 * m / p**2 * (p - x), 2 * m / (1 - p) ** 2 * (p - x)))
    else:
        yc = phi = np.zeros_like(x)
    upper = np.stack([x - yt * np.sin(phi), yc + yt * np.cos(phi)], axis=1)
    lower = np.stack([x + yt * np.sin(phi), yc - yt * np.cos(phi)], axis=1)
    if closed:
        lower[-1] = upper[-1] = [1.0, 0.0]
    return upper, lower


def selig(upper, lower, name="section"):
    rows = np.concatenate([upper[::-1], lower[1:]])
    return name + "\n" + "\n".join(f"{x:.10f} {y:.10f}" for x, y in rows) + "\n"


def spline_distance(rows: np.ndarray, points: np.ndarray, spline: bool = True) -> np.ndarray:
    """Distances of ``points`` (k, 2) from the not-a-knot cubic spline through ``rows`` (n, 2)
    (lower trailing edge first) over cumulative chord length (or, not ``spline``, the polygon
    through them): nearest of 400001 samples, then the nearer of its two segments."""
    t = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(rows, axis=0), axis=1))])
    s = np.linspace(0.0, t[-1], 400001)
    curve = CubicSpline(t, rows)(s) if spline else np.stack([np.interp(s, t, rows[:, 0]), np.interp(s, t, rows[:, 1])], 1)
    _, i = cKDTree(curve).query(points)
    best = np.full(len(points), np.inf)
    for j in (np.maximum(i - 1, 0), np.minimum(i, len(curve) - 2)):
        a, b = curve[j], curve[j + 1]
        s = np.clip(np.einsum("ij,ij->i", points - a, b - a) / np.einsum("ij,ij->i", b - a, b - a), 0, 1)
        best = np.minimum(best, np.linalg.norm(a + s[:, None] * (b - a) - points, axis=1))
    return best


def wall_nodes(path, sharp: bool) -> np.ndarray:
    zones = {zone["name"]: zone["X"] for zone in read_zones(path)}
    names = ("section",) if sharp else ("lower", "section", "upper")
    return np.concatenate([zones[name][:, 0] for name in names])


@pytest.mark.parametrize("digits, closed", [("2414", False), ("0012", True)])
def test_a_selig_file_is_meshed_with_its_wall_nodes_on_the_spline(run_cli, tmp_path, digits, closed):
    upper, lower = (np.round(surface, 10) for surface in naca4(digits, closed=closed))  # as written
    (tmp_path / f"naca{digits}.dat").write_text(selig(upper, lower, f"NACA {digits}"))
    result = run_cli("mesh", "-g", f"naca{digits}.dat", *SMALL, "-o", "x.cgns")
    assert result.returncode == 0, result.stderr
    assert ("airfoil C-grid" if closed else "airfoil O-grid") in result.stdout
    assert "inverted cells: 0 " in result.stdout
    wall = wall_nodes(tmp_path / "x.cgns", sharp=closed)
    rows = np.concatenate([lower[::-1], upper[1:]])
    on_spline = spline_distance(rows, wall) < 1e-9
    a, b = lower[-1], upper[-1]  # the blunt base, a straight segment: the rest of the O-grid's wall
    s = np.clip((wall - a) @ (b - a) / max((b - a) @ (b - a), 1e-300), 0, 1)
    on_base = np.linalg.norm(a + s[:, None] * (b - a) - wall, axis=1) < 1e-12
    assert np.all(on_spline | on_base) and on_spline.sum() >= len(wall) - (0 if closed else 5)
    # On the spline, not on the polygon through the rows (a test that could tell them apart).
    assert spline_distance(rows, wall, spline=False).max() > 1e-5
    # And near the formula the rows came from: within the spline's interpolation error.
    fine_upper, fine_lower = naca4(digits, n=20001, closed=closed)
    exact = np.concatenate([fine_lower[::-1], fine_upper[1:]])
    assert cKDTree(exact).query(wall[on_spline])[0].max() < 1e-4


def test_a_lednicer_file_with_the_lower_surface_first_meshes_like_its_selig_twin(run_cli, tmp_path):
    upper, lower = naca4("2414", n=41)

    def block(points):
        return "\n".join(f"{x:.10f} {y:.10f}" for x, y in points)

    (tmp_path / "s.dat").write_text(selig(upper, lower))
    (tmp_path / "l.dat").write_text(f"NACA 2414\n{len(upper)}. {len(lower)}.\n\n{block(lower)}\n\n{block(upper)}\n")
    for name in ("s", "l"):
        result = run_cli("mesh", "-g", f"{name}.dat", *SMALL, "-m", "tfi", "--no-quality", "-o", f"{name}.cgns")
        assert result.returncode == 0, result.stderr
    a, b = read_zones(tmp_path / "s.cgns"), read_zones(tmp_path / "l.cgns")
    for za, zb in zip(a, b):
        np.testing.assert_allclose(za["X"], zb["X"], atol=1e-12)


GOOD = ["1 0.001", "0.5 0.06", "0.2 0.05", "0 0", "0.2 -0.04", "0.5 -0.03", "1 -0.001"]


@pytest.mark.parametrize(
    "rows, words",
    [
        (["1 0.001", "0.2 0.05", "0.5 0.06", "0 0", "0.5 -0.03", "0.2 -0.04", "1 -0.001"], "back-tracks"),
        (GOOD[:2] + ["0.5 0.06"] + GOOD[2:], "duplicate point"),
        (
            ["1 -0.01", "0.9 -0.005", "0.5 0.06", "0.2 0.05", "0 0", "0.2 -0.04", "0.5 -0.03", "0.9 0.005", "1 0.01"],
            "self-crossing",
        ),
        (["1 0.2"] + GOOD[1:], "open contour"),
        (["1 0", "0 0", "0.5 -0.03", "1 -0.001"], "too few points"),
        (GOOD[:3] + ["nan 0.02"] + GOOD[3:], "not a pair of finite numbers"),
        (GOOD[:3] + ["0.1 abc"] + GOOD[3:], "expected two numbers"),
        (["just a name", "and some words"], "expected two numbers"),
        ([], "no coordinates"),
    ],
)
def test_bad_files_are_one_line_exit_2_and_nothing_written(run_cli, tmp_path, rows, words):
    (tmp_path / "bad.dat").write_text("bad\n" + "\n".join(rows) + "\n")
    result = run_cli("mesh", "-g", "bad.dat", *SMALL, "-o", "x.cgns")
    assert result.returncode == 2, result.stdout + result.stderr
    assert words in result.stderr and "bad.dat" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert not list(tmp_path.glob("x*"))


def test_a_file_has_no_naca_parameter_and_a_missing_file_is_one_line(run_cli, tmp_path):
    upper, lower = naca4("2414")
    (tmp_path / "a.dat").write_text(selig(upper, lower))
    result = run_cli("mesh", "-g", "a.dat", *SMALL, "--param", "naca=12", "-o", "x.cgns")
    assert result.returncode == 2 and "naca" in result.stderr and len(result.stderr.strip().splitlines()) == 1
    missing = run_cli("mesh", "-g", "missing.dat", *SMALL, "-o", "x.cgns")
    assert missing.returncode == 2 and "missing.dat" in missing.stderr and len(missing.stderr.strip().splitlines()) == 1
    assert not list(tmp_path.glob("x*"))


def test_evaluate_measures_against_the_file_not_the_built_in_naca_0012(run_cli, tmp_path):
    # The file's plugin is named "airfoil" as the built-in is: the mesh records the file, so a later
    # evaluate never measures it against the default NACA 0012 section.
    upper, lower = naca4("2414")
    (tmp_path / "a.dat").write_text(selig(upper, lower))
    made = run_cli("mesh", "-g", "a.dat", "--dims", "160", "120", "-m", "tfi", "--no-quality", "-o", "x.cgns")
    assert made.returncode == 0, made.stderr
    given = run_cli("evaluate", "x.cgns", "-g", "a.dat")
    assert given.returncode == 0, given.stderr
    assert float(given.stdout.split("boundary deviation max")[1].split()[0]) < 1e-10
    # Without -g: the recorded file, trusted in this process only because -g named it above (a fresh
    # process says to pass -g PATH); never the built-in NACA 0012, 0.02 chord away from this NACA 2414.
    alone = run_cli("evaluate", "x.cgns")
    assert alone.returncode == 0, alone.stderr
    assert float(alone.stdout.split("boundary deviation max")[1].split()[0]) < 1e-10


def test_a_fresh_process_asks_for_the_file_when_evaluating(run_cli_process, tmp_path):
    upper, lower = naca4("2414")
    (tmp_path / "a.dat").write_text(selig(upper, lower))
    made = run_cli_process("mesh", "-g", "a.dat", *SMALL, "-m", "tfi", "--no-quality", "-o", "x.cgns")
    assert made.returncode == 0, made.stderr
    alone = run_cli_process("evaluate", "x.cgns")
    assert alone.returncode == 0 and "pass -g PATH" in alone.stderr and "n/a (no geometry)" in alone.stdout

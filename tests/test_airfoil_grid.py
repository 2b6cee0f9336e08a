"""The airfoil block set (geometries/airfoil.py): C-grid (sharp trailing edge) and O-grid (blunt)
to y+ 1, checked at every wall node against independent figures: Schlichting's first-cell height
written out here, wall normals from the section formulas' own derivatives, the TMR NACA 0012
formula; the wake cut read back from the .cgns, OpenFOAM's checkMesh on the written case."""

import math
import re

import numpy as np
import pytest

import meshgen
from meshgen.formats._cgns import read_zones
from meshgen.geometry.blocks import load_block_set, tfi_blocks
from meshgen.geometry.plugins import plugin_module
from tests.openfoam_helpers import check_mesh, needs_openfoam

RE = 6e6
TMR = (0.594689181, (0.298222773, -0.127125232, -0.357907906, 0.291984971, -0.105174606))
NACA = (0.6, (0.2969, -0.1260, -0.3516, 0.2843, -0.1015))  # 5 t a_i with t = 0.12


def _height(y_plus=1.0, reynolds=RE):
    cf = (2.0 * math.log10(reynolds) - 0.65) ** -2.3
    return y_plus / (reynolds * math.sqrt(cf / 2.0))


def _thickness(x, coefficients):
    scale, a = coefficients
    y = scale * (a[0] * np.sqrt(x) + a[1] * x + a[2] * x**2 + a[3] * x**3 + a[4] * x**4)
    slope = scale * (0.5 * a[0] / np.sqrt(np.maximum(x, 1e-300)) + a[1] + 2 * a[2] * x + 3 * a[3] * x**2 + 4 * a[4] * x**3)
    return y, slope


def _areas(X):
    """Signed quad areas (n-1, m-1) from the two diagonals."""
    d1, d2 = X[1:, 1:] - X[:-1, :-1], X[:-1, 1:] - X[1:, :-1]
    return 0.5 * (d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0])


def _ratios(X):
    """Wall-normal expansion ratios (n, m-1): each edge along eta over the one before it."""
    edges = np.linalg.norm(np.diff(X, axis=1), axis=-1)
    return edges[:, 1:] / edges[:, :-1]


@pytest.fixture(scope="module")
def c_grid():
    return meshgen.mesh("airfoil", dims=(448, 128), method="elliptic", params={"sharp": 1})


@pytest.fixture(scope="module")
def o_grid():
    return meshgen.mesh("airfoil", dims=(448, 128), method="elliptic", params={})


def _wall_angles(wall, inward, coefficients):
    """Degrees between the first grid lines (wall -> first node) and the formula's outward normal
    (-y_t', 1) on the upper surface, (-y_t', -1) on the lower, (-1, 0) at the leading edge."""
    x = wall[:, 0]
    _, slope = _thickness(x, coefficients)
    normal = np.stack([-slope, np.sign(wall[:, 1])], axis=1)
    normal[x == 0.0] = (-1.0, 0.0)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    line = inward - wall
    line /= np.linalg.norm(line, axis=1, keepdims=True)
    return np.degrees(np.arccos(np.clip((line * normal).sum(1), -1.0, 1.0)))


def test_c_grid_at_every_wall_node(c_grid):
    block_set, Xs = c_grid.geometry, c_grid.blocks
    assert block_set.cells == 448 * 128 and [X.shape[0] - 1 for X in Xs][0] == [X.shape[0] - 1 for X in Xs][2]
    section = Xs[1]
    wall, first = section[:, 0], section[:, 1]
    h = _height()
    assert np.abs(np.linalg.norm(first - wall, axis=1) / h - 1).max() < 0.02
    # The TMR formula: every wall node on y = +-y_t(x) to 1e-12 (the trailing edge at (1, 0)).
    y_t, _ = _thickness(wall[:, 0], TMR)
    assert np.abs(np.abs(wall[:, 1]) - y_t).max() < 1e-12
    # The trailing-edge node (the first and the last) is where the cut meets the wall: no normal there.
    angles = _wall_angles(wall[1:-1], first[1:-1], TMR)
    assert angles.max() < 2.0
    for X in Xs:
        assert (_areas(X) > 0).all()
        assert _ratios(X).max() <= 1.15
    # The wake's first cells (along the cut over cut-normal): at the trailing edge the wall's first
    # height, so about te_spacing / h there, and no longer for their height downstream (they were
    # the wall's 4.46e-6 chord high out to the outflow: 2.2e6 times longer than high).
    te_aspect = 0.001 / h
    for wake, te in ((Xs[0], -1), (Xs[2], 0)):
        heights = np.linalg.norm(wake[:, 1] - wake[:, 0], axis=1)
        assert heights[te] == pytest.approx(h, rel=0.02)
        downstream = heights[::-1] if te == -1 else heights
        assert np.all(np.diff(downstream) >= -1e-9 * downstream[1:]) and downstream[-1] > 1e3 * h  # growing to the outflow
        cut = np.linalg.norm(np.diff(wake[:, 0], axis=0), axis=1)
        assert (cut / np.minimum(heights[1:], heights[:-1])).max() < 1.1 * te_aspect
    assert "first cell 4.46e-06" in c_grid.notes[-1]


def test_o_grid_at_every_wall_node(o_grid):
    Xs = o_grid.blocks
    wall = np.concatenate([Xs[0][:-1, 0], Xs[1][:-1, 0], Xs[2][:-1, 0]])
    first = np.concatenate([Xs[0][:-1, 1], Xs[1][:-1, 1], Xs[2][:-1, 1]])
    assert np.abs(np.linalg.norm(first - wall, axis=1) / _height() - 1).max() < 0.02
    base = np.isclose(wall[:, 0], 1.0, atol=1e-12)
    corners = base & np.isclose(np.abs(wall[:, 1]), 0.5 * 0.00252, atol=2e-5)
    assert base.sum() == 5 and corners.sum() == 2  # 4 cells across the base (gap 0.00252 over te_spacing 0.001)
    surface = ~base
    y_t, _ = _thickness(wall[surface, 0], NACA)
    assert np.abs(np.abs(wall[surface, 1]) - y_t).max() < 1e-12
    assert _wall_angles(wall[surface], first[surface], NACA).max() < 2.0
    # The base's inner nodes (the two corners excepted): lines along +x, its outward normal.
    inner = base & ~corners
    line = first[inner] - wall[inner]
    assert np.degrees(np.arctan2(np.abs(line[:, 1]), line[:, 0])).max() < 2.0
    for X in Xs:
        assert (_areas(X) > 0).all()
        assert _ratios(X).max() <= 1.15


def _foam_aspect(X):
    """OpenFOAM's aspect ratio (primitiveMeshCheck, 2D) of each quad cell of X (n, m, 2), (n-1, m-1):
    the larger over the smaller of the sums of |x| and |y| components of its four face areas (the
    face of edge (dx, dy) has area (dy, -dx) per unit depth)."""
    along, across = np.abs(np.diff(X, axis=0)), np.abs(np.diff(X, axis=1))
    sums = along[:, :-1] + along[:, 1:] + across[:-1] + across[1:]  # (|dx| sum, |dy| sum) per cell
    return sums.max(axis=-1) / sums.min(axis=-1)


TMR_GRID = {"sharp": 1, "farfield": 1000, "le_spacing": 0.001}  # examples/naca0012's level 0 at 456 x 131


@pytest.fixture(scope="module")
def tmr_grid():
    return meshgen.mesh("airfoil", dims=(456, 131), method="elliptic", params=TMR_GRID)


@pytest.mark.parametrize("grid", ["c_grid", "o_grid", "tmr_grid"])
def test_y_plus_1_cells_stay_under_checkmesh_aspect_limit(grid, request):
    # checkMesh fails a cell above 1000; the y+ 1 C-grids' wake cut had 2.2e6 (100 chords) and 2.7e7
    # (1000 chords), and the crest cell of each surface (the wall along x) 1150 on the TMR grid.
    mesh = request.getfixturevalue(grid)
    worst = max(_foam_aspect(X).max() for X in mesh.blocks)
    assert worst < 1000
    section = mesh.blocks[1 if grid != "o_grid" else 0]
    h = np.linalg.norm(section[:, 1] - section[:, 0], axis=1)
    assert np.abs(h / _height() - 1).max() < 0.02  # the wall's first cells as asked


def test_crest_cells_of_a_thin_section_on_a_fine_level_stay_under_the_limit():
    # NACA 0006 at level 3 (h = 1.3e-6): the crest's cells as the one segment has them (0.004 chord)
    # read 2,460 in checkMesh, and 1,290 with a node on the crest (the wall too flat to tilt them):
    # they must be shortened, to read 800.
    from meshgen.geometry.airfoil_curve import chordwise_distribution, normals_at, points_at
    from meshgen.geometry.airfoils import load_section

    values = {"naca": 6, "sharp": 1, "level": 3}
    block_set = load_block_set("airfoil", values, (448, 128))  # the parametric nodes only
    section = load_section("0006", closed_te=True)
    h = _height() * (2 / 3) ** 3

    def first_layer(s):
        wall = points_at(section, s)
        return np.stack([wall, wall + h * normals_at(section, s)], axis=1)  # (n, 2, 2): one row of cells

    cells = len(block_set.coords[1][0]) - 1
    natural = chordwise_distribution(section, cells, 0.002 * (2 / 3) ** 3, 0.001 * (2 / 3) ** 3, crest=(np.inf, (0.0, 1.0)))
    assert _foam_aspect(first_layer(natural)).max() > 1000
    meshed = block_set.coords[1][0] * section.length
    assert _foam_aspect(first_layer(meshed)).max() < 1000


def test_wake_cut_stays_an_interface_and_its_cells_grow_downstream(tmp_path, tmr_grid):
    lower, section, upper = tmr_grid.blocks
    assert np.array_equal(lower[:, 0], upper[::-1, 0])  # the cut's nodes, both sides
    assert np.array_equal(lower[-1], section[0]) and np.array_equal(section[-1], upper[0])  # the trailing-edge lines
    h, te_aspect = _height(), 0.001 / _height()  # the trailing edge's cut cell over the first height
    for wake in (lower, upper):
        assert _ratios(wake).max() <= 1.15
        first = np.linalg.norm(wake[:, 1] - wake[:, 0], axis=1)
        chords = np.linalg.norm(np.diff(wake[:, 0], axis=0), axis=1)
        longer = np.maximum(np.append(chords, chords[-1]), np.insert(chords, 0, chords[0]))  # each line's longer cut cell
        # At most the larger of h and the cut cell over te_aspect; the scaling back to 1000 chords takes less than 10 %.
        assert np.all(first <= np.maximum(h, longer / te_aspect) * (1 + 1e-5))
        assert np.all(first >= 0.9 * np.maximum(h, longer / te_aspect))
    # checkMesh's aspect ratio of the wake blocks (2.7e7 when the cut's cells kept the wall's height).
    assert max(_foam_aspect(X).max() for X in (lower, upper)) < 1000
    # The same grid read back from the .cgns: the wake cut is still one 1-to-1 connection.
    path = tmp_path / "tmr.cgns"
    tmr_grid.write(path, quality=False)
    zones = {zone["name"]: zone for zone in read_zones(path)}
    assert [c["donor"] for c in zones["lower"]["connections"]].count("upper") == 1
    # A cambered 5-digit section with a closed trailing edge at y+ 1 with the defaults: under the limit too.
    cambered = meshgen.mesh("airfoil", dims=(448, 128), method="elliptic", params={"naca": 23012, "sharp": 1})
    assert max(_foam_aspect(X).max() for X in cambered.blocks) < 1000


@pytest.mark.parametrize("grid", ["c_grid", "o_grid"])
def test_far_field_spacing_has_no_jump(grid, request):
    # The section block's far-field cells are about 15 times the wake blocks' where they meet (TFI);
    # the elliptic mesh's far-field nodes grow smoothly along the whole far field.
    Xs = request.getfixturevalue(grid).blocks
    far = np.concatenate([Xs[0][:, -1], Xs[1][1:, -1], Xs[2][1:, -1]])
    spacing = np.linalg.norm(np.diff(far, axis=0), axis=1)
    ratio = spacing[1:] / spacing[:-1]
    assert max(ratio.max(), 1 / ratio.min()) < 1.25
    tfi = tfi_blocks(request.getfixturevalue(grid).geometry)
    tfi_far = np.concatenate([tfi[0][:, -1], tfi[1][1:, -1], tfi[2][1:, -1]])
    tfi_spacing = np.linalg.norm(np.diff(tfi_far, axis=0), axis=1)
    assert (tfi_spacing[1:] / tfi_spacing[:-1]).max() > 5 or grid == "o_grid"  # the jump that was there
    # On the far field's curve: as far from the wall's mid-chord as the TFI far field (D = 100 chords out).
    assert np.allclose(np.linalg.norm(far - [0.5, 0], axis=1).max(), np.linalg.norm(tfi_far - [0.5, 0], axis=1).max(), rtol=1e-3)


def test_far_field_nodes_move_smoothly_with_the_section():
    # A family's derivatives (meshgen.neural.wall_derivatives) difference the far field: its nodes
    # must move smoothly with the section's parameters. Central differences of steps 30 times
    # apart agree (nodes interpolated along the far field's dense polyline disagreed by 3e-3 of the
    # largest derivative, the polyline's corners).
    module = plugin_module("airfoil")[0]

    def far(thickness):
        values = {**module.params, "thickness": thickness, "camber": 0.023, "camber_position": 0.37}
        block_set = load_block_set("airfoil", values, (224, 128))
        return module.far_field(module._setup(module._key(values)), block_set.coords)

    fine = (far(0.121 + 1e-5) - far(0.121 - 1e-5)) / 2e-5
    coarse = (far(0.121 + 3e-4) - far(0.121 - 3e-4)) / 6e-4
    largest = np.linalg.norm(fine, axis=1).max()
    assert largest > 100  # chords per unit thickness: the far field's nodes slide along it
    assert np.linalg.norm(fine - coarse, axis=1).max() < 1e-3 * largest


@pytest.mark.parametrize("params", [{"sharp": 1}, {}])
def test_tfi_first_cells_are_the_asked_height(params):
    block_set = load_block_set("airfoil", {**params, "first_height": 1e-5, "farfield": 20}, (160, 100))
    Xs = tfi_blocks(block_set)
    for X in Xs:
        assert (_areas(X) > 0).all()
        assert np.allclose(np.linalg.norm(X[:, 1] - X[:, 0], axis=1), 1e-5, rtol=1e-6)
        # The straight lines reach the far field 20 chords out.
        assert np.allclose(np.linalg.norm(X[:, -1] - X[:, 0], axis=1), 20.0, rtol=1e-9)


def test_alpha_turns_the_whole_grid_about_the_quarter_chord():
    # First cells of 1e-3 chord: no crest cell is longer than CREST_ASPECT of them, so no crest node.
    straight = meshgen.mesh("airfoil", dims=(160, 120), method="elliptic", params={"sharp": 1, "first_height": 1e-3})
    turned = meshgen.mesh("airfoil", dims=(160, 120), method="elliptic", params={"sharp": 1, "first_height": 1e-3, "alpha": 10})
    a = math.radians(10)
    turn = np.array([[math.cos(a), math.sin(a)], [-math.sin(a), math.cos(a)]])
    for X, Y in zip(straight.blocks, turned.blocks):
        assert np.abs((X - [0.25, 0]) @ turn.T + [0.25, 0] - Y).max() < 1e-9
    assert turned.blocks[1][0, 0, 1] == pytest.approx(-0.75 * math.sin(a), abs=1e-12)  # the trailing edge went down: nose up


@pytest.mark.parametrize("alpha", [5.0, -5.0])
def test_a_turned_y_plus_1_grid_has_nodes_on_the_turned_walls_crests(alpha):
    # Turned by alpha, the wall runs along x where the turned section is lowest (alpha 5) or highest
    # (-5), not at its thickest point: checkMesh read 1,567 there with the unturned crests as nodes.
    from scipy.optimize import minimize_scalar

    mesh = meshgen.mesh("airfoil", dims=(448, 128), method="elliptic", params={"sharp": 1, "alpha": alpha})
    assert max(_foam_aspect(X).max() for X in mesh.blocks) < 1000
    a, sign = math.radians(alpha), 1.0 if alpha > 0 else -1.0  # alpha > 0: the lower surface's crest moves

    def turned_y(x):  # the turned surface's height at chord station x (TMR's formula; nose up by alpha)
        y = -sign * TMR[0] * sum(c * x ** (k + 0.5 if k == 0 else k) for k, c in enumerate(TMR[1]))
        return -math.sin(a) * (x - 0.25) + math.cos(a) * y

    crest = minimize_scalar(lambda x: sign * turned_y(x), bounds=(0.05, 0.95), method="bounded", options={"xatol": 1e-12})
    wall = mesh.blocks[1][:, 0]
    surface = wall[wall[:, 1] * sign < turned_y(0.5) * sign + 0.2]  # the turned surface of that crest
    extreme = float((sign * surface[:, 1]).min()) * sign
    assert extreme == pytest.approx(turned_y(crest.x), abs=1e-9)  # a node on it (half a cell off: ~1e-5)


def test_cgns_wake_cut_is_one_to_one(tmp_path, c_grid):
    path = tmp_path / "naca.cgns"
    c_grid.write(path, quality=False)
    zones = {zone["name"]: zone for zone in read_zones(path)}
    n = zones["lower"]["X"].shape[0]
    cut = [c for c in zones["lower"]["connections"] if c["donor"] == "upper"]
    assert len(cut) == 1
    begin, end = cut[0]["range"]
    assert begin[1] == end[1] == 1 and sorted([begin[0], end[0]]) == [1, n]  # the whole eta0 face
    # Every vertex of the range, mapped by the Transform, has the donor's coordinates.
    T = np.zeros((2, 2), dtype=int)
    for column, t in enumerate(cut[0]["transform"]):
        T[abs(t) - 1, column] = np.sign(t)
    begin_donor = cut[0]["donor_range"][0]
    i = np.arange(1, n + 1)
    index = np.stack([i, np.ones_like(i)], axis=1)
    donor = (T @ (index - begin).T).T + begin_donor
    here = zones["lower"]["X"][index[:, 0] - 1, index[:, 1] - 1]
    there = zones["upper"]["X"][donor[:, 0] - 1, donor[:, 1] - 1]
    assert np.array_equal(here, there)
    assert np.abs(here[:, 1]).max() == 0.0 and np.ptp(here[:, 0]) == pytest.approx(100.0)


@needs_openfoam
def test_openfoam_cut_is_internal_and_checkmesh_passes(tmp_path, c_grid):
    # A wall spacing whose cells stay under checkMesh's aspect threshold (1000): Mesh OK.
    mesh = meshgen.mesh(
        "airfoil", dims=(160, 48), method="elliptic", params={"sharp": 1, "farfield": 5, "wake": 5, "first_height": 0.005}
    )
    case = mesh.write(tmp_path / "case", "openfoam", quality=False) or tmp_path / "case"
    report = check_mesh(case)
    assert report["ok"], report["log"][-3000:]
    assert report["cells"] == 160 * 48
    assert report["patches"] == {
        "farfield": 160,
        "outlet": 2 * 48,
        "wall": mesh.blocks[1].shape[0] - 1,
        "frontAndBack": 2 * 160 * 48,
    }
    # y+ 1: Mesh OK too (the wake cut's cells failed the aspect ratio check, 2.2e6); the cut has no boundary faces.
    c_grid.write(tmp_path / "yplus", "openfoam", quality=False)
    report = check_mesh(tmp_path / "yplus")
    assert report["ok"], report["log"][-3000:]
    assert "***" not in report["log"]
    # checkMesh's largest aspect ratio is the one computed here from the cells.
    largest = float(re.search(r"Max aspect ratio = ([0-9.eE+-]+) OK", report["log"]).group(1))
    assert largest == pytest.approx(max(_foam_aspect(X).max() for X in c_grid.blocks), rel=1e-6)
    # No severely non-orthogonal faces (the far field's 15-fold spacing jump made 86 degrees there).
    assert float(re.search(r"Mesh non-orthogonality Max: ([0-9.eE+-]+)", report["log"]).group(1)) < 60
    assert sum(faces for name, faces in report["patches"].items() if name != "frontAndBack") == 448 + 2 * 128 + 268


@needs_openfoam
def test_openfoam_tmr_grid_passes_checkmesh(tmp_path, tmr_grid):
    # examples/naca0012's level-0 grid (1000 chords): checkMesh failed its aspect ratio (2.7e7 along the wake
    # cut; 1150 at the crests, the wake's cells grown).
    tmr_grid.write(tmp_path / "tmr", "openfoam", quality=False)
    report = check_mesh(tmp_path / "tmr")
    assert report["ok"], report["log"][-3000:]
    assert report["cells"] == 456 * 131 and "***" not in report["log"]


@pytest.mark.parametrize(
    "args, words",
    [
        (["--param", "naca=60012"], "naca=60012"),
        (["--param", "naca=12.5"], "naca=12.5 is not a NACA"),
        (["--param", "yplus=-1"], "yplus -1 is outside"),
        (["--param", "reynolds=1e20"], "reynolds 1e+20 is outside"),
        (["--param", "farfield=1"], "farfield 1: the far field must lie 2"),
        (["--param", "growth=1"], "growth 1: the growth-ratio cap must be above 1"),
        (["--param", "level=0.5"], "level 0.5: the grid level must be a whole number"),
        (["--yplus", "1", "--param", "yplus=1"], "--yplus and --param yplus= both given"),
        (["--dims", "448", "40"], "the smallest M that works is 114"),
        (["--param", "sharp=1", "--dims", "60", "128"], "the smallest N that works is"),
    ],
)
def test_bad_input_is_one_line(run_cli, tmp_path, args, words):
    dims = [] if "--dims" in args else ["--dims", "448", "128"]
    result = run_cli("mesh", "-g", "airfoil", "--method", "elliptic", *dims, *args, "-o", "x.cgns")
    assert result.returncode == 2, result.stderr
    assert words in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert not list(tmp_path.glob("x.*"))


def test_level_scales_the_cells_and_the_first_cell():
    # DPW's family rule: 1.5x the cells per direction, 2/3 of every designed length (first cell included).
    base = load_block_set("airfoil", {"sharp": 1, "farfield": 20}, (160, 110))
    finer = load_block_set("airfoil", {"sharp": 1, "farfield": 20, "level": 1}, (160, 110))
    assert base.cells == 160 * 110 and finer.cells == 240 * 165
    for X in tfi_blocks(finer):
        assert np.allclose(np.linalg.norm(X[:, 1] - X[:, 0], axis=1), _height() * 2 / 3, rtol=1e-6)
    # The chordwise spacing at the trailing edge (te_spacing 0.001) scales too.
    te = (
        np.linalg.norm(finer.coords[1][0][1] - finer.coords[1][0][0])
        * np.linalg.norm(np.diff(tfi_blocks(finer)[1][:, 0], axis=0), axis=1).sum()
    )
    assert te == pytest.approx(0.001 * 2 / 3, rel=0.05)
    mesh = meshgen.mesh("airfoil", dims=(160, 110), method="elliptic", params={"sharp": 1, "farfield": 20, "level": 1})
    section = mesh.blocks[1]
    assert np.abs(np.linalg.norm(section[:, 1] - section[:, 0], axis=1) / (_height() * 2 / 3) - 1).max() < 0.02
    assert sum(X.shape[0] - 1 for X in mesh.blocks) == 240 and mesh.blocks[0].shape[1] == 166


def test_yplus_and_reynolds_options(run_cli, tmp_path):
    result = run_cli(
        "mesh", "-g", "airfoil", "--yplus", "0.5", "--reynolds", "1e6", "--param", "sharp=1",
        "--dims", "160", "120", "-m", "tfi", "--no-quality", "-o", "x.cgns",
    )  # fmt: skip
    assert result.returncode == 0, result.stderr
    assert f"first cell {_height(0.5, 1e6):.3g} chord (y+ 0.5 at Re 1e+06" in result.stdout
    refused = run_cli("mesh", "-g", "pipe", "--yplus", "1", "--dims", "8", "8", "8", "-m", "tfi", "-o", "y.cgns")
    assert refused.returncode == 2 and "geometry 'pipe' has no parameter 'yplus'" in refused.stderr
    assert len(refused.stderr.strip().splitlines()) == 1 and not list(tmp_path.glob("y.*"))

"""Geometry plugins: every discoverable geometry against the contract of design notes §3
(boundary reproduced by TFI, continuity across the cube's edges, positive orientation), the
built-ins' surfaces against closed-form volumes and areas, and plugin discovery from all three
sources (built-in name, ``.py`` file, entry point)."""

import itertools
import json
import sys
import textwrap

import numpy as np
import pytest
from click.testing import CliRunner
from mesh_checks import corner_jacobians

from meshgen.cli import cli
from meshgen.errors import GeometryError
from meshgen.geometry.plugins import ENTRY_POINT_GROUP, _builtin_files, available_names, load_geometry
from meshgen.methods.tfi import parametric_grid, tfi

BLOCK_SETS = [
    "airfoil",
    "dfg-cylinder",
    "dfg-cylinder-3d",
    "pipe",
]  # multi-block plugins: tests/test_blocks.py, tests/test_airfoil_grid.py
NAMES = [name for name in available_names() if name not in BLOCK_SETS]
BUILTINS = [
    "airfoil",
    "bump",
    "canal",
    "dfg-cylinder",
    "dfg-cylinder-3d",
    "flower",
    "pipe",
    "semicylinder",
    "semidisk",
    "topcurve",
]


def size_of(X):
    """Largest extent of a node array: the scale for round-off tolerances."""
    points = X.reshape(-1, X.shape[-1])
    return float(np.ptp(points, axis=0).max())


def face_points(dim, axis, side, n=9):
    """Parametric points on the face ``t[axis] = side`` of the unit cube, shape (n**(dim-1), dim)."""
    t = np.linspace(0.0, 1.0, n)
    grid = np.stack(np.meshgrid(*([t] * (dim - 1)), indexing="ij"), axis=-1).reshape(-1, dim - 1)
    return np.insert(grid, axis, side, axis=1)


def edge_jumps(geometry, step):
    """Distance between the image of points on the cube's edges (3D; corners in 2D) and the image
    of the points ``step`` into each adjacent face; shape (M,)."""
    dim = geometry.dim
    free = np.linspace(0.05, 0.95, 7) if dim == 3 else np.zeros(1)
    jumps = []
    for a, b in itertools.combinations(range(dim), 2):
        for side_a, side_b in itertools.product((0.0, 1.0), repeat=2):
            edge = np.empty((len(free), dim))
            edge[:, [d for d in range(dim) if d not in (a, b)]] = free[:, None]
            edge[:, a], edge[:, b] = side_a, side_b
            image = geometry.boundary(edge)
            for axis, side in ((b, side_b), (a, side_a)):
                inside = edge.copy()  # stays on the other face, leaves the edge
                inside[:, axis] += step if side == 0.0 else -step
                jumps.append(np.linalg.norm(geometry.boundary(inside) - image, axis=1))
    return np.concatenate(jumps)


def test_every_builtin_is_discovered():
    assert set(BUILTINS) <= set(NAMES) | set(BLOCK_SETS)
    assert sorted(_builtin_files()) == BUILTINS


# ---------------------------------------------------------------------------------------------
# the contract, for every discoverable geometry


@pytest.mark.parametrize("name", NAMES)
def test_tfi_reproduces_the_boundary_on_every_face(name):
    geometry = load_geometry(name)
    dims = (7, 8, 9)[: geometry.dim]  # unequal, so a swapped axis cannot pass
    X = tfi(geometry, dims)
    assert X.shape == tuple(n + 1 for n in dims) + (geometry.dim,)
    grid = np.stack(np.meshgrid(*parametric_grid(dims), indexing="ij"), axis=-1)
    tolerance = 1e-12 * size_of(X)
    for axis, index in itertools.product(range(geometry.dim), (0, -1)):
        face = np.take(grid, index, axis=axis).reshape(-1, geometry.dim)
        expected = geometry.boundary(face)
        np.testing.assert_allclose(np.take(X, index, axis=axis).reshape(-1, geometry.dim), expected, atol=tolerance)


@pytest.mark.parametrize("name", NAMES)
def test_boundary_map_is_continuous_across_edges(name):
    # Loading runs check_boundary; independently, the gap between an edge's image and its
    # neighbours' must shrink with the step (a jump would not).
    geometry = load_geometry(name)
    scale = geometry.characteristic_length
    coarse, fine = edge_jumps(geometry, 1e-4), edge_jumps(geometry, 1e-7)
    assert fine.max() < 1e-5 * scale
    assert np.all(fine <= coarse / 100 + 1e-12 * scale)


@pytest.mark.parametrize("name", NAMES)
def test_tfi_cells_are_not_inverted(name):
    geometry = load_geometry(name)
    dims = (30, 30, 30) if name == "semicylinder" else (12,) * geometry.dim
    jacobians = corner_jacobians(tfi(geometry, dims))
    assert jacobians.min() > 0, f"{(jacobians <= 0).sum()} inverted cell corners"


@pytest.mark.parametrize("name", NAMES)
def test_boundary_is_vectorised_and_deterministic(name):
    # The map must treat points independently: a batch gives the same images as the points one by one.
    geometry = load_geometry(name)
    rng = np.random.default_rng(1)
    points = rng.random((40, geometry.dim))
    faces = rng.integers(0, geometry.dim, 40)
    points[np.arange(40), faces] = rng.integers(0, 2, 40)
    batch = geometry.boundary(points)
    single = np.concatenate([geometry.boundary(p[None]) for p in points])
    np.testing.assert_allclose(batch, single, rtol=0, atol=1e-14 * size_of(batch))


# ---------------------------------------------------------------------------------------------
# built-in shapes against their closed forms


def test_semicylinder_is_the_reference_shape_of_design_section_3():
    geometry = load_geometry("semicylinder")
    t = np.linspace(0.0, 1.0, 11)
    zeta = np.full_like(t, 0.3)

    def at(xi, eta):
        return geometry.boundary(np.column_stack([xi, eta, zeta]))

    np.testing.assert_allclose(at(t, 0 * t), np.column_stack([2 * t - 1, 0 * t, 2 * zeta]), atol=1e-14)
    for xi, eta, angles in [
        (0 * t, t, np.pi - t * np.pi / 4),  # xi = 0: pi -> 3pi/4
        (t, 0 * t + 1, 3 * np.pi / 4 - t * np.pi / 2),  # eta = 1: 3pi/4 -> pi/4
        (0 * t + 1, t, t * np.pi / 4),  # xi = 1: pi/4 (eta = 1) -> 0 (eta = 0)
    ]:
        np.testing.assert_allclose(at(xi, eta), np.column_stack([np.cos(angles), np.sin(angles), 2 * zeta]), atol=1e-14)
    # Caps: the 2D Coons patch of the section's edges, here at the cap's centre.
    a, b = np.array([-1.0, 0.0]), np.array([1.0, 0.0])
    left, right = np.array([np.cos(7 * np.pi / 8), np.sin(7 * np.pi / 8)]), np.array([np.cos(np.pi / 8), np.sin(np.pi / 8)])
    top, bottom = np.array([0.0, 1.0]), np.array([0.0, 0.0])
    corners = a, b, np.array([np.cos(np.pi / 4), np.sin(np.pi / 4)]), np.array([np.cos(3 * np.pi / 4), np.sin(3 * np.pi / 4)])
    coons = (left + right + top + bottom) / 2 - sum(corners) / 4
    np.testing.assert_allclose(geometry.boundary(np.array([[0.5, 0.5, 1.0]]))[0], [*coons, 2.0], atol=1e-14)


def semicylinder_volume(radius, length):
    return np.pi * radius**2 * length / 2


def topcurve_volume(length, width, height, amplitude):
    # integral of H + A sin(pi x/Lx) sin(pi y/Ly) over the rectangle: Lx Ly H + A (2 Lx / pi)(2 Ly / pi)
    return length * width * height + amplitude * (2 * length / np.pi) * (2 * width / np.pi)


def flower_volume(radius, amplitude, length, twist):
    # area (1/2) int_0^2pi r(t)^2 dt with r = R(1 + a cos 5t); a twist moves each section rigidly
    return np.pi * radius**2 * (1 + amplitude**2 / 2) * length


def canal_volume(tube_radius, bend_radius):
    return np.pi * tube_radius**2 * np.pi * bend_radius  # Pappus: section area times centroid path


def semidisk_area(radius):
    return np.pi * radius**2 / 2


def bump_area(length, height, bump_height, bump_width, bump_center):
    return length * height - bump_height * bump_width / 2  # int of h cos^2 over its width w is h w / 2


CLOSED_FORMS = {
    "semicylinder": semicylinder_volume,
    "topcurve": topcurve_volume,
    "flower": flower_volume,
    "canal": canal_volume,
    "semidisk": semidisk_area,
    "bump": bump_area,
}

SHAPES = [
    ("semicylinder", {}),
    ("semicylinder", {"radius": 2.0, "length": 0.5}),
    ("topcurve", {}),
    ("topcurve", {"length": 1.0, "width": 3.0, "height": 0.5, "amplitude": -0.3}),
    ("flower", {}),
    ("flower", {"radius": 0.5, "amplitude": 0.3, "length": 3.0, "twist": 250.0}),
    ("canal", {}),
    ("canal", {"tube_radius": 0.2, "bend_radius": 0.5}),
    ("semidisk", {}),
    ("semidisk", {"radius": 3.0}),
    ("bump", {}),
    ("bump", {"length": 2.0, "height": 0.5, "bump_height": -0.2, "bump_width": 0.8, "bump_center": 0.4}),
]


def test_every_builtin_has_a_closed_form_and_a_non_default_case():
    single_block = [name for name in BUILTINS if name not in BLOCK_SETS]  # block sets: no surface to show yet
    assert sorted(CLOSED_FORMS) == single_block
    assert {name for name, params in SHAPES if params} == set(single_block)


@pytest.mark.parametrize("name, params", SHAPES, ids=[f"{n}-{'default' if not p else 'custom'}" for n, p in SHAPES])
def test_geometries_show_writes_the_shape(name, params, tmp_path):
    import trimesh

    output = tmp_path / f"{name}.stl"
    args = ["geometries", "show", name, "-o", str(output)]
    for key, value in params.items():
        args += ["--param", f"{key}={value}"]
    result = CliRunner().invoke(cli, args)
    assert result.exit_code == 0, result.output
    geometry = load_geometry(name, params)
    expected = CLOSED_FORMS[name](**geometry.values)
    surface = trimesh.load(output)  # read back independently; trimesh merges the STL's vertices
    if geometry.dim == 3:
        assert surface.is_watertight
        assert surface.volume > 0  # outward normals
        measured = surface.volume
    else:
        np.testing.assert_allclose(surface.vertices[:, 2], 0.0)
        measured = surface.area
    # 64 samples per face edge: chords of curved edges and faces, an O(h^2) error.
    assert measured == pytest.approx(expected, rel=2e-3)


@pytest.mark.parametrize(
    "name, params, word",
    [
        ("semicylinder", {"radius": -1.0}, "positive"),
        ("semidisk", {"radius": 0.0}, "positive"),
        ("topcurve", {"amplitude": -1.5}, "height + amplitude"),
        ("topcurve", {"width": 0.0}, "positive"),
        ("flower", {"amplitude": 0.5}, "amplitude"),
        ("flower", {"length": -2.0}, "length"),
        ("canal", {"tube_radius": 2.0}, "tube_radius < bend_radius"),
        ("bump", {"bump_height": 1.0}, "bump_height < height"),
        ("bump", {"bump_center": 0.2}, "inside the channel"),
    ],
)
def test_parameters_that_would_invert_or_tear_the_shape_are_rejected(name, params, word):
    with pytest.raises(GeometryError, match=f"geometry '{name}'") as error:
        load_geometry(name, params)
    assert word in str(error.value)


def test_parameters_are_bound_by_name_and_unknown_ones_rejected():
    unit = load_geometry("semicylinder")
    scaled = load_geometry("semicylinder", {"radius": 2.0, "length": 4.0})
    points = face_points(3, 0, 1.0)
    np.testing.assert_allclose(scaled.boundary(points), 2 * unit.boundary(points), atol=1e-14)
    assert unit.with_params(radius=2.0, length=4.0).values == scaled.values
    with pytest.raises(GeometryError, match="no parameter 'radus'.*did you mean 'radius'"):
        load_geometry("semicylinder", {"radus": 2.0})


# ---------------------------------------------------------------------------------------------
# plugins: the three sources, and contract violations

SKEWED_BOX = '''
"""A sheared box: affine, so TFI must reproduce the map everywhere."""
import numpy as np

name = "{name}"
dim = 3
description = "Sheared box"
params = {{"shear": 0.5, "height": 2.0}}


def boundary(points, shear, height):
    x, y, z = points.T
    return np.column_stack([x + shear * z, y, height * z])
'''


def check_skewed_box(geometry, shear=0.5, height=2.0):
    """TFI of the sheared box at scattered, uneven node positions equals the affine map itself."""
    coords = [np.sort(c) for c in np.random.default_rng(2).random((3, 6))]
    X = tfi(geometry, None, coords)
    grid = np.stack(np.meshgrid(*coords, indexing="ij"), axis=-1)
    expected = grid @ np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [shear, 0.0, height]])
    np.testing.assert_allclose(X, expected, atol=1e-13)


def test_builtin_plugin_loads_by_name():
    geometry = load_geometry("semidisk")
    assert geometry.name == "semidisk" and geometry.dim == 2
    assert geometry.source == str(_builtin_files()["semidisk"])


def test_plugin_loads_from_a_file(tmp_path):
    path = tmp_path / "skewed.py"
    path.write_text(SKEWED_BOX.format(name="skewedfile"))
    geometry = load_geometry(str(path), {"shear": 0.25})
    assert (geometry.name, geometry.source) == ("skewedfile", str(path))
    check_skewed_box(geometry, shear=0.25)


def test_plugin_loads_from_an_entry_point(tmp_path, monkeypatch):
    module = f"meshgen_test_plugin_{abs(hash(str(tmp_path))):x}"
    (tmp_path / f"{module}.py").write_text(SKEWED_BOX.format(name="skewedentry"))
    dist_info = tmp_path / "meshgen_test_plugin-1.0.dist-info"
    dist_info.mkdir()
    (dist_info / "METADATA").write_text("Metadata-Version: 2.1\nName: meshgen-test-plugin\nVersion: 1.0\n")
    (dist_info / "entry_points.txt").write_text(
        f"[{ENTRY_POINT_GROUP}]\nskewedentry = {module}\nbrokenentry = {module}_missing\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    try:
        names = available_names()
        assert {"skewedentry", "brokenentry"} <= set(names)
        assert module not in sys.modules  # discovery imports nothing
        geometry = load_geometry("skewedentry")
        assert geometry.source == f"entry point {module}"
        check_skewed_box(geometry)
        # a broken installed plugin is reported by name but does not stop the listing
        listed = CliRunner().invoke(cli, ["geometries", "--json"])
        assert listed.exit_code == 0
        assert "skewedentry" in [item["name"] for item in json.loads(listed.stdout)]
        assert "brokenentry" in listed.stderr and "ModuleNotFoundError" in listed.stderr
        with pytest.raises(GeometryError, match=r"geometry plugin 'brokenentry' .* failed to load: ModuleNotFoundError"):
            load_geometry("brokenentry")
    finally:
        sys.modules.pop(module, None)


def test_discontinuous_plugin_is_rejected_with_its_name(tmp_path):
    path = tmp_path / "torn.py"
    path.write_text(
        textwrap.dedent(
            """
            import numpy as np
            name = "tornbox"
            dim = 3
            description = "A box whose face xi = 1 is lifted off its neighbours"
            def boundary(points):
                lifted = np.isclose(points[:, 0], 1.0) & (points[:, 1] > 0) & (points[:, 1] < 1) & (points[:, 2] > 0) & (points[:, 2] < 1)
                return points + 0.05 * lifted[:, None]
            """
        )
    )
    with pytest.raises(GeometryError, match=r"geometry 'tornbox' \(.*torn\.py\): boundary is not continuous"):
        load_geometry(str(path))
    # and the independent edge test above would have caught it too
    unchecked = load_geometry(str(path), check=False)
    assert edge_jumps(unchecked, 1e-7).max() > 0.04


def test_geometries_show_of_a_block_set_is_its_closed_boundary(tmp_path):
    """A multi-block geometry is shown as its blocks' patch faces (interfaces left out): the pipe's
    surface is closed, every vertex lies on the cylinder or an end disc, and its volume is the
    section polygon of its wall vertices times the length (the wall's quads are planar
    rectangles), computed here from the vertices alone."""
    import meshio
    import trimesh

    n, radius, length = 6, 0.7, 3.0
    args = ["--param", f"radius={radius}", "--param", f"length={length}", "--resolution", str(n)]
    result = CliRunner().invoke(cli, ["geometries", "show", "pipe", "-o", str(tmp_path / "p.stl"), *args])
    assert result.exit_code == 0, result.output
    assert "watertight" in result.output
    surface = trimesh.load(tmp_path / "p.stl", process=True)
    assert surface.is_watertight
    v = np.asarray(surface.vertices)
    r = np.hypot(v[:, 0], v[:, 1])
    on_wall, on_end = np.isclose(r, radius, atol=1e-7), np.isclose(v[:, 2], 0, atol=1e-7) | np.isclose(v[:, 2], length, atol=1e-7)
    assert np.all(on_wall | on_end) and np.all(r <= radius + 1e-7)
    ring = v[on_wall & np.isclose(v[:, 2], 0, atol=1e-7)]
    assert len(ring) == 4 * n  # four wall blocks, n cells each around the circumference
    ring = ring[np.argsort(np.arctan2(ring[:, 1], ring[:, 0]))]
    x, y = ring[:, 0], ring[:, 1]
    section = 0.5 * abs(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))
    assert surface.volume == pytest.approx(section * length, rel=1e-6)  # STL stores float32
    # .vtu: each triangle's block, face and patch; the inlet is every block's zeta0 face.
    result = CliRunner().invoke(cli, ["geometries", "show", "pipe", "-o", str(tmp_path / "p.vtu"), *args])
    assert result.exit_code == 0, result.output
    mesh = meshio.read(tmp_path / "p.vtu")
    block, face = mesh.cell_data["block"][0], mesh.cell_data["cube_face"][0]
    centroid_z = mesh.points[mesh.cells[0].data][:, :, 2].mean(axis=1)
    inlet = face == 4  # zeta0
    assert sorted(set(block[inlet])) == [0, 1, 2, 3, 4] and np.allclose(centroid_z[inlet], 0)
    assert np.count_nonzero(inlet) == 5 * 2 * n * n


def test_geometries_show_of_a_2d_block_set_fills_the_domain(tmp_path):
    result = CliRunner().invoke(cli, ["geometries", "show", "dfg-cylinder", "-o", str(tmp_path / "d.ply"), "--resolution", "24"])
    assert result.exit_code == 0, result.output
    import trimesh

    channel = 2.2 * 0.41 - np.pi * 0.05**2  # the DFG benchmark's channel (2.2 x 0.41) less its cylinder (d = 0.1)

    assert trimesh.load(tmp_path / "d.ply").area == pytest.approx(channel, rel=1e-4)

"""Wall clustering: growth ratios and first-cell heights, in parametric and physical space."""

import numpy as np
import pytest

from meshgen.errors import MeshgenError
from meshgen.geometry.plugins import load_geometry
from meshgen.methods.clustering import clustered_coordinates, node_coordinates, parse_cluster
from meshgen.methods.tfi import tfi


@pytest.mark.parametrize("side", ["min", "max", "both"])
def test_growth_ratio_between_neighbouring_cells(side):
    t = clustered_coordinates(20, parse_cluster(f"zeta:{side}:1.2"))
    widths = np.diff(t)
    assert t[0] == 0.0 and t[-1] == 1.0 and np.all(widths > 0)
    ratios = widths[1:] / widths[:-1]
    away_from_wall = {"min": ratios[:], "max": 1 / ratios[:], "both": ratios[:9]}[side]
    np.testing.assert_allclose(away_from_wall, 1.2, rtol=1e-12)
    if side == "both":
        np.testing.assert_allclose(widths, widths[::-1], rtol=1e-12)


@pytest.mark.parametrize("side", ["0", "1", "both"])
def test_first_cell_height_is_met(side):
    t = clustered_coordinates(30, parse_cluster(f"eta:{side}:h=0.004"))
    wall_cells = {"0": [t[1] - t[0]], "1": [t[-1] - t[-2]], "both": [t[1] - t[0], t[-1] - t[-2]]}[side]
    np.testing.assert_allclose(wall_cells, 0.004, rtol=1e-9)


def test_physical_first_cell_ratio_on_the_semicylinder_axis():
    # z = length * zeta on the semicylinder, so physical cell heights along z follow the parametric ones.
    geometry = load_geometry("semicylinder")
    coords = node_coordinates((4, 4, 12), ["zeta:0:1.15"])
    X = tfi(geometry, None, coords)
    heights = np.diff(X[2, 2, :, 2])
    np.testing.assert_allclose(heights[1:] / heights[:-1], 1.15, rtol=1e-10)


@pytest.mark.parametrize(
    "spec", ["zeta", "zeta:both", "w:both:1.1", "zeta:top:1.1", "zeta:both:0.5", "zeta:both:abc", "zeta:0:h=2", "zeta:0:h=0.9"]
)
def test_malformed_specs_are_rejected(spec):
    with pytest.raises(MeshgenError):
        node_coordinates((10, 10, 10), [spec])


def test_axis_missing_in_2d_and_duplicate_axis_are_rejected():
    with pytest.raises(MeshgenError, match="does not exist"):
        node_coordinates((10, 10), ["zeta:0:1.1"])
    with pytest.raises(MeshgenError, match="twice"):
        node_coordinates((10, 10, 10), ["xi:0:1.1", "i:1:1.2"])


def test_cli_writes_a_clustered_mesh(run_cli, tmp_path):
    import meshio

    result = run_cli(
        "mesh", "-m", "tfi", "-g", "semicylinder", "--dims", "3", "3", "8", "--cluster", "zeta:both:1.3", "-o", "c.vtu"
    )
    assert result.returncode == 0, result.stderr
    points = meshio.read(tmp_path / "c.vtu").points.reshape(4, 4, 9, 3)
    expected = 2.0 * clustered_coordinates(8, parse_cluster("zeta:both:1.3"))
    np.testing.assert_allclose(points[1, 1, :, 2], expected, atol=1e-12)
    bad = run_cli("mesh", "--dims", "3", "3", "3", "--cluster", "zeta:both", "-o", "d.vtu")
    assert bad.returncode == 2 and "malformed --cluster" in bad.stderr and not (tmp_path / "d.vtu").exists()

"""A third --dims number extrudes the airfoil into a straight wing section (geometries/airfoil.py
``extruded``, meshgen.geometry.extrusion ``extruded_plugin``): the 3D nodes are the 2D mesh's
(written by its own run) at z = span k / K, no cell inverted (2D signed areas computed here times
the layer's height), the wake cut still a 1-to-1 CGNS connection, checkMesh passes on the
OpenFOAM case, and the listing says what the third number counts."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from meshgen.formats._cgns import read_zones
from tests.openfoam_helpers import check_mesh, needs_openfoam

REPO = Path(__file__).resolve().parents[1]
SMALL = ["--param", "sharp=1", "--param", "farfield=5", "--param", "wake=5", "--param", "first_height=0.005", "-m", "elliptic"]


def _areas(X):
    """Signed quad areas (n-1, m-1) of a 2D node array from its two diagonals."""
    d1, d2 = X[1:, 1:] - X[:-1, :-1], X[:-1, 1:] - X[1:, :-1]
    return 0.5 * (d1[..., 0] * d2[..., 1] - d1[..., 1] * d2[..., 0])


@pytest.fixture(scope="module")
def meshes(tmp_path_factory):
    from click.testing import CliRunner

    from meshgen.cli import cli

    folder = tmp_path_factory.mktemp("wing")
    for name, dims, extra in (("flat", ["160", "48"], []), ("wing", ["160", "48", "3"], ["--param", "span=2"])):
        result = CliRunner().invoke(
            cli, ["mesh", "-g", "airfoil", *SMALL, *extra, "--dims", *dims, "-o", str(folder / f"{name}.cgns")]
        )
        assert result.exit_code == 0, result.output
    return (
        {zone["name"]: zone for zone in read_zones(folder / "flat.cgns")},
        {zone["name"]: zone for zone in read_zones(folder / "wing.cgns")},
        result.output,
    )


@pytest.mark.slow
def test_the_wing_is_the_2d_mesh_extruded_along_the_span(meshes):
    flat, wing, output = meshes
    assert "inverted cells: 0 (0.00%)" in output and "3 blocks, 23040 cells" in output
    for name in ("lower", "section", "upper"):
        X2, X3 = flat[name]["X"], wing[name]["X"]
        assert X3.shape == (*X2.shape[:2], 4, 3)
        for k in range(4):
            np.testing.assert_array_equal(X3[:, :, k, :2], X2)
            assert np.all(X3[:, :, k, 2] == pytest.approx(2.0 * k / 3, abs=1e-15))
        assert _areas(X2).min() > 0  # every hex: a positive quad times a positive height


@pytest.mark.slow
def test_the_wake_cut_is_still_one_to_one(meshes):
    _, wing, _ = meshes
    cut = [c for c in wing["lower"]["connections"] if c["donor"] == "upper"]
    assert len(cut) == 1
    begin, end = np.asarray(cut[0]["range"])
    T = np.zeros((3, 3), dtype=int)
    for column, t in enumerate(cut[0]["transform"]):
        T[abs(t) - 1, column] = np.sign(t)
    lo, hi = np.minimum(begin, end), np.maximum(begin, end)
    assert lo[1] == hi[1] == 1 and hi[0] == wing["lower"]["X"].shape[0] and hi[2] == 4  # the whole eta0 face
    index = np.stack(np.meshgrid(*[np.arange(a, b + 1) for a, b in zip(lo, hi)], indexing="ij"), -1).reshape(-1, 3)
    donor = (T @ (index - begin).T).T + np.asarray(cut[0]["donor_range"][0])
    here = wing["lower"]["X"][tuple((index - 1).T)]
    there = wing["upper"]["X"][tuple((donor - 1).T)]
    assert np.array_equal(here, there) and np.abs(here[:, 1]).max() == 0.0


@pytest.mark.slow
@needs_openfoam
def test_checkmesh_passes_on_the_wing(run_cli, tmp_path):
    result = run_cli("mesh", "-g", "airfoil", *SMALL, "--dims", "160", "48", "3", "-o", "case", "--format", "openfoam")
    assert result.returncode == 0, result.stderr
    report = check_mesh(tmp_path / "case")
    assert report["ok"], report["log"][-3000:]
    assert report["cells"] == 160 * 48 * 3
    wall = report["patches"]["wall"]
    assert report["patches"] == {"farfield": 160 * 3, "outlet": 2 * 48 * 3, "front": 160 * 48, "back": 160 * 48, "wall": wall}
    boundary = (tmp_path / "case" / "constant" / "polyMesh" / "boundary").read_text()
    for name in ("front", "back"):
        assert boundary.split(name, 1)[1].split("}", 1)[0].split("type", 1)[1].split(";")[0].strip() == "symmetry"


def test_a_coordinate_file_extrudes_too_and_span_is_checked(run_cli, tmp_path):
    x = 0.5 * (1 - np.cos(np.linspace(0, np.pi, 41)))
    y = 0.6 * (0.2969 * np.sqrt(x) - 0.1260 * x - 0.3516 * x**2 + 0.2843 * x**3 - 0.1036 * x**4)
    rows = np.concatenate([np.stack([x, y], 1)[::-1], np.stack([x, -y], 1)[1:]])
    (tmp_path / "s.dat").write_text("closed 0012\n" + "\n".join(f"{a:.12f} {b:.12f}" for a, b in rows) + "\n")
    small = [a for a in SMALL if a != "sharp=1"]
    small.remove("--param")
    result = run_cli(
        "mesh", "-g", "s.dat", *small, "--param", "span=0.5", "--dims", "128", "48", "2", "-m", "tfi", "-o", "s.cgns"
    )
    assert result.returncode == 0, result.stderr
    zones = {zone["name"]: zone["X"] for zone in read_zones(tmp_path / "s.cgns")}
    assert zones["section"].shape[2] == 3 and zones["section"][..., 2].max() == pytest.approx(0.5)
    for args, words in (
        (["--param", "span=0", "--dims", "128", "48", "2"], "span 0"),
        (["--param", "span=1", "--dims", "128", "48"], "span"),
    ):
        bad = run_cli("mesh", "-g", "s.dat", *small, *args, "-o", "b.cgns")
        assert bad.returncode == 2 and words in bad.stderr and len(bad.stderr.strip().splitlines()) == 1, bad.stderr
    assert not list(tmp_path.glob("b*"))


def test_the_listing_says_what_the_third_number_counts(run_cli):
    result = run_cli("geometries", "--json")
    entry = next(item for item in json.loads(result.stdout) if item["name"] == "airfoil")
    assert entry["dims"].startswith("N M [K]") and "third number K" in entry["dims"] and "span" in entry["dims"]


@pytest.mark.slow
@needs_openfoam
@pytest.mark.skipif(shutil.which("simpleFoam") is None, reason="simpleFoam not installed")
def test_the_three_commands_mesh_check_and_solve(run_cli, tmp_path):
    # docs/airfoil.md's "Mesh, check, solve": as written there, with 224 cells along the wall and 20 iterations.
    made = run_cli("mesh", "-g", "airfoil", "--param", "sharp=1", "--yplus", "1", "--reynolds", "6e6", "--dims", "224", "128",
                   "--method", "elliptic", "--format", "openfoam", "-o", "naca")  # fmt: skip
    assert made.returncode == 0, made.stderr
    report = check_mesh(tmp_path / "naca")
    assert report["ok"] and report["cells"] == 224 * 128 and "***" not in report["log"]  # y+ 1 and Mesh OK
    script = REPO / "examples" / "naca0012" / "run_naca0012.py"
    args = ["--case", "naca", "--no-mesh", "--alpha", "10", "--max-iterations", "20", "--json", "out.json"]
    solved = subprocess.run([sys.executable, str(script), *args], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert solved.returncode == 0, solved.stdout[-2000:] + solved.stderr[-2000:]
    result = json.loads((tmp_path / "out.json").read_text())
    assert result["cells"] == 224 * 128 and result["iterations"] == 20
    assert 0.5 < result["CL"] < 1.5 and result["yplus"]["max"] < 5  # lift at 10 degrees, the wall at y+ about 1


def test_geometries_show_builds_the_airfoil(run_cli, tmp_path):
    # 4 cells per --dims number cannot reach the far field: the plugin's shown_dims are used.
    result = run_cli("geometries", "show", "airfoil", "-o", "a.stl")
    assert result.returncode == 0, result.stderr
    area = float(result.stdout.split("area ")[1])
    # The far field: 100 to 100.5 chords from the mid-chord (radial from it, 100 from the wall), sampled as a polygon.
    assert 0.98 * np.pi * 100**2 < area < np.pi * 100.5**2

"""``meshgen evaluate`` end to end: our own files and foreign ones, reports, gates, bad input."""

import json
import re

import numpy as np
import pytest

meshio = pytest.importorskip("meshio")

from meshgen.geometry.grid import cell_connectivity, flat_points  # noqa: E402
from meshgen.geometry.plugins import load_geometry  # noqa: E402
from meshgen.methods.tfi import tfi  # noqa: E402
from meshgen.quality import METRICS, STATS, cell_metrics  # noqa: E402


def sheared_box(dims, shear):
    axes = [np.arange(n + 1, dtype=float) for n in dims]
    X = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1)
    X[..., 0] += shear * X[..., 1]
    return X


def write_gmsh(path, X, extra=True):
    """A foreign file: hexahedra (or quads) written by meshio in gmsh's format, with line and
    triangle cells beside them as gmsh files have, and no meshgen metadata."""
    cells = [("hexahedron" if X.ndim == 4 else "quad", cell_connectivity(X.shape[:-1]))]
    if extra:
        cells += [("line", np.array([[0, 1], [1, 2], [2, 3]])), ("triangle", np.array([[0, 1, 2], [1, 2, 3]]))]
    meshio.write(path, meshio.Mesh(flat_points(X), cells), file_format="gmsh22", binary=False)
    return path


def evaluate_json(run_cli, tmp_path, *args):
    out = tmp_path / "report.json"
    result = run_cli("evaluate", *args, "--json", out)
    assert result.returncode == 0, result.stderr
    return json.loads(out.read_text()), result


def test_evaluate_our_own_mesh_with_recorded_geometry(run_cli, tmp_path, semicylinder):
    made = run_cli("mesh", "-m", "tfi", "-g", "semicylinder", "--dims", "10", "8", "6", "-o", "m.vtu")
    assert made.returncode == 0, made.stderr
    assert "inverted cells: 0" in made.stdout and "boundary deviation" in made.stdout
    sidecar = json.loads((tmp_path / "m.vtu.quality.json").read_text())
    assert sidecar["geometry"] == "semicylinder" and sidecar["method"] == "tfi"

    report, result = evaluate_json(run_cli, tmp_path, "m.vtu")
    assert {"cells", "dim", "metrics", "inverted", "valid", "boundary_deviation"} <= set(report)
    assert report["cells"] == 480 and report["dim"] == 3 and report["structured"]
    assert set(report["metrics"]) == set(METRICS)
    assert all(set(report["metrics"][m]) == set(STATS) for m in METRICS)
    assert set(report["inverted"]) >= {"count", "fraction"} and report["valid"] is True
    # The geometry comes from the file: the TFI boundary is exact.
    assert report["boundary_deviation"]["max_rel"] < 1e-12
    # The figures are those of the node array, computed here independently of the file.
    metrics = cell_metrics(tfi(semicylinder, (10, 8, 6)))
    for name in METRICS:
        assert report["metrics"][name]["mean"] == pytest.approx(metrics[name].mean(), rel=1e-12)
        assert report["metrics"][name]["min"] == pytest.approx(metrics[name].min(), rel=1e-12)
        assert report["metrics"][name]["p01"] == pytest.approx(np.percentile(metrics[name], 1), rel=1e-12)
    # and the per-cell arrays travel in the file
    cell_data = meshio.read(tmp_path / "m.vtu").cell_data
    np.testing.assert_allclose(cell_data["non_orthogonality"][0], metrics["non_orthogonality"], rtol=1e-14)
    assert "min angle" in result.stdout and "valid" in result.stdout


def test_foreign_gmsh_file_known_answers_and_skipped_cells(run_cli, tmp_path):
    shear = 0.5
    write_gmsh(tmp_path / "box.msh", sheared_box((4, 3, 2), shear))
    report, result = evaluate_json(run_cli, tmp_path, "box.msh")
    assert report["cells"] == 24 and not report["structured"]
    assert report["skipped"] == {"line": 3, "triangle": 2}
    acute = np.degrees(np.arctan2(1.0, shear))
    assert report["metrics"]["min_angle"]["mean"] == pytest.approx(acute, rel=1e-12)
    assert report["metrics"]["max_angle"]["max"] == pytest.approx(180 - acute, rel=1e-12)
    assert report["metrics"]["non_orthogonality"]["max"] == pytest.approx(np.degrees(np.arctan(shear)), rel=1e-12)
    assert report["metrics"]["aspect_ratio"]["mean"] == pytest.approx(np.hypot(1, shear), rel=1e-12)
    assert report["metrics"]["scaled_jacobian"]["min"] == pytest.approx(1 / np.hypot(1, shear), rel=1e-12)
    assert "boundary_deviation" not in report
    assert "skipped" in result.stdout and "3 line" in result.stdout


def test_foreign_file_boundary_deviation_needs_and_takes_the_flag(run_cli, tmp_path, semicylinder):
    X = tfi(semicylinder, (8, 7, 6))
    X[..., :2] *= 0.98  # shrunk: arc nodes 0.02 inside
    write_gmsh(tmp_path / "shrunk.msh", X, extra=False)
    report, _ = evaluate_json(run_cli, tmp_path, "shrunk.msh", "--geometry", "semicylinder")
    deviation = report["boundary_deviation"]
    assert deviation["max"] == pytest.approx(0.02, rel=1e-9)
    assert deviation["max_rel"] == pytest.approx(0.02 / 3.0, rel=1e-9)  # L = bounding-box diagonal 3
    assert deviation["characteristic_length"] == pytest.approx(3.0)
    # A parameter changes the true boundary: radius 0.98 fits the shrunk section, so only the
    # caps' and diameter's nodes, which were not moved off their planes, remain: all on it.
    report, _ = evaluate_json(run_cli, tmp_path, "shrunk.msh", "-g", "semicylinder", "--param", "radius=0.98")
    assert report["boundary_deviation"]["max"] < 1e-12


def test_several_meshes_one_table_and_a_json_list(run_cli, tmp_path):
    write_gmsh(tmp_path / "a.msh", sheared_box((2, 2, 2), 0.0))
    write_gmsh(tmp_path / "b.msh", sheared_box((2, 2, 2), 1.0))
    reports, result = evaluate_json(run_cli, tmp_path, "a.msh", "b.msh")
    assert [r["file"] for r in reports] == ["a.msh", "b.msh"]
    assert reports[0]["metrics"]["min_angle"]["mean"] == pytest.approx(90)
    assert reports[1]["metrics"]["min_angle"]["mean"] == pytest.approx(45)
    header = next(line for line in result.stdout.splitlines() if "a.msh" in line)
    assert "b.msh" in header  # one table, a column each


def test_markdown_has_the_values(run_cli, tmp_path):
    write_gmsh(tmp_path / "box.msh", sheared_box((3, 2, 2), 0.7))
    result = run_cli("evaluate", "box.msh", "--markdown", "summary.md", "--json", "r.json", "--fail-if", "min_angle.mean<70")
    assert result.returncode == 1  # min angle 55: the gate trips, the reports are written all the same
    report = json.loads((tmp_path / "r.json").read_text())
    text = (tmp_path / "summary.md").read_text()
    rows = {cells[0]: cells[1:] for cells in (line.strip("|").split("|") for line in text.splitlines() if line.startswith("|"))}
    rows = {key.strip(): [v.strip() for v in values] for key, values in rows.items()}
    for label, name in (
        ("min angle (deg)", "min_angle"),
        ("aspect ratio", "aspect_ratio"),
        ("scaled Jacobian", "scaled_jacobian"),
    ):
        values = [float(v) for v in rows[label]]
        expected = [report["metrics"][name][stat] for stat in STATS]
        np.testing.assert_allclose(values, expected, rtol=1e-3)
    assert "min_angle.mean<70" in text and "FAILED" in text


def test_gate_exit_statuses(run_cli, tmp_path):
    write_gmsh(tmp_path / "box.msh", sheared_box((3, 2, 2), 0.7))  # min angle 55 degrees, nothing inverted
    passed = run_cli("evaluate", "box.msh", "--fail-if", "inverted.count>0", "--fail-if", "min_angle.mean<50")
    assert passed.returncode == 0, passed.stderr
    tripped = run_cli("evaluate", "box.msh", "--fail-if", "inverted.count>0", "--fail-if", "min_angle.mean<70")
    assert tripped.returncode == 1
    assert re.search(r"min_angle\.mean<70: FAILED .*min_angle\.mean = 55\.0", tripped.stderr)
    assert "inverted.count>0: FAILED" not in tripped.stderr
    unknown = run_cli("evaluate", "box.msh", "--fail-if", "min_angel.mean<70")
    assert unknown.returncode == 2
    assert "did you mean 'min_angle.mean'" in unknown.stderr and "equiangle_skewness" in unknown.stderr
    malformed = run_cli("evaluate", "box.msh", "--fail-if", "min_angle.mean <<< 70")
    assert malformed.returncode == 2 and "malformed" in malformed.stderr and "non_orthogonality" in malformed.stderr
    no_geometry = run_cli("evaluate", "box.msh", "--fail-if", "boundary_deviation.max_rel>1e-3")
    assert no_geometry.returncode == 2 and "--geometry" in no_geometry.stderr
    for result in (unknown, malformed, no_geometry):
        assert "Traceback" not in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_an_inverted_cell_trips_the_inverted_gate_and_the_validity_gate(run_cli, tmp_path):
    X = sheared_box((4, 1, 1), 0.0)
    X[2, ..., 0] = 3.5  # cell 2 inside out
    write_gmsh(tmp_path / "bad.msh", X, extra=False)
    result = run_cli("evaluate", "bad.msh", "--fail-if", "inverted.count>0", "--fail-if", "valid==false", "--json", "r.json")
    assert result.returncode == 1
    report = json.loads((tmp_path / "r.json").read_text())
    assert report["inverted"] == {"count": 1, "fraction": 0.25, "degenerate": 0} and report["valid"] is False
    assert [g["tripped"] for g in report["gates"]] == [True, True]


def test_quad_meshes_from_the_mesh_command(run_cli, tmp_path):
    made = run_cli("mesh", "-m", "tfi", "-g", "semidisk", "--dims", "12", "8", "-o", "d.vtk")
    assert made.returncode == 0, made.stderr
    report, _ = evaluate_json(run_cli, tmp_path, "d.vtk", "--fail-if", "boundary_deviation.max_rel>1e-9")
    assert report["dim"] == 2 and report["cells"] == 96 and report["cell_type"] == "quad"
    metrics = cell_metrics(tfi(load_geometry("semidisk"), (12, 8)))
    assert report["metrics"]["max_angle"]["max"] == pytest.approx(metrics["max_angle"].max(), rel=1e-12)
    assert report["boundary_deviation"]["max_rel"] < 1e-12


@pytest.mark.parametrize(
    "setup, message",
    [
        (lambda d: None, "does not exist"),
        (lambda d: (d / "m.vtu").write_bytes(b""), "empty"),
        (lambda d: (d / "m.vtu").write_text("<VTKFile nonsense"), "not a VTK XML file"),
        (
            lambda d: meshio.write(
                d / "m.vtu", meshio.Mesh(np.random.rand(4, 3), [("triangle", np.array([[0, 1, 2], [1, 2, 3]]))])
            ),
            "no hexahedra or quadrilaterals to evaluate (found: 2 triangle)",
        ),
        (
            lambda d: meshio.write(d / "m.vtu", meshio.Mesh(np.full((8, 3), np.nan), [("hexahedron", np.arange(8)[None])])),
            "nothing to evaluate",
        ),
        (
            lambda d: meshio.write(d / "m.vtu", meshio.Mesh(np.zeros((8, 3)), [("hexahedron", np.arange(8)[None])])),
            "degenerate",
        ),
    ],
)
def test_bad_input_is_one_clear_line_and_exit_2(run_cli, tmp_path, setup, message):
    setup(tmp_path)
    result = run_cli("evaluate", "m.vtu", "--json", "r.json")
    assert result.returncode == 2
    assert message in result.stderr
    assert "Traceback" not in result.stderr and len(result.stderr.strip().splitlines()) == 1
    assert result.stdout.strip() == "" and not (tmp_path / "r.json").exists()


def test_some_non_finite_nodes_are_reported_not_fatal(run_cli, tmp_path):
    X = sheared_box((3, 3, 3), 0.0)
    X[3, 3, 3] = np.nan
    write_gmsh(tmp_path / "nan.msh", X, extra=False)
    result = run_cli("evaluate", "nan.msh", "--fail-if", "inverted.count>0")
    assert result.returncode == 1 and "non-finite" in result.stderr


def test_help_names_every_gate_quantity(run_cli):
    from meshgen.quality.gates import gate_names

    result = run_cli("evaluate", "--help")
    assert result.returncode == 0
    text = " ".join(result.stdout.split())
    for name in gate_names():
        head, _, field = name.partition(".")
        assert head in text and (not field or field in text), name


def test_solver_figures_of_our_own_mesh_and_their_gates(run_cli, tmp_path, semicylinder):
    from meshgen.quality.faces_openfoam import non_orthogonality
    from meshgen.quality.smoothness import expansion_ratio

    dims = (4, 5, 6)
    assert run_cli("mesh", "-g", "semicylinder", "--method", "tfi", "--dims", *dims, "-o", "m.vtu").returncode == 0
    report, _ = evaluate_json(run_cli, tmp_path, "m.vtu")
    figures = report["solver_figures"]
    X = tfi(semicylinder, dims)  # the structured path's node array, computed independently here
    internal = non_orthogonality(X)["non_orthogonality_internal"]
    assert figures["non_orthogonality_internal"]["max"] == pytest.approx(internal["max"], abs=1e-9)
    assert figures["expansion_ratio"]["max"] == pytest.approx(expansion_ratio(X).max(), rel=1e-12)
    below, above = internal["max"] - 0.01, internal["max"] + 0.01
    assert run_cli("evaluate", "m.vtu", "--fail-if", f"non_orthogonality_internal.max>{below}").returncode == 1
    assert run_cli("evaluate", "m.vtu", "--fail-if", f"non_orthogonality_internal.max>{above}").returncode == 0
    # a foreign unstructured file has no grid lines: the gate says so (usage error)
    write_gmsh(tmp_path / "box.msh", sheared_box((3, 2, 2), 0.7))
    foreign = run_cli("evaluate", "box.msh", "--fail-if", "expansion_ratio.max>2")
    assert foreign.returncode == 2 and "structured mesh" in foreign.stderr


def test_the_table_is_printed_as_without_rich_warmed_up(run_cli, tmp_path, monkeypatch):
    """rich is warmed up on a thread while the metrics are computed (``tables.warm_up``): the table
    is the one printed without that, and the thread has ended when the command returns."""
    import threading

    import meshgen.cli.evaluate as command

    made = run_cli("mesh", "-m", "tfi", "-g", "semicylinder", "--dims", "6", "5", "4", "-o", "m.vts", "-q")
    assert made.returncode == 0, made.stderr
    calls = []
    original = command.warm_up
    monkeypatch.setattr(command, "warm_up", lambda: (calls.append(1), original()))
    warmed = run_cli("evaluate", "m.vts", "m.vts")
    assert warmed.returncode == 0, warmed.stderr
    assert len(calls) == 2 and not [t for t in threading.enumerate() if t.name == "meshgen-rich"]
    monkeypatch.setattr(command, "warm_up", lambda: None)
    plain = run_cli("evaluate", "m.vts", "m.vts")
    assert warmed.stdout == plain.stdout and "mesh quality" in plain.stdout
    quiet = run_cli("evaluate", "m.vts", "--json", "-")
    assert quiet.returncode == 0 and len(calls) == 2  # no table, no warm-up

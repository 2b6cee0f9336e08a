"""meshgen compare: the table's figures are meshgen evaluate's on the written meshes, the best
value per column, tables and pictures with --out, timing repeats, file comparison, errors."""

from __future__ import annotations

import csv
import importlib.util
import json
import math
import statistics
import struct
import sys

import numpy as np
import pytest

from meshgen.cli import comparison as comparing
from meshgen.cli import plots
from meshgen.cli.tables import number

HAVE_MATPLOTLIB = importlib.util.find_spec("matplotlib") is not None


def png_size(path) -> tuple[int, int]:
    with open(path, "rb") as handle:
        head = handle.read(24)
    assert head[:8] == b"\x89PNG\r\n\x1a\n"
    return struct.unpack(">II", head[16:24])


def png_pixels(path) -> np.ndarray:
    from matplotlib.image import imread

    return imread(path)


def markdown_rows(text: str) -> list[list[str]]:
    """Cells of the first Markdown table in ``text`` (header first, separator dropped)."""
    lines = [line for line in text.splitlines() if line.startswith("|")]
    rows = [[cell.strip() for cell in line.strip("|").split(" | ")] for line in lines]
    return [rows[0], *rows[2:]]


@pytest.fixture(scope="module")
def methods_run(tmp_path_factory):
    """One end-to-end comparison of tfi and elliptic on the half-disk, and evaluate --json of the
    meshes it wrote (both through the command line)."""
    import os
    import subprocess
    from pathlib import Path

    folder = tmp_path_factory.mktemp("compare")
    environment = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[1])}

    def cli(*args):
        return subprocess.run(
            [sys.executable, "-m", "meshgen", *args], cwd=folder, env=environment, capture_output=True, text=True, timeout=300
        )

    result = cli(
        "compare", "-g", "semidisk", "--dims", "12", "7", "--methods", "tfi,elliptic", "--timing-repeats", "3", "--out", "out"
    )
    assert result.returncode == 0, result.stderr
    evaluated = cli("evaluate", "out/tfi.vtu", "out/elliptic.vtu", "--json", "-")
    assert evaluated.returncode == 0, evaluated.stderr
    return folder, result, json.loads(evaluated.stdout)


def test_figures_equal_evaluate_on_the_written_meshes(methods_run):
    folder, result, evaluated = methods_run
    comparison = json.loads((folder / "out" / "compare.json").read_text())
    assert [row["name"] for row in comparison["rows"]] == ["tfi", "elliptic"]
    by_file = {report["file"]: report for report in evaluated}
    for row in comparison["rows"]:
        report = by_file[f"out/{row['name']}.vtu"]
        headline = row["headline"]
        for metric in comparing.HEADLINE_METRICS:
            assert headline[metric] == pytest.approx(report["metrics"][metric]["mean"], rel=1e-12), metric
        assert headline["inverted_count"] == report["inverted"]["count"]
        assert headline["inverted_percent"] == pytest.approx(100 * report["inverted"]["fraction"])
        assert headline["valid"] is report["valid"]
        for stat in ("max", "max_rel", "mean", "mean_rel"):
            assert headline[f"boundary_deviation_{stat}"] == pytest.approx(
                report["boundary_deviation"][stat], rel=1e-9, abs=1e-15
            )
        # The figures as the terminal prints them: 4 significant digits, on the method's line.
        line = next(line for line in result.stdout.splitlines() if line.split()[:1] == [row["name"]])
        for metric in comparing.HEADLINE_METRICS:
            assert number(report["metrics"][metric]["mean"]) in line.split(), (metric, line)
    # The CSV holds the same figures at full precision.
    with open(folder / "out" / "compare.csv", newline="") as handle:
        lines = list(csv.DictReader(handle))
    for line, row in zip(lines, comparison["rows"]):
        assert line["name"] == row["name"]
        for metric in comparing.HEADLINE_METRICS:
            assert float(line[metric]) == row["headline"][metric]


def test_best_values_are_marked_where_evaluate_says_they_are(methods_run):
    folder, _, evaluated = methods_run
    comparison = json.loads((folder / "out" / "compare.json").read_text())
    means = {report["file"].split("/")[-1][:-4]: report["metrics"] for report in evaluated}
    # Independently: larger mean min angle, smaller mean max angle, smaller skewness and non-orthogonality.
    expected = {
        "min_angle": max(means, key=lambda m: means[m]["min_angle"]["mean"]),
        "max_angle": min(means, key=lambda m: means[m]["max_angle"]["mean"]),
        "equiangle_skewness": min(means, key=lambda m: means[m]["equiangle_skewness"]["mean"]),
        "non_orthogonality": min(means, key=lambda m: means[m]["non_orthogonality"]["mean"]),
        "aspect_ratio": min(means, key=lambda m: means[m]["aspect_ratio"]["mean"]),
    }
    for key, name in expected.items():
        assert comparison["best"][key] == [name], key
    # Both meshes meet the boundary to round-off and have no inverted cells: ties, both marked.
    assert sorted(comparison["best"]["boundary_deviation_max_rel"]) == ["elliptic", "tfi"]
    assert sorted(comparison["best"]["inverted_percent"]) == ["elliptic", "tfi"]
    assert "test_loss" not in comparison["best"]  # no row has one

    rows = markdown_rows((folder / "out" / "compare.md").read_text())
    header, body = rows[0], rows[1:]
    labels = {c.key: c.label for c in comparing.COLUMNS}
    for key, name in expected.items():
        column = header.index(labels[key])
        for row in body:
            assert row[column].startswith("**") == (row[0] == name), (key, row)


def test_timing_repeats_record_each_run_and_their_median(methods_run):
    folder, _, _ = methods_run
    comparison = json.loads((folder / "out" / "compare.json").read_text())
    assert comparison["timing_repeats"] == 3
    for row in comparison["rows"]:
        timings = row["meshing_timings"]
        assert len(timings) == 3 and all(t > 0 for t in timings)
        assert row["meshing_seconds"] == sorted(timings)[1]
        assert row["headline"]["meshing_seconds"] == row["meshing_seconds"]
    # The written mesh records the median too.
    recorded = json.loads((folder / "out" / "elliptic.vtu.quality.json").read_text())
    assert recorded["meshing_seconds"] == comparison["rows"][1]["meshing_seconds"]


@pytest.mark.skipif(not HAVE_MATPLOTLIB, reason="matplotlib (meshgen[plot]) not installed")
def test_sections_picture_has_the_documented_size_and_is_not_blank(methods_run):
    folder, _, _ = methods_run
    path = folder / "out" / "sections.png"
    assert png_size(path) == plots.sections_size(2, 1) == (2 * 400 + 120, 360 + 40)
    pixels = png_pixels(path)
    assert pixels.shape[:2] == (400, 920)
    assert float(pixels[..., :3].var()) > 0
    comparison = json.loads((folder / "out" / "compare.json").read_text())
    assert comparison["pictures"]["size_px"] == [920, 400]
    assert not (folder / "out" / "loss_curves.png").exists()  # no neural method


def test_compare_files_gives_the_same_figures_as_the_methods(methods_run, run_cli, tmp_path):
    folder, _, _ = methods_run
    made = run_cli("mesh", "-m", "tfi", "-g", "semidisk", "--dims", "12", "7", "-o", "tfi.cgns")
    assert made.returncode == 0, made.stderr
    result = run_cli("compare", "tfi.cgns", folder / "out" / "elliptic.vtu", "--out", "files")
    assert result.returncode == 0, result.stderr
    files = json.loads((tmp_path / "files" / "compare.json").read_text())
    methods = json.loads((folder / "out" / "compare.json").read_text())
    assert files["mode"] == "files" and [row["kind"] for row in files["rows"]] == ["file", "file"]
    for file_row, method_row in zip(files["rows"], methods["rows"]):
        for key, value in method_row["headline"].items():
            if key in ("meshing_seconds", "training_seconds", "test_loss"):
                continue
            if isinstance(value, float):
                assert file_row["headline"][key] == pytest.approx(value, rel=1e-9, abs=1e-15), key
            else:
                assert file_row["headline"][key] == value, key
    # Meshing time: what each file records (its sidecar).
    recorded = json.loads((folder / "out" / "elliptic.vtu.quality.json").read_text())
    assert files["rows"][1]["meshing_seconds"] == recorded["meshing_seconds"]
    assert not list((tmp_path / "files").glob("*.vtu"))  # files are not copied
    if HAVE_MATPLOTLIB:
        assert png_size(tmp_path / "files" / "sections.png") == plots.sections_size(2, 1)


def test_without_matplotlib_the_tables_are_written_and_the_command_says_how_to_get_pictures(tmp_path, monkeypatch):
    from click.testing import CliRunner

    from meshgen.cli import cli

    monkeypatch.setitem(sys.modules, "matplotlib", None)  # import matplotlib now raises ImportError
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(cli, ["compare", "-g", "bump", "--dims", "6", "3", "--methods", "tfi", "--out", "out"])
    assert result.exit_code == 0, result.output
    assert "pip install 'meshgen[plot]'" in result.output
    for name in ("compare.json", "compare.md", "compare.csv", "tfi.vtu"):
        assert (tmp_path / "out" / name).stat().st_size > 0, name
    assert not (tmp_path / "out" / "sections.png").exists()
    assert "pip install 'meshgen[plot]'" in (tmp_path / "out" / "compare.md").read_text()


def test_a_failing_method_gets_a_failed_row_and_exit_1_while_the_others_are_compared(tmp_path, monkeypatch):
    from click.testing import CliRunner

    import meshgen.methods.registry
    from meshgen.cli import cli
    from meshgen.errors import MeshgenError

    def broken(geometry, coords):
        raise MeshgenError("tfi broke")

    monkeypatch.setattr(meshgen.methods.registry, "build_tfi", broken)
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(cli, ["compare", "-g", "bump", "--dims", "6", "3", "--out", "out"])
    assert result.exit_code == 1
    assert "tfi failed: tfi broke" in result.output
    comparison = json.loads((tmp_path / "out" / "compare.json").read_text())
    assert comparison["rows"][0] == {"name": "tfi", "kind": "classical", "error": "tfi broke"}
    assert comparison["rows"][1]["headline"]["valid"] is True
    assert comparison["best"] == {}  # one row with figures: nothing to rank
    assert "- `tfi` failed: tfi broke" in (tmp_path / "out" / "compare.md").read_text()
    assert not (tmp_path / "out" / "tfi.vtu").exists() and (tmp_path / "out" / "elliptic.vtu").exists()


@pytest.mark.parametrize(
    "args, message",
    [
        (
            ["--methods", "tfi,foo"],
            "unknown method 'foo' (methods: tfi, elliptic, neural, 3dmeshnet, exact, pinn, fd-pinn, rwgp-pinn, mgnet)",
        ),
        (["--checkpoint", "tfi=x.pt"], "'tfi' is not a neural method"),
        (["--checkpoint", "pinn"], "malformed --checkpoint"),
        (["--steps", "5"], "--steps applies to neural methods only"),
        (["--methods", "tfi", "--tol", "1e-3"], "--tol applies to none of the compared methods"),
        (["--mesh-format", "stl"], "unknown output extension .stl"),
        (["--dims", "4", "4", "4"], "semidisk' is 2D"),
    ],
)
def test_bad_input_is_one_line_exit_2_and_nothing_written(run_cli, tmp_path, args, message):
    base = ["compare", "-g", "semidisk", "--out", "out"]
    if "--dims" not in args:
        base += ["--dims", "4", "3"]
    result = run_cli(*base, *args)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error:") and message in lines[0], result.stderr
    assert not (tmp_path / "out").exists()


def test_files_and_methods_do_not_mix(run_cli, tmp_path):
    result = run_cli("compare", "a.vtu", "--methods", "tfi")
    assert result.returncode == 2 and "--methods applies when meshing a geometry" in result.stderr
    result = run_cli("compare", "missing.vtu", "--out", "out")
    assert result.returncode == 2 and "missing.vtu does not exist" in result.stderr
    assert not (tmp_path / "out").exists()


# ---------------------------------------------------------------------------------------------
# the parts


def row(name, **values):
    return {"name": name, "headline": values}


def test_best_rows_rules():
    rows = [
        row("a", min_angle=80.0, max_angle=95.0, aspect_ratio=1.5, boundary_deviation_max_rel=1e-16, test_loss=None),
        row(
            "b", min_angle=85.0, max_angle=100.0, aspect_ratio=1.5 * (1 + 1e-12), boundary_deviation_max_rel=3e-16, test_loss=2e-3
        ),
        row("c", min_angle=60.0, max_angle=120.0, aspect_ratio=2.0, boundary_deviation_max_rel=1e-3, test_loss=float("nan")),
    ]
    best = comparing.best_rows(rows)
    assert best["min_angle"] == ["b"]  # the largest mean min angle
    assert best["max_angle"] == ["a"]  # the smallest mean max angle
    assert best["aspect_ratio"] == ["a", "b"]  # equal up to round-off: a tie
    assert best["boundary_deviation_max_rel"] == ["a", "b"]  # both below 1e-12 of L
    assert "test_loss" not in best  # one finite value is no comparison
    assert "valid" not in best


def test_headline_and_cells_of_a_report():
    from meshgen.geometry.plugins import load_geometry
    from meshgen.methods.tfi import tfi
    from meshgen.quality import quality_report

    geometry = load_geometry("semidisk")
    report = quality_report(tfi(geometry, (6, 4)), geometry)
    values = comparing.headline(report, meshing_seconds=0.25)
    assert values["non_orthogonality"] == report["metrics"]["non_orthogonality"]["mean"]
    assert values["test_loss"] is None and values["meshing_seconds"] == 0.25
    column = {c.key: c for c in comparing.COLUMNS}
    assert comparing.cell_text(column["inverted_percent"], values) == "0 (0%)"
    assert comparing.cell_text(column["test_loss"], values) == "n/a"
    assert comparing.cell_text(column["valid"], values) == "yes"


def test_mid_section_values_are_the_whole_mesh_metrics_of_the_cells_on_the_plane():
    from meshgen.geometry.plugins import load_geometry
    from meshgen.methods.tfi import tfi
    from meshgen.quality import cell_metrics

    X = tfi(load_geometry("semicylinder"), (7, 5, 4))
    whole = {name: values.reshape(7, 5, 4) for name, values in cell_metrics(X).items()}
    for axis in range(3):
        n = X.shape[axis] - 1
        for metric in ("non_orthogonality", "aspect_ratio", "min_angle"):
            faces, values, names, node = plots.mid_section(X, axis, metric)
            assert node == n // 2
            expected = np.take(whole[metric], min(n // 2, n - 1), axis=axis).reshape(-1)
            np.testing.assert_allclose(values, expected, rtol=1e-12, atol=1e-12)
        # Faces: the plane's nodes on the two drawn axes, corner 0 of face (a, b) at node (a, b).
        plane = np.take(X, n // 2, axis=axis)
        drawn = ["xyz".index(name) for name in names]
        assert faces.shape == ((plane.shape[0] - 1) * (plane.shape[1] - 1), 4, 2)
        np.testing.assert_array_equal(faces[:, 0], plane[:-1, :-1][..., drawn].reshape(-1, 2))
        np.testing.assert_array_equal(faces[:, 2], plane[1:, 1:][..., drawn].reshape(-1, 2))
    # The k mid-plane of the semicylinder is a cross-section z = const: drawn on x and y.
    assert plots.mid_section(X, 2, "aspect_ratio")[2] == ["x", "y"]


@pytest.mark.skipif(not HAVE_MATPLOTLIB, reason="matplotlib (meshgen[plot]) not installed")
def test_3d_sections_and_loss_curves_figures(tmp_path):
    from meshgen.geometry.plugins import load_geometry

    geometry = load_geometry("semicylinder")
    outcome = comparing.compare_methods(geometry, (5, 4, 3), ["tfi"])
    history = tmp_path / "history.csv"
    steps = np.arange(1, 41)
    with open(history, "w") as handle:
        handle.write("stage,step,L1,L2,total,a1,a2,conflict,lr,seconds\n")
        for step in steps:
            stage = "pretrain" if step <= 10 else "adam"
            handle.write(f"{stage},{step},{1 / step},{2 / step**2},{3 / step},1,1,0,0.001,{step * 0.01}\n")
    pictures = outcome.pictures + [plots_picture("other", X=outcome.pictures[0].X * 2.0, history=str(history))]
    path = plots.sections_figure(pictures, "min_angle", tmp_path / "sections.png")
    assert png_size(path) == plots.sections_size(2, 3) == (920, 3 * 360 + 40)
    assert float(png_pixels(path)[..., :3].var()) > 0
    curves = plots.loss_curves_figure(pictures, tmp_path / "loss.png")
    assert png_size(curves) == plots.loss_curves_size(1) == (400, 400)
    assert float(png_pixels(curves)[..., :3].var()) > 0
    assert plots.read_history(history)["L2"][3] == pytest.approx(2 / 16)
    assert not list(tmp_path.glob(".*tmp*"))  # atomic writes leave no temporary files


def plots_picture(label, **fields):
    return comparing.Picture(label, **fields)


def test_timing_repeats_mesh_n_times_and_report_the_median(monkeypatch, semidisk):
    import meshgen.methods.registry
    from meshgen.run.request import MeshRequest, carry_out

    calls, build = [], meshgen.methods.registry.build_tfi

    def counted(*args, **kwargs):
        calls.append(1)
        return build(*args, **kwargs)

    monkeypatch.setattr(meshgen.methods.registry, "build_tfi", counted)
    made = carry_out(MeshRequest((4, 3), semidisk, method="tfi", timing_repeats=4))
    assert len(calls) == 4 and len(made.timings) == 4
    assert made.seconds == statistics.median(made.timings) and all(math.isfinite(t) for t in made.timings)


def test_compare_sidecar_records_the_clustering_and_meshes_as_meshgen_mesh(run_cli, tmp_path):
    from meshgen.formats import read_mesh

    args = ("-g", "semidisk", "--dims", 6, 4, "--cluster", "eta:0:1.2")
    compared = run_cli("compare", *args, "--methods", "tfi,elliptic", "--out", "cmp", "-q")
    assert compared.returncode == 0, compared.stderr
    for method in ("tfi", "elliptic"):
        sidecar = json.loads((tmp_path / "cmp" / f"{method}.vtu.quality.json").read_text())
        assert sidecar["cluster"] == ["eta:0:1.2"] and sidecar["method"] == method and sidecar["dims"] == [6, 4]
        made = run_cli("mesh", "-m", method, *args, "-o", f"{method}.vtu", "-q")
        assert made.returncode == 0, made.stderr
        mesh_sidecar = json.loads((tmp_path / f"{method}.vtu.quality.json").read_text())
        recorded = ("meshgen_version", "method", "geometry", "params", "dims", "cluster")
        assert {k: sidecar[k] for k in recorded} == {k: mesh_sidecar[k] for k in recorded}
        np.testing.assert_array_equal(
            read_mesh(tmp_path / f"{method}.vtu").points, read_mesh(tmp_path / "cmp" / f"{method}.vtu").points
        )


# ---------------------------------------------------------------------------------------------
# neural methods (run when meshgen.neural is installed)

TINY_BUDGET = [
    "--steps", "20",
    "--set", "model.widths=[8,8]",
    "--set", "pretrain.steps=5",
    "--set", "points.interior=256",
    "--set", "points.boundary=256",
    "--set", "test.interior=100",
    "--set", "test.boundary=100",
]  # fmt: skip


@pytest.mark.slow
def test_neural_method_trains_meshes_and_reuses_its_checkpoint(run_cli, tmp_path):
    import torch

    result = run_cli("compare", "-g", "semidisk", "--dims", "10", "6", "--methods", "tfi,3dmeshnet", *TINY_BUDGET, "--out", "out")
    assert result.returncode == 0, result.stderr
    comparison = json.loads((tmp_path / "out" / "compare.json").read_text())
    neural = comparison["rows"][1]
    assert neural["name"] == "3dmeshnet" and neural["kind"] == "neural"
    checkpoint_path = tmp_path / "out" / "runs" / "3dmeshnet" / "checkpoint.pt"
    checkpoint = torch.load(checkpoint_path, map_location="cpu", weights_only=True)
    assert neural["headline"]["test_loss"] == pytest.approx(float(checkpoint["test_loss"]["total"]))
    assert neural["headline"]["training_seconds"] > 0
    evaluated = run_cli("evaluate", "out/3dmeshnet.vtu", "--json", "-")
    report = json.loads(evaluated.stdout)
    for metric in comparing.HEADLINE_METRICS:
        assert neural["headline"][metric] == pytest.approx(report["metrics"][metric]["mean"], rel=1e-12)
    assert neural["headline"]["boundary_deviation_max"] == pytest.approx(report["boundary_deviation"]["max"], rel=1e-9)
    if HAVE_MATPLOTLIB:
        assert png_size(tmp_path / "out" / "loss_curves.png") == plots.loss_curves_size(1)
        assert float(png_pixels(tmp_path / "out" / "loss_curves.png")[..., :3].var()) > 0

    # Reusing the checkpoint: no training, the same network, so the same mesh and test-set loss.
    again = run_cli(
        "compare",
        "-g",
        "semidisk",
        "--dims",
        "10",
        "6",
        "--methods",
        "3dmeshnet",
        "--checkpoint",
        f"3dmeshnet={checkpoint_path}",
        "--out",
        "again",
    )
    assert again.returncode == 0, again.stderr
    reused = json.loads((tmp_path / "again" / "compare.json").read_text())["rows"][0]
    assert reused["headline"]["test_loss"] == neural["headline"]["test_loss"]
    for metric in comparing.HEADLINE_METRICS:
        assert reused["headline"][metric] == pytest.approx(neural["headline"][metric], rel=1e-12)
    assert not (tmp_path / "again" / "runs").exists()

"""``meshgen mesh`` and ``meshgen evaluate`` of multi-block geometries, and their one-line errors."""

import json

import pytest


def test_mesh_pipe_elliptic_cgns_and_evaluate(run_cli, tmp_path):
    result = run_cli("mesh", "-g", "pipe", "--dims", "4", "2", "3", "--method", "elliptic", "-o", "pipe.cgns")
    assert result.returncode == 0, result.stderr
    assert "5 blocks" in result.stdout and "wrote pipe.cgns" in result.stdout
    sidecar = json.loads((tmp_path / "pipe.cgns.quality.json").read_text())
    assert sidecar["cells"] == 4 * 4 * 3 + 4 * 2 * 4 * 3
    evaluated = run_cli("evaluate", "pipe.cgns", "--json", "-")
    assert evaluated.returncode == 0, evaluated.stderr
    report = json.loads(evaluated.stdout)
    assert report["cells"] == sidecar["cells"]
    assert report["inverted"]["count"] == 0


def test_mesh_dfg_tfi_vtu(run_cli, tmp_path):
    import meshio

    result = run_cli("mesh", "-g", "dfg-cylinder", "--dims", "4", "3", "--method", "tfi", "-o", "dfg.vtu")
    assert result.returncode == 0, result.stderr
    mesh = meshio.read(tmp_path / "dfg.vtu")
    assert len(mesh.cells[0].data) == json.loads((tmp_path / "dfg.vtu.quality.json").read_text())["cells"]


@pytest.mark.parametrize(
    "args, words",
    [
        (["--dims", "4", "2", "-o", "x.cgns"], "--dims needs 3 numbers (N M A"),
        (["--dims", "4", "2", "3", "-o", "x.vts"], "vts does not take multi-block meshes"),
        (["--dims", "4", "2", "3", "--cluster", "zeta:both:1.1", "-o", "x.cgns"], "takes PATCH:RATIO (e.g. wall:1.1"),
        (["--dims", "4", "2", "3", "--method", "neural", "-o", "x.cgns"], "no trained model for pipe"),
    ],
)
def test_bad_block_requests_are_one_line(run_cli, tmp_path, args, words):
    result = run_cli("mesh", "-g", "pipe", *args)
    assert result.returncode == 2
    assert words in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert not list(tmp_path.glob("x.*"))


def test_evaluate_per_block(run_cli, tmp_path):
    assert run_cli("mesh", "-g", "pipe", "--dims", "4", "2", "3", "--method", "tfi", "-o", "p.cgns", "-q").returncode == 0
    result = run_cli("evaluate", "p.cgns", "--per-block", "--json", "-")
    assert result.returncode == 0, result.stderr
    reports = json.loads(result.stdout)
    assert [r["file"] for r in reports] == ["p.cgns"] + [f"p.cgns:{b}" for b in ("core", "east", "north", "west", "south")]
    assert reports[0]["cells"] == sum(r["cells"] for r in reports[1:]) == 4 * 4 * 3 + 4 * 2 * 4 * 3
    assert reports[1]["cells"] == 4 * 4 * 3

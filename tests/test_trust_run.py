"""Trust on the surfaces added since 0.2: block sets' sizes and parameters, multi-zone
.cgns headers, the .vtm's pieces folder, links planted at the names meshgen writes through, and a
resumed checkpoint's optimiser state. Each case drives the real command line: exit 2, one line
that names the problem, nothing written or changed (the quality worker's stop: test_quality_worker.py)."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
import torch
from helpers import files_in as snapshot
from neural_helpers import tiny_config

from meshgen.formats import read_mesh
from meshgen.geometry.plugins import load_geometry
from meshgen.neural.train import train
from meshgen.run import publish

REPO = Path(__file__).resolve().parents[1]


def one_line_error(result, *fragments) -> str:
    assert result.returncode == 2, (result.returncode, result.stdout, result.stderr)
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("Error: "), result.stderr
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    return lines[0]


# --- block sets -------------------------------------------------------------------------------


def test_a_block_set_too_large_for_memory_is_one_line_before_any_work(tmp_path, run_cli_process):
    result = run_cli_process("mesh", "-g", "pipe", "--dims", 2000, 2000, 2000, "-o", "m.cgns", timeout=120)
    line = one_line_error(result, "multi-block geometry 'pipe'", "5 blocks", "available", "pick fewer cells")
    # the nodes of its five blocks, as the plugin lays them out, at 2000^3: about 4e10
    assert "4.01e+10 nodes" in line
    assert os.listdir(tmp_path) == []


def test_a_tiny_wake_growth_meshes_even_wake_cells(run_cli, tmp_path):
    """wake_growth=1e-300 is inside (0, 10]: the growth ratio 1 + 1e-300 / N rounds to 1, so the
    wake's cells are even, of the box's cell size 2 BOX / N."""
    result = run_cli("mesh", "-g", "dfg-cylinder", "--dims", 8, 4, "-m", "tfi", "--param", "wake_growth=1e-300", "-o", "m.cgns")
    assert result.returncode == 0, result.stderr
    x = np.unique(np.round(read_mesh(tmp_path / "m.cgns").points[:, 0], 12))
    wake = x[x >= 0.3 - 1e-12]  # from the box's downstream side (0.2 + BOX) to the outlet at 2.2
    assert np.allclose(np.diff(wake), 2 * 0.1 / 8, rtol=1e-9) and wake[-1] == pytest.approx(2.2)


def test_a_parameter_that_breaks_a_block_set_is_one_line_naming_it(run_cli, tmp_path):
    """The plugin's old wake count (log(1 + x) / log(growth), growth = 1 + 1e-300 / N = 1) divides
    by zero: a floating-point failure inside a plugin's block_coords is one line naming the
    parameters, never numpy's warning and a traceback."""
    source = (REPO / "geometries" / "dfg-cylinder.py").read_text()
    old = source.replace('name = "dfg-cylinder"', 'name = "old-dfg"')
    old = old.replace(
        "int(np.ceil(np.log1p((LENGTH - _X[2]) * step / h) / np.log1p(step)))",
        "int(np.ceil(np.log(1.0 + (LENGTH - _X[2]) * step / h) / np.log(1.0 + step)))",
    )
    assert old.count("np.log(1.0 + step)") == 1
    (tmp_path / "old_dfg.py").write_text(old)
    result = run_cli("mesh", "-g", "old_dfg.py", "--dims", 8, 4, "-m", "tfi", "--param", "wake_growth=1e-300", "-o", "m.cgns")
    one_line_error(result, "old-dfg", "wake_growth=1e-300", "block_coords()")
    assert sorted(os.listdir(tmp_path)) == ["old_dfg.py"]


# --- multi-zone .cgns -------------------------------------------------------------------------


@pytest.fixture(scope="module")
def pipe_cgns(tmp_path_factory) -> Path:
    """The 3D pipe's five blocks (48 cells each), one zone per block."""
    from meshgen.formats.multiblock import write_blocks
    from meshgen.geometry.blocks import load_block_set, tfi_blocks

    block_set = load_block_set("pipe", {}, (4, 4, 3))
    path = tmp_path_factory.mktemp("pipe") / "pipe.cgns"
    write_blocks(path, block_set, tfi_blocks(block_set))
    return path


def _replace(node, data=None, **dataset):
    del node[" data"]
    node.create_dataset(" data", data=data, **dataset)


def claims_without_data(path: Path) -> None:
    """The third zone's header claims 1001^3 nodes; its coordinates are datasets of that shape
    with nothing stored (HDF5 allocates them lazily)."""
    with h5py.File(path, "r+") as root:
        zone = root["Base"]["north"]
        sizes = zone[" data"][()]
        sizes[0] = 1001
        _replace(zone, sizes)
        for name in ("CoordinateX", "CoordinateY", "CoordinateZ"):
            _replace(zone["GridCoordinates"][name], shape=(1001,) * 3, dtype="<f8")


def typed_unstructured(path: Path) -> None:
    with h5py.File(path, "r+") as root:
        _replace(root["Base"]["east"]["ZoneType"], np.frombuffer(b"Unstructured", dtype=np.int8))


@pytest.mark.parametrize(
    ("damage", "words"),
    [
        (claims_without_data, ["zone 'north' claims (1001, 1001, 1001) nodes", "stores 0 GB"]),
        (typed_unstructured, ["zone 'east' is Unstructured"]),
    ],
    ids=["claim", "unstructured"],
)
@pytest.mark.parametrize("flags", [["--per-block"], []], ids=["per-block", "merged"])
def test_every_zone_header_is_checked_before_a_zone_is_read(pipe_cgns, tmp_path, run_cli, damage, words, flags):
    path = tmp_path / "p.cgns"
    shutil.copy(pipe_cgns, path)
    damage(path)
    before = snapshot(tmp_path)
    one_line_error(run_cli("evaluate", path.name, *flags, "--in-memory", "--json", "r.json"), *words)
    assert snapshot(tmp_path) == before


def test_chunked_evaluation_refuses_a_multi_zone_file_and_the_default_measures_every_zone(pipe_cgns, tmp_path, run_cli):
    shutil.copy(pipe_cgns, tmp_path / "p.cgns")
    before = snapshot(tmp_path)
    one_line_error(run_cli("evaluate", "p.cgns", "--chunked", "--json", "r.json"), "5 zones", "without --chunked")
    assert snapshot(tmp_path) == before
    result = run_cli("evaluate", "p.cgns", "--json", "r.json")  # chunked or not decided by the file: every zone
    assert result.returncode == 0, result.stderr
    import json

    assert json.loads((tmp_path / "r.json").read_text())["cells"] == 5 * 48


# --- writers and links ------------------------------------------------------------------------


def test_a_vtm_refuses_a_folder_that_is_not_its_own_pieces_folder(run_cli, tmp_path):
    mesh = ["mesh", "-g", "pipe", "--dims", 4, 4, 3, "-m", "tfi", "-o"]
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "core.vts").write_text("the user's own file\n")
    before = snapshot(tmp_path)
    one_line_error(run_cli(*mesh, "mine.vtm"), "mine", "not the pieces folder of mine.vtm")
    assert snapshot(tmp_path) == before
    # its own pieces folder (listed by its .vtm) is rewritten; a file the .vtm does not list stops it
    assert run_cli(*mesh, "own.vtm").returncode == 0
    pieces = sorted(os.listdir(tmp_path / "own"))
    assert pieces == ["core.vts", "east.vts", "north.vts", "south.vts", "west.vts"]
    assert run_cli(*mesh, "own.vtm").returncode == 0
    (tmp_path / "own" / "notes.txt").write_text("mine\n")
    before = snapshot(tmp_path)
    one_line_error(run_cli(*mesh, "own.vtm"), "not the pieces folder of own.vtm")
    assert snapshot(tmp_path) == before


@pytest.fixture
def guessable(monkeypatch):
    """The random part of meshgen's temporary names made predictable ("0" to "9", over and over:
    the names a planter would have to guess), so that links can be planted at the names it tries."""
    counter = iter(range(10**6))
    monkeypatch.setattr(publish, "temporary_token", lambda: str(next(counter) % 10))


def test_links_planted_at_the_temporary_names_are_never_followed(run_cli, tmp_path, guessable):
    """Links at the first names meshgen would use (and at 0.2's pid-only names) point at a victim
    file and at a path that does not exist: meshgen writes under other names, the links and their
    targets stay as they were, the mesh and its sidecar are whole."""
    outside = tmp_path / "outside"
    outside.mkdir()
    victim = outside / "victim.txt"
    victim.write_text("not meshgen's\n")
    pid = os.getpid()
    names = [f".m.tmp-{pid}-{n}.vtu" for n in range(8)] + [f".m.vtu.quality.tmp-{pid}-{n}.json" for n in range(8)]
    names += [f".m.tmp-{pid}.vtu", f".m.vtu.quality.tmp-{pid}.json", f".m.vtu.old-{pid}"]
    for number, name in enumerate(names):
        (tmp_path / name).symlink_to(victim if number % 2 else outside / f"created-{number}")
    result = run_cli("mesh", "-g", "semidisk", "--dims", 6, 5, "-m", "tfi", "-o", "m.vtu", "-q")
    assert result.returncode == 0, result.stderr
    assert victim.read_text() == "not meshgen's\n" and os.listdir(outside) == ["victim.txt"]
    assert all((tmp_path / name).is_symlink() for name in names)
    assert len(read_mesh(tmp_path / "m.vtu").points) == 7 * 6
    assert (tmp_path / "m.vtu.quality.json").is_file() and not (tmp_path / "m.vtu").is_symlink()


def test_a_link_at_the_lock_name_is_refused_in_one_line(run_cli, tmp_path):
    (tmp_path / ".m.vtu.lock").symlink_to(tmp_path / "elsewhere")
    before = snapshot(tmp_path)
    one_line_error(
        run_cli("mesh", "-g", "semidisk", "--dims", 6, 5, "-m", "tfi", "-o", "m.vtu"), ".m.vtu.lock", "not a regular file"
    )
    assert snapshot(tmp_path) == before and not os.path.lexists(tmp_path / "elsewhere")


def test_a_block_set_case_never_writes_through_a_planted_link(run_cli, tmp_path):
    """An OpenFOAM case of a block set: the system files were written in place where missing; a
    dangling link planted at controlDict made meshgen create the link's target."""
    (tmp_path / "case" / "system").mkdir(parents=True)
    (tmp_path / "case" / "system" / "controlDict").symlink_to(tmp_path / "created")
    result = run_cli("mesh", "-g", "pipe", "--dims", 4, 4, 3, "-m", "tfi", "--format", "openfoam", "-o", "case", "-q")
    assert result.returncode == 0, result.stderr
    assert not os.path.lexists(tmp_path / "created") and (tmp_path / "case" / "system" / "controlDict").is_symlink()
    from meshgen.geometry.block_nodes import merged_mesh
    from meshgen.geometry.blocks import load_block_set, tfi_blocks

    block_set = load_block_set("pipe", {}, (4, 4, 3))
    points = (tmp_path / "case" / "constant" / "polyMesh" / "points").read_text()
    assert f"\n{len(merged_mesh(block_set, tfi_blocks(block_set))[0])}\n(" in points
    assert (tmp_path / "case" / "system" / "fvSchemes").is_file()


# --- a resumed checkpoint's optimiser state ---------------------------------------------------


@pytest.fixture(scope="module")
def stopped_run(tmp_path_factory) -> Path:
    """A tiny semidisk run stopped in its Adam stage (optimiser state saved)."""
    folder = tmp_path_factory.mktemp("stopped") / "run"
    folder.mkdir()
    polls = iter(range(1000))
    train(tiny_config("lbfgs.steps=0"), load_geometry("semidisk"), folder, stop=lambda: next(polls) >= 6, summary=False)
    return folder


def _first_state(checkpoint) -> dict:
    return checkpoint["optimizer"]["state"][0]


def _poke(key: str, value: float):
    def damage(checkpoint):
        _first_state(checkpoint)[key].view(-1)[0] = value

    return damage


DAMAGED = {
    "shape": (lambda c: _first_state(c).__setitem__("exp_avg", torch.zeros(3, 3)), "shape (3, 3) for a parameter of shape"),
    "missing-moment": (lambda c: _first_state(c).pop("exp_avg_sq"), "lacks exp_avg_sq"),
    "missing-optimiser": (lambda c: c.pop("optimizer"), "lacks its training state's optimizer"),
    "missing-rng": (lambda c: c.pop("rng"), "lacks its training state's rng"),
    "nan": (_poke("exp_avg", float("nan")), "optimiser state holds non-finite numbers"),
    "inf": (_poke("exp_avg_sq", float("inf")), "optimiser state holds non-finite numbers"),
    "nan-lr": (lambda c: c["optimizer"]["param_groups"][0].__setitem__("lr", float("nan")), "non-finite"),
    "nan-reweighting": (lambda c: c["reweighting"]["log_a"].view(-1).__setitem__(0, float("nan")), "reweighting"),
}


@pytest.mark.parametrize("case", sorted(DAMAGED))
def test_a_damaged_optimiser_state_fails_before_the_run_folder_changes(stopped_run, tmp_path, run_cli, case):
    run = tmp_path / "run"
    shutil.copytree(stopped_run, run)
    checkpoint = torch.load(run / "checkpoint.pt", weights_only=True)
    assert checkpoint["stage"] == "adam" and checkpoint["optimizer"]["state"]
    damage, words = DAMAGED[case]
    damage(checkpoint)
    torch.save(checkpoint, run / "checkpoint.pt")
    before = snapshot(tmp_path)
    one_line_error(run_cli("train", "--resume", "run/checkpoint.pt", "--steps", 12, "-q"), words)
    assert snapshot(tmp_path) == before  # config.yaml, history.csv and the checkpoint as they were

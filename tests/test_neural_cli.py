"""``meshgen train`` end to end: a run folder, the final lines, Ctrl-C and --resume, and every bad
input (one-line error, exit 2, nothing written)."""

import csv
import signal
import subprocess
import sys
import time

import pytest
import torch
from helpers import files_in as snapshot
from neural_helpers import TINY, tiny_config

from meshgen.geometry.plugins import load_geometry
from meshgen.neural.checkpoint import load_checkpoint
from meshgen.neural.config import from_dict, preset_paths
from meshgen.neural.history import HISTORY_COLUMNS
from meshgen.neural.train import train

TINY_ARGS = [arg for item in TINY for arg in ("--set", item)]


@pytest.fixture(scope="module")
def semidisk_checkpoint(tmp_path_factory):
    """An interrupted tiny semidisk run, written in-process (the CLI writes the same files)."""
    folder = tmp_path_factory.mktemp("semidisk-run")
    train(tiny_config(), load_geometry("semidisk"), folder, stop=lambda: True, summary=False)
    return folder / "checkpoint.pt"


def test_train_writes_a_run_folder_and_says_how_to_mesh(run_cli, tmp_path):
    result = run_cli("train", "-g", "semidisk", "--preset", "2d", *TINY_ARGS, "--steps", "6", "--out", "run", "--quiet")
    assert result.returncode == 0, result.stderr
    run = tmp_path / "run"
    assert {p.name for p in run.iterdir()} == {"checkpoint.pt", "config.yaml", "history.csv", "summary.json"}
    with open(run / "history.csv", newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert tuple(rows[0]) == HISTORY_COLUMNS
    assert [int(r["step"]) for r in rows] == list(range(2 + 6 + 2))
    assert [r["stage"] for r in rows] == ["pretrain"] * 2 + ["adam"] * 6 + ["lbfgs"] * 2
    checkpoint = load_checkpoint(run / "checkpoint.pt")
    import yaml

    assert from_dict(yaml.safe_load((run / "config.yaml").read_text())) == from_dict(checkpoint["config"])
    assert checkpoint["config"]["adam"]["steps"] == 6 and checkpoint["config"]["dim"] == 2
    lines = result.stdout.strip().splitlines()
    assert "Network, 30 x 30 mesh:" in result.stdout and "TFI, 30 x 30 mesh:" in result.stdout
    assert (
        "boundary deviation from 'semidisk': max" in result.stdout
        and "Network corrected to N + TFI[g - N] (what meshgen mesh writes), 30 x 30 mesh:" in result.stdout
    )
    assert lines[-2] == f"Checkpoint: {run.relative_to(tmp_path) / 'checkpoint.pt'}"
    assert lines[-1].startswith("Mesh with: meshgen mesh") and "checkpoint.pt" in lines[-1]
    assert "Adam: 6 steps" in result.stderr  # --quiet: log lines, no progress bar


def test_list_presets_shows_one_line_each(run_cli):
    result = run_cli("train", "--list-presets")
    assert result.returncode == 0
    lines = result.stdout.strip().splitlines()
    assert [line.split()[0] for line in lines] == list(preset_paths())
    assert all(len(line.split(None, 1)) == 2 for line in lines)


@pytest.mark.slow
def test_ctrl_c_saves_a_checkpoint_and_resume_finishes_the_run(tmp_path):
    from conftest import REPO

    command = [
        sys.executable,
        "-m",
        "meshgen",
        "train",
        "-g",
        "semidisk",
        "--preset",
        "2d",
        *TINY_ARGS,
        "--set",
        "pretrain.steps=0",
        "--steps",
        "100000",
        "--out",
        "run",
        "--quiet",
    ]
    env = {"PYTHONPATH": str(REPO), "PATH": "/usr/bin:/bin"}
    process = subprocess.Popen(command, cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    history = tmp_path / "run" / "history.csv"
    deadline = time.time() + 60
    while time.time() < deadline and not (history.exists() and history.stat().st_size > 2000):
        time.sleep(0.1)
    process.send_signal(signal.SIGINT)
    stdout, stderr = process.communicate(timeout=60)
    assert process.returncode == 130, stderr
    assert "Interrupted at step" in stdout and "Continue with: meshgen train --resume run/checkpoint.pt" in stdout
    saved = load_checkpoint(tmp_path / "run" / "checkpoint.pt")
    assert saved["stage"] == "adam" and saved["step"] > 0
    stopped_at = saved["step"]

    from conftest import REPO as repo  # noqa: F811

    resumed = subprocess.run(
        [sys.executable, "-m", "meshgen", "train", "--resume", "run/checkpoint.pt", "--steps", str(stopped_at + 3), "-q"],
        cwd=tmp_path,
        env={"PYTHONPATH": str(repo), "PATH": "/usr/bin:/bin"},
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert resumed.returncode == 0, resumed.stderr
    final = load_checkpoint(tmp_path / "run" / "checkpoint.pt")
    assert final["stage"] == "done" and final["step"] == stopped_at + 3 + 2
    with open(history, newline="") as handle:
        steps = [int(row["step"]) for row in csv.DictReader(handle)]
    assert steps == list(range(stopped_at + 3 + 2))  # the rows after the checkpoint were dropped, none twice


BAD_INPUTS = [
    (["-g", "nosuch"], "unknown geometry 'nosuch'"),
    (["--preset", "nosuch"], "unknown preset 'nosuch'"),
    (["--config", "bad.yaml"], "bad.yaml is malformed YAML at line 3"),
    (["--set", "adam.stepz=3"], "unknown configuration key 'adam.stepz'; did you mean 'adam.steps'? (valid keys: "),
    (["--set", "adam.steps=many"], "configuration key 'adam.steps' must be an integer, got 'many'"),
    (["--preset", "2d", "-g", "semicylinder"], "preset '2d' is made for 2D geometries; 'semicylinder' is 3D"),
    (["--resume", "missing.pt"], "checkpoint missing.pt does not exist"),
    (["--resume", "truncated.pt"], "checkpoint truncated.pt is truncated or not a meshgen checkpoint"),
    (["--resume", "notes.pt"], "is truncated or not a meshgen checkpoint"),
    (["--resume", "semidisk.pt", "-g", "semicylinder"], "was trained on semidisk {'radius': 1.0}, not on semicylinder"),
    (
        ["--resume", "semidisk.pt", "--param", "radius=2"],
        "was trained on semidisk {'radius': 1.0}, not on semidisk {'radius': 2.0}",
    ),
    (["--resume", "semidisk.pt", "--set", "model.widths=[4]"], "--set model.widths cannot change when resuming"),
    (["--resume", "semidisk.pt", "--preset", "paper"], "--preset does not apply with --resume"),
    (["--out", "occupied"], "output folder occupied exists and is not a run folder"),
    (
        ["--device", "cuda"] if not torch.cuda.is_available() else ["--device", "tpu"],
        "cuda" if not torch.cuda.is_available() else "tpu",
    ),
]


@pytest.mark.parametrize("args, message", BAD_INPUTS, ids=[" ".join(a) for a, _ in BAD_INPUTS])
def test_bad_input_is_one_line_exit_2_and_writes_nothing(run_cli, tmp_path, semidisk_checkpoint, args, message):
    (tmp_path / "bad.yaml").write_text("adam:\n  steps: [1, 2\n")
    data = semidisk_checkpoint.read_bytes()
    (tmp_path / "semidisk.pt").write_bytes(data)
    (tmp_path / "truncated.pt").write_bytes(data[: len(data) // 3])
    (tmp_path / "notes.pt").write_text("my notes\n")
    (tmp_path / "occupied").mkdir()
    (tmp_path / "occupied" / "thesis.tex").write_text("important\n")
    before = snapshot(tmp_path)
    result = run_cli("train", *args, "--steps", "1")
    assert result.returncode == 2, result.stderr
    assert result.stderr.count("\n") == 1 and result.stderr.startswith("Error: "), result.stderr
    assert message in result.stderr
    assert snapshot(tmp_path) == before
    assert not (tmp_path / "runs").exists()

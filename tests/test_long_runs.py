"""Long runs are never silent and Ctrl-C keeps what is done: ``meshgen compare`` interrupted
after some methods finished prints and writes the table of those (exit status 130); ``meshgen
evaluate`` shows a progress bar at a terminal and nothing extra when piped; the progress of a
chunked run only grows, so its bar's clock keeps running through the quality phase."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from conftest import REPO
from terminal_helpers import run_in_terminal

from meshgen.formats import write_mesh
from meshgen.geometry.plugins import load_geometry
from meshgen.methods.clustering import node_coordinates
from meshgen.methods.tfi import tfi
from meshgen.quality import evaluate_file
from meshgen.run.chunked import run_fraction, tfi_array, write_chunked_mesh

HELPERS = Path(__file__).resolve().parent / "hardening_helpers.py"


def test_compare_interrupted_keeps_the_finished_rows(tmp_path):
    marker = tmp_path / "stalled"
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    env.pop("MESHGEN_DEBUG", None)
    command = [sys.executable, str(HELPERS), "make-mesh", str(marker), "2"]
    arguments = ["compare", "--methods", "tfi,elliptic", "--dims", "4", "4", "8", "--out", "out"]
    process = subprocess.Popen(
        [*command, *arguments], cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    try:
        deadline = time.time() + 120
        while not marker.exists():  # tfi has finished; elliptic waits before meshing
            assert process.poll() is None and time.time() < deadline, process.communicate()
            time.sleep(0.02)
        process.send_signal(signal.SIGINT)
        stdout, stderr = process.communicate(timeout=120)
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 130, stderr
    assert "Interrupted: not run: elliptic." in stderr and "Aborted" not in stderr
    table_lines = [line for line in stdout.splitlines() if "tfi" in line or "elliptic" in line]
    assert any("tfi" in line for line in table_lines) and not any("elliptic" in line for line in table_lines)
    recorded = json.loads((tmp_path / "out" / "compare.json").read_text())
    assert [row["name"] for row in recorded["rows"]] == ["tfi"]
    assert recorded["interrupted"] == {"not_run": ["elliptic"]}
    assert "elliptic" in (tmp_path / "out" / "compare.md").read_text()  # the note names what did not run
    # the finished row describes the mesh it wrote: the same figures evaluate measures on it
    measured = evaluate_file(tmp_path / "out" / "tfi.vtu")
    assert recorded["rows"][0]["quality"]["metrics"]["min_angle"]["mean"] == measured["metrics"]["min_angle"]["mean"]
    assert not (tmp_path / "out" / "elliptic.vtu").exists()


def test_chunked_run_progress_only_grows_to_its_end(tmp_path, semicylinder):
    dims = (6, 6, 12)
    X = tfi_array(semicylinder, node_coordinates(dims, ()), block_nodes=100)
    heard = []
    write_chunked_mesh(
        tmp_path / "m.cgns", X, semicylinder, progress=lambda done, total, phase: heard.append((done, total, phase))
    )
    assert X.npartitions > 2 and {phase for _, _, phase in heard} == {"mesh", "quality"}
    fractions = [run_fraction(done, total, phase, True) for done, total, phase in heard]
    assert all(b > a for a, b in zip(fractions, fractions[1:]))
    assert max(fractions[:-1]) < 1 and np.isclose(fractions[-1], 1.0)  # finished only at the very end
    mesh_only = [run_fraction(done, total, phase, False) for done, total, phase in heard if phase == "mesh"]
    assert np.isclose(mesh_only[-1], 1.0)


def test_evaluate_reports_progress(tmp_path):
    geometry = load_geometry("semicylinder")
    path = write_mesh(tmp_path / "m.vtu", tfi(geometry, (4, 4, 8)), metadata={"geometry": "semicylinder", "dims": [4, 4, 8]})
    heard = []
    evaluate_file(path, progress=lambda done, **figures: heard.append((done, figures.get("phase"))))
    assert [phase for _, phase in heard] == ["reading", "metrics", "report", "done"]
    assert [done for done, _ in heard] == sorted(done for done, _ in heard) and heard[-1][0] == 1.0


def test_evaluate_shows_a_bar_only_at_a_terminal(tmp_path, run_cli):
    geometry = load_geometry("semicylinder")
    write_mesh(tmp_path / "m.vtu", tfi(geometry, (4, 4, 8)))
    status, raw, _ = run_in_terminal(["evaluate", "m.vtu"], 120, tmp_path)
    assert status == 0 and "evaluating m.vtu" in raw
    piped = run_cli("evaluate", "m.vtu")
    assert piped.returncode == 0 and "evaluating" not in piped.stdout + piped.stderr

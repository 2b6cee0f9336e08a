"""The benchmark's Markdown summary (``benchmarks/run.py``) says where and on what it was measured
whichever sections ran: a run of one section (``--only airfoil``) names its commit and machine too."""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def benchmark_runner():
    spec = importlib.util.spec_from_file_location("benchmark_run", REPO / "benchmarks" / "run.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def results_without_machine(sections: dict) -> dict:
    return {
        "date": "2026-12-02T00:00:00+00:00",
        "command": "python benchmarks/run.py --only airfoil",
        "sections": sections,
        "load_average": {"start": [0.5, 0.5, 0.5], "end": [0.6, 0.5, 0.5]},
        "run": {"wall_seconds": 120.0},
        "summary": [],
    }


@pytest.mark.skipif(shutil.which("git") is None or not (REPO / ".git").exists(), reason="needs git and the repository")
def test_a_run_without_the_machine_section_names_its_commit_and_cores():
    text = benchmark_runner().markdown(results_without_machine({}))
    head = subprocess.run(["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    assert f"commit {head}" in text
    assert f"{len(os.sched_getaffinity(0))} cores" in text and " on ?," not in text

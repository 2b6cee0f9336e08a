"""Meshes larger than memory: throughput and peak memory of the block-wise (chunked) path.

    python benchmarks/bench_chunked.py [--quick] [--big-dims N] [--folder DIR] [--json FILE]
    python benchmarks/bench_chunked.py --only-openfoam [--openfoam-dims N] [--folder DIR] [--json FILE]

Each figure is a ``meshgen`` command run in a subprocess by a wrapper whose only child it is (wall
and CPU seconds from start to exit, peak resident memory from ``RUSAGE_CHILDREN``):

- the in-memory path and the chunked path at the same size (``--dims 200^3``; ``--quick`` 60^3),
  TFI to ``.cgns``, each with and without the quality report (``--no-quality``); node throughput
  is nodes per wall second, and the ratio is in-memory over chunked throughput (target:
  at most 1.5);
- the chunked path at ``--big-dims`` (default 400; ``--quick`` 80), TFI to ``.cgns`` with
  ``--no-quality``, then ``meshgen evaluate --chunked`` of that file, then with the quality report
  (its peak memory includes the quality phase); the bundled neural model in
  memory and in blocks at the same size (``--no-quality``);
- the 1000^3 rows are this with ``--big-dims 1000`` run by hand (about 24 GB on disk in
  ``--folder``, tens of minutes): not part of ``benchmarks/run.py``;
- a chunked mesh in a solver format: ``--chunked --format openfoam`` (binary polyMesh, streamed slab
  by slab through a scratch .cgns file) at ``--openfoam-dims`` (default 300; ``--quick`` 40) with
  ``--no-quality``, its peak memory, and OpenFOAM's ``checkMesh`` on the case ("Mesh OK"; skipped
  with the reason where OpenFOAM is not installed);
- GPU inference: skipped where torch sees no CUDA device (this machine), with the reason.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

BENCHMARKS = Path(__file__).resolve().parent
REPO = BENCHMARKS.parent
sys.path.insert(0, str(REPO))

_WRAPPER = """
import json, resource, subprocess, sys, time
start = time.perf_counter()
done = subprocess.run(sys.argv[1:], capture_output=True, text=True)
wall = time.perf_counter() - start
usage = resource.getrusage(resource.RUSAGE_CHILDREN)
print(json.dumps({"seconds": wall, "cpu_seconds": usage.ru_utime + usage.ru_stime, "peak_kib": usage.ru_maxrss,
                  "returncode": done.returncode, "stderr": done.stderr[-2000:]}))
"""


def run_command(arguments: list[str], folder: Path) -> dict:
    """``meshgen ARGUMENTS`` in ``folder``: wall and CPU seconds, peak resident memory (MB)."""
    environment = dict(os.environ)
    environment["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), environment.get("PYTHONPATH")]))
    command = [sys.executable, "-m", "meshgen", *arguments]
    result = subprocess.run(
        [sys.executable, "-c", _WRAPPER, *command], cwd=folder, env=environment, check=True, capture_output=True, text=True
    )
    figures = json.loads(result.stdout.strip().splitlines()[-1])
    if figures["returncode"] != 0:
        raise RuntimeError(f"meshgen {' '.join(arguments)} failed: {figures['stderr']}")
    return {
        "command": "meshgen " + " ".join(arguments),
        "seconds": figures["seconds"],
        "cpu_seconds": figures["cpu_seconds"],
        "peak_megabytes": figures["peak_kib"] * 1024 / 1e6,
    }


def mesh_row(method: str, cells: int, mode: str, quality: bool, folder: Path) -> dict:
    output = folder / f"{method}-{cells}{mode}.cgns"
    arguments = ["mesh", "-m", method, "--dims", *[str(cells)] * 3, mode, "-o", str(output), "-q"]
    if not quality:
        arguments.append("--no-quality")
    row = run_command(arguments, folder)
    nodes = (cells + 1) ** 3
    row.update(
        method=method,
        cells_per_axis=cells,
        nodes=nodes,
        path=mode.lstrip("-"),
        quality=quality,
        nodes_per_second=nodes / row["seconds"],
        megabytes_written=output.stat().st_size / 1e6,
    )
    return row


# checkMesh's peak memory per cell, measured: 644 MB for 1e6 hexahedra, 4.7 GB for 8e6, 15.1 GB for 2.7e7.
CHECK_MESH_BYTES_PER_CELL = 600


def check_mesh(case: Path, cells: int) -> dict:
    """OpenFOAM's ``checkMesh`` on ``case`` of ``cells`` cells: {"mesh_ok", "seconds",
    "peak_megabytes"}, or {"skipped"} without OpenFOAM or where it would need more than 90 % of
    the memory available now. It runs first in line for the kernel's out-of-memory killer, so a
    shared machine's other work is not what a shortfall kills."""
    import shutil

    from meshgen.run.resources import available_memory

    if shutil.which("checkMesh") is None:
        return {"skipped": "OpenFOAM's checkMesh is not installed (Debian package openfoam)"}
    need, available = CHECK_MESH_BYTES_PER_CELL * cells, available_memory()
    if need > 0.9 * available:
        return {"skipped": f"checkMesh would need about {need / 1e9:.0f} GB, {available / 1e9:.0f} GB available"}
    bashrc = next(
        (p for p in ("/usr/share/openfoam/etc/bashrc", "/usr/lib/openfoam/openfoam/etc/bashrc") if Path(p).is_file()), None
    )
    script = (
        f"source {bashrc} >/dev/null 2>&1; " if bashrc else ""
    ) + f"echo 1000 > /proc/self/oom_score_adj; exec checkMesh -case '{case}'"
    wrapped = [sys.executable, "-c", _WRAPPER, "bash", "-c", script]
    figures = json.loads(subprocess.run(wrapped, capture_output=True, text=True, check=True).stdout.strip().splitlines()[-1])
    log = subprocess.run(["bash", "-c", script], capture_output=True, text=True) if figures["returncode"] == 0 else None
    return {
        "mesh_ok": figures["returncode"] == 0 and log is not None and "Mesh OK." in log.stdout,
        "seconds": figures["seconds"],
        "peak_megabytes": figures["peak_kib"] * 1024 / 1e6,
    }


def openfoam_row(cells: int, folder: Path) -> dict:
    """``meshgen mesh -m tfi --dims cells^3 --chunked --no-quality --format openfoam``: time, peak
    memory, the case's size on disk, then checkMesh on it."""
    case = folder / f"case-{cells}"
    row = run_command(
        [
            "mesh",
            "-m",
            "tfi",
            "--dims",
            *[str(cells)] * 3,
            "--chunked",
            "--no-quality",
            "--format",
            "openfoam",
            "-o",
            str(case),
            "-q",
        ],
        folder,
    )
    row.update(cells_per_axis=cells, megabytes_written=sum(p.stat().st_size for p in case.rglob("*") if p.is_file()) / 1e6)
    row["check_mesh"] = check_mesh(case, cells**3)
    return row


GPU_NODES = 501  # per axis: 1.26e8 nodes, 3 GB of float64 coordinates on the host
GPU_WIDTHS = [85, 85, 85, 85]


def gpu_row(repeats: int = 3) -> dict:
    """The [85]*4 network (random weights) over 501^3 nodes on the GPU, the nodes copied back into
    one float64 host array (``evaluate_on_grid(device="cuda")``, what ``meshgen mesh --device cuda``
    runs): median of ``repeats`` after a warm-up. Skipped where torch sees no CUDA device."""
    import numpy as np
    import torch

    if not torch.cuda.is_available():
        return {"skipped": "no CUDA device on this machine (torch.cuda.is_available() is False)"}
    from meshgen.neural.gpu_forward import evaluate_on_grid
    from meshgen.neural.model import MLP, describe

    torch.manual_seed(0)
    model = describe(MLP(3, GPU_WIDTHS), GPU_WIDTHS, False, [0.0, 0.0, 0.0], 1.0)
    coords = [np.linspace(0.0, 1.0, GPU_NODES)] * 3
    out = np.empty((GPU_NODES**3, 3))
    evaluate_on_grid(model, [c[:101] for c in coords], device="cuda")  # warm-up: context, kernels
    seconds = []
    for _ in range(repeats):
        start = time.perf_counter()
        evaluate_on_grid(model, coords, out=out, device="cuda")
        torch.cuda.synchronize()
        seconds.append(time.perf_counter() - start)
    return {
        "nodes_per_axis": GPU_NODES,
        "widths": GPU_WIDTHS,
        "device": torch.cuda.get_device_name(0),
        "seconds": sorted(seconds)[len(seconds) // 2],
        "all_seconds": seconds,
    }


def measure(quick: bool, big_dims: int | None = None, folder: Path | None = None, openfoam_dims: int | None = None) -> dict:
    same = 60 if quick else 200
    big = big_dims or (80 if quick else 400)
    with tempfile.TemporaryDirectory(dir=folder) as temporary:
        temporary = Path(temporary)
        openfoam = openfoam_row(openfoam_dims or (40 if quick else 300), temporary)
        print(
            f"  {openfoam['command']}: {openfoam['seconds']:.1f} s, peak {openfoam['peak_megabytes']:.0f} MB; "
            f"checkMesh: {openfoam['check_mesh']}",
            flush=True,
        )
        import shutil

        shutil.rmtree(temporary / f"case-{openfoam['cells_per_axis']}")
        rows = []
        for quality in (True, False):
            for mode in ("--in-memory", "--chunked"):
                rows.append(mesh_row("tfi", same, mode, quality, temporary))
                print(
                    f"  {rows[-1]['command']}: {rows[-1]['seconds']:.1f} s, {rows[-1]['nodes_per_second'] / 1e6:.2f} M nodes/s, "
                    f"peak {rows[-1]['peak_megabytes']:.0f} MB",
                    flush=True,
                )
                (temporary / f"tfi-{same}{mode}.cgns").unlink()
        for mode in ("--in-memory", "--chunked"):
            rows.append(mesh_row("neural", same, mode, False, temporary))
            print(
                f"  {rows[-1]['command']}: {rows[-1]['seconds']:.1f} s, {rows[-1]['nodes_per_second'] / 1e6:.2f} M nodes/s, "
                f"peak {rows[-1]['peak_megabytes']:.0f} MB",
                flush=True,
            )
            (temporary / f"neural-{same}{mode}.cgns").unlink()
        big_row = mesh_row("tfi", big, "--chunked", False, temporary)
        print(
            f"  {big_row['command']}: {big_row['seconds']:.1f} s, {big_row['nodes_per_second'] / 1e6:.2f} M nodes/s, "
            f"peak {big_row['peak_megabytes']:.0f} MB",
            flush=True,
        )
        evaluate_row = run_command(["evaluate", str(temporary / f"tfi-{big}--chunked.cgns"), "--chunked", "-q"], temporary)
        (temporary / f"tfi-{big}--chunked.cgns").unlink()
        big_quality_row = mesh_row("tfi", big, "--chunked", True, temporary)  # the quality phase's memory included
        print(
            f"  {big_quality_row['command']}: {big_quality_row['seconds']:.1f} s, peak {big_quality_row['peak_megabytes']:.0f} MB",
            flush=True,
        )
        evaluate_row.update(cells=big**3, cells_per_second=big**3 / evaluate_row["seconds"])
        print(
            f"  {evaluate_row['command']}: {evaluate_row['seconds']:.1f} s, peak {evaluate_row['peak_megabytes']:.0f} MB",
            flush=True,
        )

    def throughput(path, quality, method="tfi"):
        return next(
            r["nodes_per_second"] for r in rows if r["method"] == method and r["path"] == path and r["quality"] == quality
        )

    ratios = {
        ("with_quality" if quality else "without_quality"): throughput("in-memory", quality) / throughput("chunked", quality)
        for quality in (True, False)
    }
    ratios["neural_without_quality"] = throughput("in-memory", False, "neural") / throughput("chunked", False, "neural")
    return {
        "same_size_cells_per_axis": same,
        "big_cells_per_axis": big,
        "rows": rows,
        "big": big_row,
        "evaluate_big": evaluate_row,
        "big_quality": big_quality_row,
        "throughput_ratio_in_memory_over_chunked": ratios,
        "big_over_same_size_in_memory_ratio": throughput("in-memory", False) / big_row["nodes_per_second"],
        "openfoam": openfoam,
        "gpu_inference": gpu_row(),
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="60^3 and 80^3 instead of 200^3 and 400^3")
    parser.add_argument("--big-dims", type=int, default=None, help="cells per axis of the large chunked run (1000: by hand)")
    parser.add_argument("--folder", type=Path, default=None, help="where the files go (needs (N+1)^3 * 24 bytes free)")
    parser.add_argument("--openfoam-dims", type=int, default=None, help="cells per axis of the chunked OpenFOAM case (300)")
    parser.add_argument("--only-openfoam", action="store_true", help="only the chunked OpenFOAM row")
    parser.add_argument("--json", type=Path, default=None, help="write the figures here")
    args = parser.parse_args()
    if args.only_openfoam:
        with tempfile.TemporaryDirectory(dir=args.folder) as temporary:
            row = openfoam_row(args.openfoam_dims or (40 if args.quick else 300), Path(temporary))
        print(json.dumps(row, indent=2))
        if args.json:
            args.json.write_text(json.dumps(row, indent=2) + "\n")
        return
    data = measure(args.quick, args.big_dims, args.folder, args.openfoam_dims)
    print(json.dumps(data["throughput_ratio_in_memory_over_chunked"]))
    if args.json:
        args.json.write_text(json.dumps(data, indent=2) + "\n")


if __name__ == "__main__":
    main()

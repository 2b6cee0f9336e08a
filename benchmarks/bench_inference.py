"""Benchmark meshing with a trained model: the forward pass, the whole command, and its memory.

    python benchmarks/bench_inference.py [--quick] [--json FILE]

Figures (targets for a 2-core CPU):

- inference: ``meshgen.neural.gpu_forward.evaluate_on_grid`` on 101^3 nodes through a random
  [85]*4 tanh network, median of 5 (target 0.6 s), next to the float32 matrix-product roof: the
  network's flop count divided by the GFLOP/s of a large sgemm measured here;
- end to end: ``meshgen mesh --dims 100 100 100 -o out.vtu`` in a fresh folder (no ./runs/, so
  the bundled model), a subprocess timed from start to exit including ``import torch``, quality
  and writing, median of 3 (target 5 s);
- memory: peak resident memory (ru_maxrss) of ``meshgen mesh --dims 200 200 200 -o out.vtu``
  (target 6 GB).

--quick: inference median of 3, one end-to-end run, memory of a 100^3 mesh (its target not judged).
Prints a table with the targets and writes the figures as JSON with --json.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

TARGETS = {"inference_seconds": 0.6, "end_to_end_seconds": 5.0, "peak_memory_gb": 6.0}
WIDTHS = [85, 85, 85, 85]
NODES = 101


def matmul_rates(size: int = 4096, repeats: int = 5) -> dict:
    """float32 GFLOP/s of a size x size product with torch (MKL/OpenBLAS sgemm, torch's threads),
    best of ``repeats``: the roof a network's forward pass is compared with. Also per CPU second
    (all threads) of that run: the per-core rate, which the load of a shared machine changes less."""
    import torch

    a, b = torch.randn(size, size), torch.randn(size, size)
    a @ b  # warm up: threads, allocator
    flop = 2.0 * size**3
    best_wall, cpu_of_best = float("inf"), float("inf")
    for _ in range(repeats):
        wall, cpu = time.perf_counter(), time.process_time()
        a @ b
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        if wall < best_wall:
            best_wall, cpu_of_best = wall, cpu
    return {
        "size": size,
        "repeats": repeats,
        "threads": torch.get_num_threads(),
        "gflops": flop / best_wall / 1e9,
        "gflops_per_cpu_second": flop / max(cpu_of_best, 1e-9) / 1e9,
        "best_seconds": best_wall,
    }


def matmul_roof(size: int = 4096, repeats: int = 5) -> float:
    """float32 GFLOP/s of a size x size product, best of ``repeats`` (see ``matmul_rates``)."""
    return matmul_rates(size, repeats)["gflops"]


def network_flops(widths, dim: int, nodes: int) -> float:
    sizes = [dim, *widths, dim]
    return 2.0 * nodes * sum(a * b for a, b in zip(sizes[:-1], sizes[1:]))


def inference_seconds(repeats: int) -> list[float]:
    import torch

    from meshgen.neural.gpu_forward import evaluate_on_grid
    from meshgen.neural.model import MLP, describe

    torch.manual_seed(0)
    model = describe(MLP(3, WIDTHS), WIDTHS, False, [0.0, 0.0, 0.0], 1.0)
    coords = [np.linspace(0.0, 1.0, NODES)] * 3
    evaluate_on_grid(model, coords)  # warm-up: threads, allocator
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        evaluate_on_grid(model, coords)
        times.append(time.perf_counter() - start)
    return times


_WRAPPER = """
import json, resource, subprocess, sys, threading, time

def resident_kib(pid):
    try:
        with open(f"/proc/{pid}/status") as handle:
            return next(int(line.split()[1]) for line in handle if line.startswith("VmRSS:"))
    except (OSError, StopIteration, ValueError):
        return 0

def process_tree(pid):
    try:
        with open(f"/proc/{pid}/task/{pid}/children") as handle:
            children = [int(child) for child in handle.read().split()]
    except OSError:
        children = []
    return [pid, *children]

start = time.perf_counter()
process = subprocess.Popen(sys.argv[1:])
peak_sum = [0]

def sample():
    while process.poll() is None:
        peak_sum[0] = max(peak_sum[0], sum(resident_kib(pid) for pid in process_tree(process.pid)))
        time.sleep(0.02)

sampler = threading.Thread(target=sample, daemon=True)
sampler.start()
if process.wait() != 0:
    sys.exit(process.returncode)
wall = time.perf_counter() - start
sampler.join()
usage = resource.getrusage(resource.RUSAGE_CHILDREN)
print(json.dumps({"seconds": wall, "cpu_seconds": usage.ru_utime + usage.ru_stime, "peak_kib": usage.ru_maxrss,
                  "peak_sum_kib": peak_sum[0]}))
"""


def mesh_command(cells: int, folder: Path, environment: dict | None = None, options=()) -> dict:
    """Run ``meshgen mesh --dims cells^3 -o out.vtu -q [options]`` in ``folder`` (with ``environment``,
    default this process's, and this checkout first on PYTHONPATH) by a wrapper process whose only
    child it is. Returns its wall and CPU seconds from start to exit (``import torch``, meshing,
    quality, writing), its peak resident memory: the larger of the largest process's (ru_maxrss of
    the wrapper's RUSAGE_CHILDREN: this process's would mix in earlier children) and the sum over
    the command and its children (the quality worker), sampled every 20 ms (shared memory counted
    in each process that maps it: an upper bound), the size of the file written and whether the
    mesh was polished (its sidecar's record)."""
    environment = dict(os.environ if environment is None else environment)
    environment["PYTHONPATH"] = os.pathsep.join(filter(None, [str(REPO), environment.get("PYTHONPATH")]))
    command = [sys.executable, "-m", "meshgen", "mesh", "--dims", *[str(cells)] * 3, "-o", "out.vtu", "-q", *options]
    result = subprocess.run(
        [sys.executable, "-c", _WRAPPER, *command], cwd=folder, env=environment, check=True, capture_output=True, text=True
    )
    figures = json.loads(result.stdout.strip().splitlines()[-1])
    return {
        "seconds": figures["seconds"],
        "cpu_seconds": figures["cpu_seconds"],
        "peak_megabytes": max(figures["peak_kib"], figures["peak_sum_kib"]) * 1024 / 1e6,  # KiB on Linux
        "largest_process_megabytes": figures["peak_kib"] * 1024 / 1e6,
        "megabytes_written": (Path(folder) / "out.vtu").stat().st_size / 1e6,
        "polished": bool(_sidecar_polish(Path(folder) / "out.vtu.quality.json").get("polished", False)),
    }


def _sidecar_polish(sidecar: Path) -> dict:
    """The ``method_info.polish`` record of a quality sidecar ({} where there is none)."""
    return json.loads(sidecar.read_text()).get("method_info", {}).get("polish", {}) if sidecar.is_file() else {}


def run_mesh(cells: int, folder: Path) -> float:
    """Wall seconds of ``meshgen mesh --dims cells^3 -o out.vtu`` run in ``folder``."""
    return mesh_command(cells, folder)["seconds"]


def peak_memory_gb(cells: int, folder: Path) -> float:
    """Peak resident memory (GB) of ``meshgen mesh --dims cells^3`` (see ``mesh_command``)."""
    return mesh_command(cells, folder)["peak_megabytes"] / 1e3


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats, memory of 100^3 instead of 200^3")
    parser.add_argument("--json", type=Path, default=None, help="write the figures here")
    args = parser.parse_args()

    import torch

    gflops = matmul_roof()
    flops = network_flops(WIDTHS, 3, NODES**3)
    times = inference_seconds(3 if args.quick else 5)
    inference = float(np.median(times))
    roof_seconds = flops / (gflops * 1e9)
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        run_mesh(10, folder)  # warm the file cache (torch's libraries) for the timed runs
        end_to_end = [run_mesh(100, folder) for _ in range(1 if args.quick else 3)]
        memory_cells = 100 if args.quick else 200
        memory = peak_memory_gb(memory_cells, folder)
    figures = {
        "machine": {
            "cpus": os.cpu_count(),
            "torch_threads": torch.get_num_threads(),
            "python": platform.python_version(),
            "torch": torch.__version__,
            "processor": platform.processor() or platform.machine(),
        },
        "matmul_gflops": gflops,
        "network": {"widths": WIDTHS, "nodes": NODES**3, "gflop": flops / 1e9},
        "inference_seconds": inference,
        "inference_runs": times,
        "roof_seconds": roof_seconds,
        "fraction_of_roof": roof_seconds / inference,
        "end_to_end_seconds": float(np.median(end_to_end)),
        "end_to_end_runs": end_to_end,
        "peak_memory_gb": memory,
        "peak_memory_cells": memory_cells,
        "quick": args.quick,
    }
    rows = [
        (
            "inference, 101^3 nodes, [85]*4",
            f"{inference:.3f} s",
            f"<= {TARGETS['inference_seconds']} s",
            inference <= TARGETS["inference_seconds"],
        ),
        (
            "  matmul roof",
            f"{roof_seconds:.3f} s",
            f"{gflops:.0f} GFLOP/s; inference at {100 * roof_seconds / inference:.0f}% of it",
            None,
        ),
        (
            "meshgen mesh --dims 100 100 100",
            f"{figures['end_to_end_seconds']:.2f} s",
            f"<= {TARGETS['end_to_end_seconds']} s",
            figures["end_to_end_seconds"] <= TARGETS["end_to_end_seconds"],
        ),
        (
            f"peak memory, {memory_cells}^3 mesh",
            f"{memory:.2f} GB",
            f"< {TARGETS['peak_memory_gb']} GB (200^3)",
            memory < TARGETS["peak_memory_gb"] if memory_cells == 200 else None,
        ),
    ]
    width = max(len(r[0]) for r in rows)
    print(f"{'figure':<{width}}  {'measured':>10}  target")
    for name, value, target, met in rows:
        verdict = "" if met is None else ("  met" if met else "  NOT MET")
        print(f"{name:<{width}}  {value:>10}  {target}{verdict}")
    figures["met"] = {row[0]: row[3] for row in rows if row[3] is not None}
    if args.json:
        args.json.write_text(json.dumps(figures, indent=2) + "\n")


if __name__ == "__main__":
    main()

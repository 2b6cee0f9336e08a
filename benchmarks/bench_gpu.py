"""The GPU rows of meshgen, each with the CPU row of the same run beside it:

- ``elliptic``: the elliptic semicylinder at 100^3 cells by the torch multigrid on the device,
  against the CPU solver's mesh and time (``bench_elliptic.gpu_elliptic_row``);
- ``quality``: the seven per-cell metrics and their summary of 1e9 hexahedra, made slab by slab on
  the device (``bench_quality.gpu_quality_row``), a sub-block checked against the numba kernels;
- ``neural``: 1e9 hexahedra of a 3D semicylinder network (0.2's bundled model, ``THREE_D``) made, boundary-corrected and
  quality-checked on the device slab by slab (``meshgen.neural.gpu_mesh``), the copy of the nodes
  to the host (what writing would start from) timed apart; a sub-block checked against the CPU
  path's nodes; the CPU path's rate at 200^3 beside it;
- ``training``: ``meshgen train --preset exact`` on the GPU and on 8 host threads, side by side
  in the same run, and the pipe block set on the GPU (time-capped): training seconds, test loss,
  mean minimum angle.

    python benchmarks/bench_gpu.py [--device cuda] [--cells 1000] [--only ROW ...] [--json FILE]

Without a CUDA device every row is skipped with the reason; ``--device cpu`` with small
``--cells`` runs the same code on the CPU (a check of the script, not a figure).
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

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402

ROWS = ("elliptic", "quality", "neural", "training")
# 0.2's bundled semicylinder model, a 3D network (the slab mesher's case; today's bundled model is a section)
THREE_D = Path(__file__).resolve().parents[1] / "tests" / "data" / "semicylinder-3d-model.pt"
NEURAL_CHECK_PLANES = 4  # cell planes of the neural mesh compared with the CPU path's nodes and metrics


def cuda_reason() -> str | None:
    """None where torch sees a CUDA device, else why the rows are skipped."""
    import torch

    if not torch.cuda.is_available():
        return "no CUDA device on this machine (torch.cuda.is_available() is False)"
    return None


def synchronize(device: str) -> None:
    import torch

    if device == "cuda":
        torch.cuda.synchronize()


def device_name(device: str) -> str:
    import torch

    if device == "cuda":
        return torch.cuda.get_device_name(0)
    import platform

    return f"CPU ({platform.processor() or platform.machine()}, {os.cpu_count()} cores)"


def _owned(slab_iterator):
    """``meshgen.neural.gpu_mesh.slabs``' (i0, i1, first, X) as ``summarise_hex_torch``'s (X, first, last)."""
    for i0, i1, first, X in slab_iterator:
        yield X, first, first + i1 - i0


def neural_row(cells: int = 1000, device: str = "cuda", planes: int | None = None) -> dict:
    """A 3D semicylinder network's mesh (``THREE_D``: the bundled model is a section network, which
    meshgen extrudes) of ``cells``^3 hexahedra made, corrected and
    quality-checked on ``device`` slab by slab (``seconds``, the setup of the face data on the host
    included); the mesh alone timed in a second pass; then the copy of every node plane into one
    host array (where a writer would start), timed apart; a sub-block against the CPU path."""
    import torch

    from meshgen.geometry.plugins import load_geometry
    from meshgen.methods.tfi import parametric_grid
    from meshgen.neural.gpu_mesh import SLAB_PLANES, SlabMesher, slabs
    from meshgen.neural.models import load_model
    from meshgen.quality.torch_kernels import report_summaries, summarise_hex_torch

    planes = planes or SLAB_PLANES
    geometry = load_geometry("semicylinder")
    model = load_model(THREE_D).checkpoint["model"]
    coords = parametric_grid([cells] * 3)
    small = SlabMesher(model, geometry, parametric_grid([16] * 3), device)  # warm-up: context, cuBLAS, kernels
    summarise_hex_torch(_owned(slabs(small, 8)), small.tolerance)
    if device == "cuda":
        torch.cuda.reset_peak_memory_stats()
    synchronize(device)

    start = time.perf_counter()
    mesher = SlabMesher(model, geometry, coords, device)
    synchronize(device)
    setup = time.perf_counter() - start
    summary = summarise_hex_torch(_owned(slabs(mesher, planes)), mesher.tolerance)
    synchronize(device)
    total = time.perf_counter() - start
    figures = report_summaries(summary)

    start = time.perf_counter()
    for _ in slabs(mesher, planes):  # the mesh alone
        pass
    synchronize(device)
    mesh_only = time.perf_counter() - start

    host = np.empty((cells + 1, cells + 1, cells + 1, 3))
    copy_seconds = 0.0
    for i0, i1, first, X in slabs(mesher, planes):
        owned = X[first : first + i1 - i0 + (1 if i1 == cells else 0)]
        synchronize(device)
        begin = time.perf_counter()
        torch.from_numpy(host[i0 : i0 + owned.shape[0]]).copy_(owned)
        copy_seconds += time.perf_counter() - begin
    return {
        "cells": cells**3,
        "device": device_name(device),
        "slab_planes": planes,
        "seconds": total,
        "setup_seconds": setup,
        "mesh_only_seconds": mesh_only,
        "copy_to_host_seconds": copy_seconds,
        "inverted": summary["inverted"],
        "degenerate": summary["degenerate"],
        "min_angle_mean": figures["min_angle"]["mean"],
        "scaled_jacobian_min": figures["scaled_jacobian"]["min"],
        "correction": mesher.info,
        "check": _neural_check(model, geometry, coords, host),
        "peak_device_gigabytes": torch.cuda.max_memory_allocated() / 1e9 if device == "cuda" else None,
    }


def _neural_check(model, geometry, coords, host) -> dict:
    """The first ``NEURAL_CHECK_PLANES`` cell planes of the device's nodes against the CPU path's
    (``meshgen.run.chunked.neural_array``: the float32 network by numba, the rest in float64)."""
    from meshgen.run.chunked import neural_array

    planes = NEURAL_CHECK_PLANES + 1
    X = neural_array(model, geometry, coords)[0][:planes].compute()
    return {
        "planes": NEURAL_CHECK_PLANES,
        "max_node_difference_over_length": float(np.abs(host[:planes] - X).max() / geometry.characteristic_length),
    }


def cpu_quality_rate(cells: int = 200, repeat: int = 3) -> dict:
    """The numba kernels (``meshgen.quality.compiled.structured_hex``, every core) on the analytic
    mesh of ``bench_quality_gpu`` at ``cells``^3: cells per second, best of ``repeat``."""
    from bench_quality_gpu import shell_nodes

    from meshgen.quality.compiled import structured_hex
    from meshgen.quality.kernels import METRICS

    X = np.ascontiguousarray(shell_nodes(cells, 0, cells + 1, "cpu").numpy())
    count = cells**3
    out, degenerate = np.empty((len(METRICS), count)), np.empty(count, dtype=bool)
    structured_hex(X, (0, 0, 0), (cells,) * 3, 1e-12, out, degenerate)  # compiled code loaded
    seconds = []
    for _ in range(repeat):
        start = time.perf_counter()
        structured_hex(X, (0, 0, 0), (cells,) * 3, 1e-12, out, degenerate)
        seconds.append(time.perf_counter() - start)
    return {"cells": count, "seconds": min(seconds), "cells_per_second": count / min(seconds), "cores": os.cpu_count()}


def cpu_neural_rate(cells: int = 200) -> dict:
    """The CPU path's neural mesh (``THREE_D``'s network, corrected; ``make_mesh``) and the seven metrics of
    its cells by the numba kernels, in memory at ``cells``^3 on this machine's cores: cells per
    second of both together."""
    from meshgen.geometry.plugins import load_geometry
    from meshgen.methods.registry import make_mesh
    from meshgen.methods.tfi import parametric_grid
    from meshgen.neural.models import load_model
    from meshgen.quality.compiled import structured_hex
    from meshgen.quality.kernels import METRICS

    geometry = load_geometry("semicylinder")
    model = load_model(THREE_D)
    make_mesh("neural", geometry, parametric_grid([20] * 3), model=model)  # warm-up: kernels loaded
    count = cells**3
    out, degenerate = np.empty((len(METRICS), count)), np.empty(count, dtype=bool)
    start = time.perf_counter()
    X, _ = make_mesh("neural", geometry, parametric_grid([cells] * 3), model=model)
    structured_hex(np.ascontiguousarray(X), (0, 0, 0), (cells,) * 3, 1e-12, out, degenerate)
    seconds = time.perf_counter() - start
    return {"cells": count, "seconds": seconds, "cells_per_second": count / seconds, "cores": os.cpu_count()}


def _train(arguments: list[str], folder: Path, timeout: float) -> dict:
    """``meshgen train ARGUMENTS --out FOLDER -q`` in a subprocess: wall seconds and the run's
    summary (training seconds, test loss, mean minimum angle of its 30^3 mesh)."""
    command = [sys.executable, "-m", "meshgen", "train", *arguments, "--out", str(folder), "-q"]
    start = time.perf_counter()
    try:
        done = subprocess.run(command, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"command": " ".join(command[2:]), "timed_out_after": timeout}
    wall = time.perf_counter() - start
    row = {"command": " ".join(command[2:]), "wall_seconds": wall, "returncode": done.returncode}
    summary = folder / "summary.json"
    if done.returncode or not summary.is_file():
        row["error"] = (done.stderr or done.stdout)[-800:]
        return row
    data = json.loads(summary.read_text())
    row.update(
        training_seconds=data.get("training_seconds"),
        test_loss=data.get("test_loss"),
        min_angle_mean=data.get("network", {}).get("metrics", {}).get("min_angle", {}).get("mean"),
    )
    return row


def training_rows(timeout: float = 240.0, pipe: bool = False) -> dict:
    """``exact`` on the GPU and on 8 host threads at once (side by side: the same run, the same
    machine), and with ``pipe`` then the pipe block set on the GPU alone, each capped at
    ``timeout`` seconds."""
    with tempfile.TemporaryDirectory() as scratch:
        scratch = Path(scratch)
        exact = ["-g", "semicylinder", "--preset", "exact", "--seed", "0"]
        from concurrent.futures import ThreadPoolExecutor

        with ThreadPoolExecutor(2) as pool:
            gpu = pool.submit(_train, [*exact, "--device", "cuda"], scratch / "exact-gpu", timeout)
            cpu = pool.submit(_train, [*exact, "--device", "cpu", "--threads", "8"], scratch / "exact-cpu", timeout)
            rows = {"exact_gpu": gpu.result(), "exact_cpu_8_threads": cpu.result()}
        if pipe:
            rows["pipe_gpu"] = _train(["-g", "pipe", "--device", "cuda", "--seed", "0"], scratch / "pipe-gpu", timeout)
    return rows


def measure(
    rows=ROWS, device: str = "cuda", cells: int = 1000, elliptic_n: int = 100, timeout: float = 240.0, json_path=None
) -> dict:
    """The chosen rows as a JSON-ready dict; every row skipped with the reason where ``device`` is
    cuda and torch sees none. ``json_path``: written again after each row (a run cut short keeps
    the rows it finished)."""
    if device == "cuda" and (reason := cuda_reason()):
        return {"skipped": reason}
    import torch

    results = {
        "device": device_name(device),
        "host_cpus": os.cpu_count(),
        "versions": {"torch": torch.__version__, "numpy": np.__version__, "python": sys.version.split()[0]},
    }
    for name in rows:
        start = time.perf_counter()
        try:
            if name == "elliptic":
                from bench_elliptic import gpu_elliptic_row

                results[name] = gpu_elliptic_row(elliptic_n, device=device)
            elif name == "quality":
                from bench_quality_gpu import gpu_quality_row

                results[name] = gpu_quality_row(cells, device=device)
                results[name]["cpu"] = cpu_quality_rate(min(cells, 200))
            elif name == "neural":
                results[name] = neural_row(cells, device)
                results[name]["cpu"] = cpu_neural_rate(min(cells, 200))
            elif name == "training":
                results[name] = training_rows(timeout)
        except Exception as error:  # a row that breaks is reported and the others still run
            import traceback

            results[name] = {"error": f"{type(error).__name__}: {error}", "traceback": traceback.format_exc()[-2000:]}
        print(f"{name} ({time.perf_counter() - start:.1f} s): {json.dumps(results[name], default=str)[:1500]}", flush=True)
        if json_path:
            Path(json_path).write_text(json.dumps(results, indent=2, default=str))
    return results


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cuda", choices=["cuda", "cpu"])
    parser.add_argument("--cells", type=int, default=1000, help="cells per axis of the quality and neural rows")
    parser.add_argument("--elliptic", type=int, default=100, help="cells per axis of the elliptic row")
    parser.add_argument("--timeout", type=float, default=240.0, help="cap of each training run, seconds")
    parser.add_argument("--only", choices=ROWS, action="append")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    measure(args.only or ROWS, args.device, args.cells, args.elliptic, args.timeout, args.json)


if __name__ == "__main__":
    main()

"""Benchmark: the quality summary of 1e9 hexahedra on one GPU (target: at most 60 s), and torch's
CPU device against the compiled numba kernels.

    python benchmarks/bench_quality_gpu.py [--cells-per-side 1000] [--device cuda] [--json FILE]
    python benchmarks/bench_quality_gpu.py --cpu-compare 100     # torch CPU vs numba, 100^3 cells

``gpu_quality_row`` builds an analytic mesh (a sheared, twisted thick cylindrical shell with a
deterministic per-node wobble of 0.15 cell, so the metrics spread) slab by slab on the device
from index arithmetic (no host transfer), takes its bounding box in a first pass (the
degenerate-edge tolerance), then summarises it (``meshgen.quality.torch_kernels.summarise_hex_torch``)
and checks a sub-block against the numba kernel on the same nodes (copied to the host).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from meshgen.quality.kernels import METRICS  # noqa: E402
from meshgen.quality.structured import box_tolerance  # noqa: E402

__all__ = ["cpu_compare", "gpu_quality_row", "shell_nodes"]


def shell_nodes(n: int, i0: int, i1: int, device, wobble: float = 0.15):
    """Node planes i0 <= i < i1 (and all j, k) of the analytic (n+1)^3-node mesh, float64 (i1-i0, n+1, n+1, 3)
    on ``device``: a thick cylindrical shell sheared and twisted, each node moved by up to ``wobble``
    cell sizes along a pseudo-random direction from its indices."""
    import torch

    options = {"dtype": torch.float64, "device": device}
    i = torch.arange(i0, i1, **options)[:, None, None]
    j = torch.arange(n + 1, **options)[None, :, None]
    k = torch.arange(n + 1, **options)[None, None, :]
    u, v, w = i / n, j / n, k / n
    r = 1.0 + u + 0.2 * w
    theta = 0.5 * math.pi * v + 0.3 * w * u
    h = wobble / n
    x = r * torch.cos(theta) + h * torch.sin(12.9898 * i + 78.233 * j + 37.719 * k)
    y = r * torch.sin(theta) + h * torch.sin(39.346 * i + 11.135 * j + 83.155 * k)
    z = w + 0.4 * u + 0.1 * torch.sin(2 * math.pi * v) + h * torch.sin(73.156 * i + 52.235 * j + 9.151 * k)
    return torch.stack([x, y, z], dim=-1)


def _slabs(n: int, slab_planes: int, device):
    """(nodes, first, last) of the slabs of ``slab_planes`` cell planes, each with its halo."""
    for c0 in range(0, n, slab_planes):
        c1 = min(c0 + slab_planes, n)
        s0, s1 = max(c0 - 1, 0), min(c1 + 2, n + 1)
        yield shell_nodes(n, s0, s1, device), c0 - s0, c1 - s0


def _sync(device) -> None:
    import torch

    if str(device).startswith("cuda"):
        torch.cuda.synchronize()


def _agreement(n: int, sub: int, tolerance: float, device) -> dict:
    """Max abs difference per metric (non-degenerate cells) between the device and the numba
    kernel on a sub-block of sub^3 cells in the middle of the mesh (the same nodes), the fraction of
    values equal to the bit, and whether the degenerate masks agree."""

    from meshgen.quality.compiled import structured_hex
    from meshgen.quality.torch_kernels import structured_hex_torch

    c0 = max(0, n // 2 - sub // 2)
    c1 = min(n, c0 + sub)
    s0, s1 = max(c0 - 1, 0), min(c1 + 2, n + 1)
    nodes = shell_nodes(n, s0, s1, device)[:, s0:s1, s0:s1]
    first, last = (c0 - s0,) * 3, (c1 - s0,) * 3
    rows, mask = structured_hex_torch(nodes, tolerance, first, last)
    rows, mask = rows.cpu().numpy(), mask.cpu().numpy()
    X = np.ascontiguousarray(nodes.cpu().numpy())
    m = rows.shape[1]
    out, degenerate = np.empty((len(METRICS), m)), np.empty(m, dtype=bool)
    structured_hex(X, first, last, tolerance, out, degenerate)
    kept = ~degenerate
    return {
        "cells": int(m),
        "degenerate_masks_equal": bool(np.array_equal(mask, degenerate)),
        "max_abs_difference": {name: float(np.max(np.abs(rows[r, kept] - out[r, kept]))) for r, name in enumerate(METRICS)},
        "bitwise_equal_fraction": {name: float(np.mean(rows[r, kept] == out[r, kept])) for r, name in enumerate(METRICS)},
    }


def gpu_quality_row(
    cells_per_side: int = 1000, slab_planes: int = 64, device: str = "cuda", agreement_cells_per_side: int = 100
) -> dict:
    """The quality summary of the analytic mesh of ``cells_per_side``^3 hexahedra built and evaluated
    slab by slab (``slab_planes`` cell planes each) on ``device``. Returns seconds (bounding-box
    pass, summary pass: generation included; ``seconds`` their total), cells, counts, the report's
    figures, the device name, peak device memory, and the agreement of a
    ``agreement_cells_per_side``^3 sub-block with the numba kernel."""
    import torch

    from meshgen.quality.torch_kernels import report_summaries, summarise_hex_torch

    n = int(cells_per_side)
    if str(device).startswith("cuda"):
        torch.cuda.reset_peak_memory_stats()
        name = torch.cuda.get_device_name()
    else:
        name = "cpu"
    _sync(device)
    start = time.perf_counter()
    low = torch.full((3,), math.inf, dtype=torch.float64, device=device)
    high = -low
    for nodes, _, _ in _slabs(n, slab_planes, device):
        low = torch.minimum(low, nodes.reshape(-1, 3).amin(dim=0))
        high = torch.maximum(high, nodes.reshape(-1, 3).amax(dim=0))
    tolerance = box_tolerance(low.tolist(), high.tolist())
    _sync(device)
    box_seconds = time.perf_counter() - start
    start = time.perf_counter()
    summary = summarise_hex_torch(_slabs(n, slab_planes, device), tolerance)
    _sync(device)
    summary_seconds = time.perf_counter() - start
    peak = torch.cuda.max_memory_allocated() / 2**30 if str(device).startswith("cuda") else None
    return {
        "device": name,
        "cells": summary["cells"],
        "seconds": box_seconds + summary_seconds,
        "box_seconds": box_seconds,
        "summary_seconds": summary_seconds,
        "peak_memory_gib": peak,
        "inverted": summary["inverted"],
        "degenerate": summary["degenerate"],
        "metrics": report_summaries(summary),
        "agreement": _agreement(n, min(agreement_cells_per_side, n), tolerance, device),
    }


def cpu_compare(cells_per_side: int = 100, repeat: int = 3) -> dict:
    """Seconds (best of ``repeat``) of the seven metrics of a cells_per_side^3 analytic mesh: the
    numba kernel (``compiled.structured_hex``, all threads) and the torch code on torch's CPU device."""
    import torch

    from meshgen.quality.compiled import structured_hex
    from meshgen.quality.torch_kernels import structured_hex_torch

    n = int(cells_per_side)
    nodes = shell_nodes(n, 0, n + 1, "cpu")
    X = np.ascontiguousarray(nodes.numpy())
    m = n**3
    out, degenerate = np.empty((len(METRICS), m)), np.empty(m, dtype=bool)
    structured_hex(X, (0, 0, 0), (n, n, n), 1e-12, out, degenerate)  # compiled code loaded

    def best(function):
        times = []
        for _ in range(repeat):
            start = time.perf_counter()
            function()
            times.append(time.perf_counter() - start)
        return min(times)

    numba_seconds = best(lambda: structured_hex(X, (0, 0, 0), (n, n, n), 1e-12, out, degenerate))
    torch_seconds = best(lambda: structured_hex_torch(nodes, 1e-12))
    return {
        "cells": m,
        "numba_seconds": numba_seconds,
        "torch_cpu_seconds": torch_seconds,
        "torch_threads": torch.get_num_threads(),
    }


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells-per-side", type=int, default=1000)
    parser.add_argument("--slab-planes", type=int, default=64)
    parser.add_argument("--device", default="cuda")
    parser.add_argument("--cpu-compare", type=int, help="instead: torch CPU vs numba at this many cells per side")
    parser.add_argument("--json", dest="json_path", help="write the results as JSON")
    args = parser.parse_args(argv)
    if args.cpu_compare:
        data = cpu_compare(args.cpu_compare)
    else:
        data = gpu_quality_row(args.cells_per_side, args.slab_planes, args.device)
    text = json.dumps(data, indent=2)
    print(text)
    if args.json_path:
        Path(args.json_path).write_text(text + "\n")


if __name__ == "__main__":
    main()

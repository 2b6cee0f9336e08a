"""Boundary layouts on every 3D built-in: fixed (each face the Coons layout of its edges) against
smoothed (arc length on the edges, the surface's Winslow grid on each face; ``meshgen.layout``).

    python benchmarks/bench_layout.py [--quick] [--json FILE]

Per geometry and size (30^3 and 100^3 cells; --quick: 30^3 only): for TFI and elliptic with each
layout, the mean minimum angle, inverted cells, the largest boundary deviation relative to the
characteristic length (``meshgen.quality.quality_report`` against the geometry's own surface) and
the wall seconds of the mesh (the smoothed layout's one-off fine-grid solve is timed apart, as
``layout_seconds``). Issue 16's marks on the semicylinder: the smoothed gmsh transfinite mesh's
mean minimum angle, 74.42 at 30^3 and 74.79 at 100^3.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from meshgen.elliptic import elliptic  # noqa: E402
from meshgen.geometry import load_geometry, list_geometries  # noqa: E402
from meshgen.layout import layout_of, smoothed  # noqa: E402
from meshgen.quality import quality_report  # noqa: E402
from meshgen.tfi import tfi  # noqa: E402

GMSH_SMOOTHED = {30: 74.42, 100: 74.79}  # semicylinder, mean min angle (issue 16)


def figures(X, geometry, seconds: float) -> dict:
    report = quality_report(X, geometry)
    return {
        "min_angle_mean": report["metrics"]["min_angle"]["mean"],
        "inverted": report["inverted"]["count"],
        "deviation_max_rel": report["boundary_deviation"]["max_rel"],
        "seconds": seconds,
    }


def measure(name: str, cells: int) -> dict:
    geometry = load_geometry(name)
    start = time.perf_counter()
    layout = layout_of(geometry)
    layout_seconds = time.perf_counter() - start
    dims = (cells,) * 3
    rows = {}
    for layout_name in ("fixed", "smoothed"):
        start = time.perf_counter()
        X = tfi(smoothed(geometry) if layout_name == "smoothed" else geometry, dims)
        rows[f"tfi {layout_name}"] = figures(X, geometry, time.perf_counter() - start)
        start = time.perf_counter()
        X, info = elliptic(geometry, dims, boundary_layout=layout_name)
        rows[f"elliptic {layout_name}"] = {**figures(X, geometry, time.perf_counter() - start), "cycles": info["iterations"]}
    return {
        "geometry": name,
        "cells": cells,
        "layout_seconds": layout_seconds,  # once per geometry and parameters (cached in the process)
        "face_iterations": {face: info["iterations"] for face, info in layout.face_info.items()},
        "methods": rows,
    }


def run(quick: bool = False) -> list[dict]:
    names = [g.name for g in list_geometries() if g.dim == 3]
    results = []
    for cells in (30,) if quick else (30, 100):
        for name in names:
            result = measure(name, cells)
            results.append(result)
            for method, row in result["methods"].items():
                print(
                    f"{name:13s} {cells:4d}^3 {method:18s} min angle {row['min_angle_mean']:7.3f}  inverted "
                    f"{row['inverted']:4d}  deviation {row['deviation_max_rel']:.1e}  {row['seconds']:6.2f} s",
                    flush=True,
                )
    return results


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    results = run(args.quick)
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Write time and size of the solver formats (and .vtu, the reference) for a mesh as ``meshgen
mesh`` writes it: the seven quality arrays, the metadata and the geometry's patches.

    python benchmarks/bench_solver_formats.py [--cells 100] [--repeat 3] [--mesh neural|tfi]
                                              [--json benchmarks/solver_formats.json]

The default mesh is the semicylinder by the bundled network, snapped (what ``meshgen mesh``
makes without options): its coordinates and quality values vary in every bit, unlike TFI's
extrusion, whose repeated values zlib compresses several times better. Times: wall seconds,
median of ``--repeat`` writes (CPU seconds beside them); sizes: the file, or the OpenFOAM case's
polyMesh folder. Target: the .vts at most half the .vtu's size and no slower to write.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from meshgen.formats import read_mesh, write_mesh  # noqa: E402
from meshgen.geometry.patches import geometry_patches  # noqa: E402
from meshgen.geometry.plugins import load_geometry  # noqa: E402
from meshgen.quality import cell_metrics  # noqa: E402

# (label, file name, write options)
TARGETS = [
    (".vtu", "mesh.vtu", {}),
    (".vts", "mesh.vts", {}),
    (".cgns", "mesh.cgns", {}),
    ("openfoam binary", "case_binary", {"format": "openfoam", "binary": True}),
    ("openfoam ascii", "case_ascii", {"format": "openfoam", "binary": False}),
    (".su2", "mesh.su2", {}),
    (".msh", "mesh.msh", {}),
]


def make_mesh(kind: str, cells: int):
    from meshgen.methods.clustering import node_coordinates
    from meshgen.methods.registry import make_mesh as build

    geometry = load_geometry("semicylinder")
    X, _ = build(kind, geometry, node_coordinates((cells,) * 3))
    return geometry, X


def size_mb(path: Path) -> float:
    if path.is_dir():
        return sum(p.stat().st_size for p in (path / "constant" / "polyMesh").iterdir()) / 1e6
    return path.stat().st_size / 1e6


def measure(X, geometry, repeat: int, label: str = "neural") -> dict:
    """Rows {format, write_seconds, write_cpu_seconds, runs_seconds, megabytes, read_seconds}."""
    metrics = cell_metrics(X)
    dims = [n - 1 for n in X.shape[:-1]]
    metadata = {"method": label, "geometry": geometry.name, "params": geometry.values, "dims": dims}
    patches = geometry_patches(geometry)
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for name, file_name, options in TARGETS:
            path = Path(folder) / file_name
            walls, cpus = [], []
            for _ in range(repeat):
                wall, cpu = time.perf_counter(), time.process_time()
                write_mesh(path, X, metrics, metadata, patches=patches, **options)
                walls.append(time.perf_counter() - wall)
                cpus.append(time.process_time() - cpu)
            start = time.perf_counter()
            read_mesh(path)
            rows.append(
                {
                    "format": name,
                    "write_seconds": statistics.median(walls),
                    "write_cpu_seconds": statistics.median(cpus),
                    "runs_seconds": walls,
                    "megabytes": size_mb(path),
                    "read_seconds": time.perf_counter() - start,
                }
            )
    by_name = {row["format"]: row for row in rows}
    vts, vtu = by_name[".vts"], by_name[".vtu"]
    return {
        "mesh": f"semicylinder, {label}",
        "cells_per_axis": dims[0],
        "cells": dims[0] * dims[1] * dims[2],
        "repeat": repeat,
        "results": rows,
        "vts_vs_vtu": {
            "size_ratio": vts["megabytes"] / vtu["megabytes"],
            "write_time_ratio": vts["write_seconds"] / vtu["write_seconds"],
            "size_met": vts["megabytes"] <= 0.5 * vtu["megabytes"],
            "speed_met": vts["write_seconds"] <= vtu["write_seconds"],
        },
    }


def print_table(data: dict) -> None:
    print(f"{data['mesh']}, {data['cells_per_axis']}^3 cells, 7 quality arrays + patches; write median of {data['repeat']}")
    print(f"{'format':<18}{'write [s]':>10}{'cpu [s]':>9}{'size [MB]':>11}{'read [s]':>10}")
    for row in data["results"]:
        print(
            f"{row['format']:<18}{row['write_seconds']:>10.2f}{row['write_cpu_seconds']:>9.2f}{row['megabytes']:>11.1f}{row['read_seconds']:>10.2f}"
        )
    ratio = data["vts_vs_vtu"]
    print(
        f".vts / .vtu: size {ratio['size_ratio']:.2f} (target <= 0.5: {'met' if ratio['size_met'] else 'NOT met'}), "
        f"write time {ratio['write_time_ratio']:.2f} (target <= 1: {'met' if ratio['speed_met'] else 'NOT met'})"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, default=100)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--mesh", choices=["neural", "tfi"], default="neural")
    parser.add_argument("--json", type=Path, default=Path(__file__).with_name("solver_formats.json"))
    args = parser.parse_args()
    geometry, X = make_mesh(args.mesh, args.cells)
    data = measure(X, geometry, args.repeat, args.mesh)
    data["load_average"] = os.getloadavg()
    print_table(data)
    args.json.write_text(json.dumps(data, indent=2) + "\n")
    print(f"wrote {args.json}")


if __name__ == "__main__":
    main()

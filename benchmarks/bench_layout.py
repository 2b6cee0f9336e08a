"""Boundary layouts on every 3D built-in: fixed (each face the Coons layout of its edges) against
smoothed (arc length on the edges, the surface's Winslow grid on each face; ``meshgen.geometry.layout``).

    python benchmarks/bench_layout.py [--quick] [--json FILE]

Per geometry and size (30^3 and 100^3 cells; --quick: 30^3 only): for TFI and elliptic with each
layout, the mean minimum angle, inverted cells, the largest boundary deviation relative to the
characteristic length (``meshgen.quality.quality_report`` against the geometry's own surface) and
the wall seconds of the mesh (the smoothed layout's one-off fine-grid solve is timed apart, as
``layout_seconds``). The reference on the semicylinder: the smoothed gmsh transfinite mesh's
mean minimum angle, measured here when gmsh is installed (``gmsh_smoothed``: gmsh's transfinite
mesh of the section with its elliptic smoother run to convergence; the semicylinder's smoothed
elliptic mesh is its extrusion, node for node, tests/test_layout.py), 74.42 at 30^3 and 74.79 at
100^3.
"""

from __future__ import annotations

import argparse
import json
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from meshgen.geometry.blocks import is_multiblock  # noqa: E402
from meshgen.geometry.layout import layout_of, smoothed  # noqa: E402
from meshgen.geometry.plugins import list_geometries, load_geometry  # noqa: E402
from meshgen.methods.elliptic import elliptic  # noqa: E402
from meshgen.methods.tfi import tfi  # noqa: E402
from meshgen.quality import quality_report  # noqa: E402

GMSH_SMOOTHED = {30: 74.42, 100: 74.79}  # semicylinder, mean min angle of gmsh's smoothed transfinite mesh
SECTION_GEO = """Point(1) = {{0, 0, 0}}; Point(2) = {{-1, 0, 0}}; Point(3) = {{Cos(3*Pi/4), Sin(3*Pi/4), 0}};
Point(4) = {{Cos(Pi/4), Sin(Pi/4), 0}}; Point(5) = {{1, 0, 0}};
Circle(1) = {{2, 1, 3}}; Circle(2) = {{3, 1, 4}}; Circle(3) = {{4, 1, 5}}; Line(4) = {{5, 2}};
Curve Loop(1) = {{1, 2, 3, 4}}; Plane Surface(1) = {{1}};
Transfinite Curve{{1, 2, 3, 4}} = {nodes}; Transfinite Surface{{1}} = {{2, 3, 4, 5}}; Recombine Surface{{1}};
Mesh.Smoothing = {steps};
"""  # the semicylinder's section (radius 1, corners at angles pi, 3pi/4, pi/4, 0)


def gmsh_smoothed(cells: int) -> float | None:
    """Mean min angle of gmsh's smoothed transfinite mesh of the semicylinder's section, cells x
    cells, smoother run to convergence (2 cells^2 steps); None when gmsh is not installed."""
    import meshio
    import numpy as np

    gmsh = shutil.which("gmsh")
    if gmsh is None:
        return None
    with tempfile.TemporaryDirectory() as folder:
        geo, msh = Path(folder) / "section.geo", Path(folder) / "section.msh"
        geo.write_text(SECTION_GEO.format(nodes=cells + 1, steps=2 * cells**2))
        subprocess.run([gmsh, str(geo), "-2", "-o", str(msh), "-format", "msh22"], check=True, capture_output=True)
        mesh = meshio.read(msh)
    corners = mesh.points[mesh.cells_dict["quad"], :2]
    before, after = np.roll(corners, 1, axis=1) - corners, np.roll(corners, -1, axis=1) - corners
    cosines = (before * after).sum(-1) / (np.linalg.norm(before, axis=-1) * np.linalg.norm(after, axis=-1))
    return float(np.degrees(np.arccos(np.clip(cosines, -1.0, 1.0))).min(axis=1).mean())


def gmsh_extruded(cells: int) -> dict | None:
    """gmsh's smoothed transfinite semicylinder with cells^3 hexahedra: the section of
    ``SECTION_GEO`` (smoother run to convergence, as ``gmsh_smoothed``) extruded over the length 2
    in ``cells`` recombined layers, the mesh the elliptic solver makes of it. Returns the meshing
    seconds gmsh reports (its 1D, 2D and 3D "Done meshing" walls: writing excluded), the process's
    wall seconds and the version; None when gmsh is not installed."""
    import re

    gmsh = shutil.which("gmsh")
    if gmsh is None:
        return None
    with tempfile.TemporaryDirectory() as folder:
        geo, msh = Path(folder) / "semicylinder.geo", Path(folder) / "semicylinder.msh"
        extrude = f"Extrude {{0, 0, 2}} {{ Surface{{1}}; Layers{{{cells}}}; Recombine; }}\n"
        geo.write_text(SECTION_GEO.format(nodes=cells + 1, steps=2 * cells**2) + extrude)
        start = time.perf_counter()
        run = subprocess.run([gmsh, str(geo), "-3", "-o", str(msh)], check=True, capture_output=True, text=True)
        process = time.perf_counter() - start
    walls = [float(value) for value in re.findall(r"Done meshing \dD \(Wall ([0-9.eE+-]+)s", run.stdout)]
    version = subprocess.run([gmsh, "--version"], capture_output=True, text=True)
    return {
        "meshing_seconds": sum(walls),
        "process_seconds": process,
        "version": (version.stdout + version.stderr).strip(),
        "smoothing_steps": 2 * cells**2,
    }


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
    result = {
        "geometry": name,
        "cells": cells,
        "layout_seconds": layout_seconds,  # once per geometry and parameters (cached in the process)
        "face_iterations": {face: info["iterations"] for face, info in layout.face_info.items()},
        "methods": rows,
    }
    if name == "semicylinder":
        result["gmsh_smoothed_min_angle_mean"] = gmsh_smoothed(cells)
    return result


def run(quick: bool = False) -> list[dict]:
    names = [g.name for g in list_geometries() if g.dim == 3 and not is_multiblock(g.name)]  # one block each
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
            if result.get("gmsh_smoothed_min_angle_mean") is not None:
                print(
                    f"{name:13s} {cells:4d}^3 {'gmsh smoothed':18s} min angle "
                    f"{result['gmsh_smoothed_min_angle_mean']:7.3f}  (the section, smoother converged)",
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

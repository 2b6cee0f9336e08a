"""Shapes from files: the parametrisation of a large patch, a STEP loft and an STL bent duct.

    python benchmarks/bench_shapes.py [--quick] [--json FILE]

Rows (each shape built by the benchmark itself, as the tests build theirs: tests/shape_helpers.py):

- ``parametrise``: one random four-cornered patch of about 200k triangles (--quick: 20k) onto the
  unit square (mean-value weights, one sparse LU, one solve per coordinate): seconds (median of
  3), and whether it is foldover-free (every triangle positively oriented). Target: < 2 s on 2 cores.
- ``step_loft``: a twisted loft through three rectangles exported to STEP by gmsh, meshed
  elliptic at 20x20x40 (--quick: 8x8x16): inverted cells, the largest distance of a boundary node
  from the CAD faces (gmsh's closest point) and of a mesh corner from a CAD vertex, both over the
  bounding-box diagonal L, and the mesh volume's relative difference from OCC's volume of the solid.
  Targets: 0 inverted, 1e-7 L, 1e-9 L, 1e-3.
- ``stl_duct``: a 90-degree bend of a rectangular duct, a multi-solid ASCII STL of about 30k
  triangles (--quick: 3k), TFI and elliptic at 12x8x40 (--quick: 6x4x12): inverted cells, the
  largest distance of a boundary node from the triangles (VTK's cell locator) over L, the largest
  distance of a mesh corner from the duct's closed-form corners, and the mean minimum angle.
  Targets: 0 inverted, 1e-9 L, corners on the corner vertices.
- ``stl_duct_neural`` (only with --neural): ``meshgen train -g duct.stl --preset exact`` then
  ``meshgen mesh --method neural``: the mean minimum angle against the elliptic mesh's (target:
  within 0.5 degrees).

Seconds include reading the file and parametrising its faces (``load_seconds``) apart from the
meshing. The layout cache is put in a temporary folder, so the smoothed layout is computed.
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

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from shape_helpers import (  # noqa: E402
    DUCT_CORNERS,
    distance_to_cad,
    distance_to_triangles,
    duct_point,
    duct_surface,
    enclosed_volume,
    random_patch,
    write_ascii_stl,
    write_twisted_loft,
)

from meshgen.geometry.plugins import load_geometry  # noqa: E402
from meshgen.geometry.shapes.parametrise import parametrise, signed_areas  # noqa: E402
from meshgen.quality import quality_report  # noqa: E402
from meshgen.run.request import mesh  # noqa: E402


def boundary_nodes(X):
    mask = np.zeros(X.shape[:3], dtype=bool)
    mask[[0, -1]], mask[:, [0, -1]], mask[:, :, [0, -1]] = True, True, True
    return X[mask]


def corners_of(X):
    return X[[0, -1]][:, [0, -1]][:, :, [0, -1]].reshape(-1, 3)


def bench_parametrise(triangles: int) -> dict:
    vertices, tris, corners = random_patch(triangles, seed=7)
    seconds, patch = [], None
    for _ in range(3):
        start = time.perf_counter()
        patch = parametrise(vertices, tris, corners)
        seconds.append(time.perf_counter() - start)
    areas = signed_areas(patch.uv, patch.triangles)
    return {
        "triangles": int(len(tris)),
        "seconds_median": statistics.median(seconds),
        "seconds": seconds,
        "foldover_free": bool(areas.min() > 0),
        "dividing_edges_split": int((len(patch.triangles) - len(tris)) // 2),
    }


def bench_step(folder: Path, dims) -> dict:
    path = folder / "loft.step"
    volume = write_twisted_loft(path)
    start = time.perf_counter()
    geometry = load_geometry(str(path))
    load_seconds = time.perf_counter() - start
    start = time.perf_counter()
    result = mesh(geometry, dims, method="elliptic")
    seconds = time.perf_counter() - start
    X = result.X
    report = quality_report(X, geometry)
    distance, vertices = distance_to_cad(boundary_nodes(X), path)
    length = float(np.linalg.norm(vertices.max(0) - vertices.min(0)))
    corner_gap = np.linalg.norm(corners_of(X)[:, None] - vertices[None], axis=-1).min(axis=1)
    return {
        "dims": list(dims),
        "load_seconds": load_seconds,
        "elliptic_seconds": seconds,
        "inverted": report["inverted"]["count"],
        "min_angle_mean": report["metrics"]["min_angle"]["mean"],
        "boundary_distance_max_rel": float(distance.max() / length),
        "corner_distance_max_rel": float(corner_gap.max() / length),
        "volume_rel_error": float(abs(enclosed_volume(X) - volume) / volume),
        "occ_volume": volume,
    }


def bench_duct(folder: Path, shape, dims) -> dict:
    vertices, triangles, labels = duct_surface(*shape)
    path = write_ascii_stl(folder / "duct.stl", vertices, triangles, labels)
    start = time.perf_counter()
    geometry = load_geometry(str(path))
    load_seconds = time.perf_counter() - start
    length = float(np.linalg.norm(vertices.max(0) - vertices.min(0)))
    expected = np.array([duct_point(*c) for c in DUCT_CORNERS])
    rows = {"triangles": int(len(triangles)), "dims": list(dims), "load_seconds": load_seconds}
    for method in ("tfi", "elliptic"):
        start = time.perf_counter()
        X = mesh(geometry, dims, method=method).X
        seconds = time.perf_counter() - start
        report = quality_report(X, geometry)
        distance = distance_to_triangles(boundary_nodes(X), vertices, triangles)
        gaps = np.linalg.norm(corners_of(X)[:, None] - expected[None], axis=-1).min(axis=1)
        rows[method] = {
            "seconds": seconds,
            "inverted": report["inverted"]["count"],
            "min_angle_mean": report["metrics"]["min_angle"]["mean"],
            "boundary_distance_max_rel": float(distance.max() / length),
            "corner_distance_max": float(gaps.max()),
        }
    return rows


def bench_neural(folder: Path, dims) -> dict:
    """Train the exact preset on the duct (already written in ``folder``) and mesh with it."""
    import subprocess

    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    start = time.perf_counter()
    train = subprocess.run(
        [sys.executable, "-m", "meshgen", "train", "-g", "duct.stl", "--preset", "exact"],
        cwd=folder,
        env=env,
        capture_output=True,
        text=True,
    )
    train_seconds = time.perf_counter() - start
    if train.returncode != 0:
        return {"error": train.stderr.strip().splitlines()[-1] if train.stderr.strip() else "train failed"}
    out = folder / "neural.vtu"
    dims_args = [str(n) for n in dims]
    made = subprocess.run(
        [sys.executable, "-m", "meshgen", "mesh", "-g", "duct.stl", "--method", "neural", "--dims", *dims_args, "-o", str(out)],
        cwd=folder,
        env=env,
        capture_output=True,
        text=True,
    )
    if made.returncode != 0:
        return {"error": made.stderr.strip().splitlines()[-1] if made.stderr.strip() else "mesh failed"}
    report = json.loads((folder / "neural.vtu.quality.json").read_text())
    return {
        "train_seconds": train_seconds,
        "inverted": report["inverted"]["count"],
        "min_angle_mean": report["metrics"]["min_angle"]["mean"],
    }


def run(quick: bool = False, neural: bool = False) -> dict:
    results = {}
    with tempfile.TemporaryDirectory() as folder:
        os.environ["MESHGEN_CACHE_DIR"] = str(Path(folder) / "cache")
        folder = Path(folder)
        row = results["parametrise"] = bench_parametrise(20_000 if quick else 200_000)
        print(
            f"parametrise  {row['triangles']:7d} triangles  {row['seconds_median']:6.2f} s (median of 3)  "
            f"foldover-free {row['foldover_free']}  (target < 2 s)",
            flush=True,
        )
        try:
            import gmsh  # noqa: F401

            row = results["step_loft"] = bench_step(folder, (8, 8, 16) if quick else (20, 20, 40))
            print(
                f"step_loft    elliptic {'x'.join(map(str, row['dims']))}  inverted {row['inverted']}  boundary "
                f"{row['boundary_distance_max_rel']:.1e} L  corners {row['corner_distance_max_rel']:.1e} L  volume "
                f"{row['volume_rel_error']:.1e}  load {row['load_seconds']:.2f} s  mesh {row['elliptic_seconds']:.2f} s",
                flush=True,
            )
        except ImportError:
            print("step_loft    skipped: the gmsh Python package is not installed", flush=True)
        shape, dims = ((24, 8, 6), (6, 4, 12)) if quick else ((120, 32, 20), (12, 8, 40))
        row = results["stl_duct"] = bench_duct(folder, shape, dims)
        for method in ("tfi", "elliptic"):
            m = row[method]
            print(
                f"stl_duct     {row['triangles']:6d} triangles {method:8s} {'x'.join(map(str, dims))}  inverted "
                f"{m['inverted']}  boundary {m['boundary_distance_max_rel']:.1e} L  corners {m['corner_distance_max']:.1e}  "
                f"min angle {m['min_angle_mean']:.2f}  load {row['load_seconds']:.2f} s  mesh {m['seconds']:.2f} s",
                flush=True,
            )
        if neural:
            row = results["stl_duct_neural"] = bench_neural(folder, dims)
            if "error" in row:
                print(f"stl_duct_neural  failed: {row['error']}", flush=True)
            else:
                gap = row["min_angle_mean"] - results["stl_duct"]["elliptic"]["min_angle_mean"]
                row["min_angle_gap_to_elliptic"] = gap
                print(
                    f"stl_duct_neural  inverted {row['inverted']}  min angle {row['min_angle_mean']:.2f} "
                    f"({gap:+.2f} vs elliptic; target within 0.5)  train {row['train_seconds']:.0f} s",
                    flush=True,
                )
    return results


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--neural", action="store_true", help="also train the exact preset on the duct (minutes)")
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    results = run(args.quick, args.neural)
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())

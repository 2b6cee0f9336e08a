"""Swept CAD solids: STEP files of straight sweeps meshed as block sets.

    python benchmarks/bench_sweeps.py [--quick] [--json FILE]

One row per solid (each built by gmsh's OCC kernel and exported to STEP, as the tests build
theirs: tests/shape_helpers.py ``write_sweep_solid``): ``cylinder`` (radius 0.5, length 2),
``hole`` (that cylinder with a coaxial hole of radius 0.2), ``fillet`` (a 1 x 1 x 2 box with one
edge filleted, radius 0.3), ``pentagon`` (a regular pentagonal prism), ``wedge`` (a triangular
prism), ``bend`` (a disk of radius 0.5 turned 90 degrees about an axis 2 away), ``bent_pentagon``
(a pentagon turned 120 degrees), ``tube`` (a square tube, 1 x 1 less 0.4 x 0.4, 3 long), ``wing``
(a NACA 0012 section of chord 1, sharp trailing edge, extruded 1), ``loft`` (a ruled loft from a
circle of radius 0.5 to a 0.8 x 0.8 square 2 above it), ``stl_cylinder`` (trimesh's cylinder,
64 sections, as STL: boundary distance from its facets), ``stl_torus`` and ``stl_bent_pentagon``
(binary STL bends by tests/shape_helpers ``turned_surface``: the ``bend``'s disk as a 64-gon turned
90 degrees and the ``bent_pentagon`` turned 120 degrees, 25 steps each (the nodes between the rings): boundary distance from
the facets by VTK's closest point, volume against the divergence theorem over the file's
triangles), each at about 20 cells across
its cap (--quick: about 10), by TFI and by the elliptic method (the wing's keeps the TFI mesh), and
(not --quick) the CAD solids by the neural method: a model trained in the run (``meshgen train -g
FILE``, the default configuration: the networks fitted to the solid's elliptic mesh), its training
seconds in the row. Per method: inverted cells, the worst scaled Jacobian and minimum angle, the largest
distance of a patch node from its own CAD face (gmsh's closest point) over the bounding-box
diagonal L, the mesh volume's relative difference from OCC's, checkMesh's verdict on the OpenFOAM
case (None without OpenFOAM), and seconds (reading the file and meshing). The cylinder also gets
the built-in pipe's worst minimum angle at the same counts.

Targets: 0 inverted, scaled Jacobian >= 0.4, boundary distance <= 1e-6 L, volume error <= 1e-2,
checkMesh OK; the cylinder's worst minimum angle (elliptic) >= 76 deg and the pipe's. The wing's
scaled Jacobian cannot reach 0.4: its trailing edge's cell holds the whole edge angle, 16.5 deg
(sin: 0.285); every other cell's is above 0.4.
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

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests"))

from shape_helpers import SWEEP_SOLIDS, enclosed_volume, prism_distance, write_sweep_solid  # noqa: E402

from meshgen.geometry import cube  # noqa: E402
from meshgen.run.request import mesh  # noqa: E402

DIMS = {"cylinder": (10, 5, 20), "hole": (10, 5, 20), "fillet": (7, 3, 20), "pentagon": (10, 1, 20), "wedge": (10, 1, 20)}
DIMS |= {"bend": (10, 5, 20), "bent_pentagon": (10, 1, 20), "tube": (20, 6, 20), "wing": (10, 5, 20), "loft": (10, 5, 20)}
QUICK_DIMS = {"cylinder": (5, 3, 8), "hole": (5, 3, 8), "fillet": (4, 2, 8), "pentagon": (5, 1, 8), "wedge": (5, 1, 8)}
QUICK_DIMS |= {"bend": (5, 3, 8), "bent_pentagon": (5, 1, 8), "tube": (10, 3, 8), "wing": (5, 3, 8), "loft": (5, 3, 8)}


def patch_distance(path: Path, made) -> tuple[float, float]:
    """(largest distance of a patch node from its own CAD face, bounding-box diagonal L)."""
    import gmsh

    if not gmsh.isInitialized():
        gmsh.initialize(readConfigFiles=False, interruptible=False)
    gmsh.option.setNumber("General.Terminal", 0)
    gmsh.model.add(f"bench-{path.name}")
    gmsh.model.occ.importShapes(str(path))
    gmsh.model.occ.synchronize()
    faces = [abs(t) for d, t in gmsh.model.getBoundary(gmsh.model.getEntities(3), oriented=False) if d == 2]
    box = np.array(gmsh.model.getBoundingBox(-1, -1)).reshape(2, 3)
    worst = 0.0
    for (block, face_name), (name, _) in made.geometry.patches.items():
        face = cube.face_named(face_name, 3)
        nodes = np.take(made.blocks[block], 0 if face.side == 0 else -1, axis=face.axis).reshape(-1, 3)
        tag = faces[int(name.removeprefix("face")) - 1]
        closest = np.array(gmsh.model.getClosestPoint(2, tag, nodes.ravel().tolist())[0]).reshape(-1, 3)
        worst = max(worst, float(np.linalg.norm(closest - nodes, axis=1).max()))
    gmsh.model.remove()
    return worst, float(np.linalg.norm(box[1] - box[0]))


def check_mesh_ok(made, folder: Path):
    """checkMesh's verdict on the mesh's OpenFOAM case, or None without OpenFOAM."""
    from openfoam_helpers import check_mesh, missing_reason

    if missing_reason() is not None:
        return None
    case = folder / "case"
    made.write(case, "openfoam", quality=False)
    return bool(check_mesh(case)["ok"])


def bench_solid(kind: str, folder: Path, dims, method: str) -> dict:
    path = folder / f"{kind}.step"
    volume = write_sweep_solid(kind, path)
    options, trained = {}, {}
    if method == "neural":  # a model of the solid, trained as a user trains it
        trained = train_model(path, folder / f"run-{kind}")
        options["model"] = str(trained["checkpoint"])
    start = time.perf_counter()
    made = mesh(str(path), dims, method=method, **options)
    seconds = time.perf_counter() - start
    distance, length = patch_distance(path, made)
    row = figures(made, dims, distance / length, volume, seconds, folder)
    return row | ({"training_seconds": trained["seconds"]} if trained else {})


def train_model(path: Path, run: Path) -> dict:
    """``meshgen train -g PATH --out RUN -q`` in a subprocess: {"checkpoint", "seconds"}."""
    environment = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    start = time.perf_counter()
    command = [sys.executable, "-m", "meshgen", "train", "-g", str(path), "--out", str(run), "-q"]
    subprocess.run(command, check=True, env=environment, stdout=subprocess.DEVNULL)
    return {"checkpoint": run / "checkpoint.pt", "seconds": time.perf_counter() - start}


def figures(made, dims, distance_rel: float, volume: float, seconds: float, folder: Path) -> dict:
    """One row: cells, inverted, worst scaled Jacobian and min angle, the boundary distance given
    (over L), the volume's relative error against ``volume``, checkMesh's verdict, seconds."""
    report = made.report()
    with tempfile.TemporaryDirectory(dir=folder) as scratch:
        ok = check_mesh_ok(made, Path(scratch))
    return {
        "dims": list(dims),
        "blocks": len(made.blocks),
        "cells": int(sum(np.prod(np.array(X.shape[:3]) - 1) for X in made.blocks)),
        "inverted": int(report["inverted"]["count"]),
        "scaled_jacobian_min": float(report["metrics"]["scaled_jacobian"]["min"]),
        "min_angle_min": float(report["metrics"]["min_angle"]["min"]),
        "boundary_distance_max_rel": distance_rel,
        "volume_rel_error": abs(sum(enclosed_volume(X) for X in made.blocks) - volume) / volume,
        "checkmesh_ok": ok,
        "seconds": seconds,
    }


def patch_nodes(made) -> np.ndarray:
    """(N, 3) the nodes of every block face on a patch of the mesh ``made``."""
    nodes = []
    for (block, face_name), _ in made.geometry.patches.items():
        face = cube.face_named(face_name, 3)
        nodes.append(np.take(made.blocks[block], 0 if face.side == 0 else -1, axis=face.axis).reshape(-1, 3))
    return np.concatenate(nodes)


def bench_stl(folder: Path, dims, method: str) -> dict:
    """The ``stl_cylinder`` row: trimesh's cylinder (radius 0.5, height 2, 64 sections) as STL;
    boundary distance from its facets (``prism_distance``), volume against trimesh's."""
    import trimesh

    path = folder / "cylinder.stl"
    trimesh.creation.cylinder(radius=0.5, height=2.0, sections=64).export(path)
    start = time.perf_counter()
    made = mesh(str(path), dims, method=method)
    seconds = time.perf_counter() - start
    distance = prism_distance(path, patch_nodes(made)) / np.sqrt(6.0)
    return figures(made, dims, distance, trimesh.load(path).volume, seconds, folder)


STL_BENDS = {"stl_torus": ("torus", np.pi / 2, "bend"), "stl_bent_pentagon": ("pentagon", 2 * np.pi / 3, "bent_pentagon")}


def bench_stl_bend(row: str, folder: Path, dims, method: str) -> dict:
    """A ``stl_torus`` or ``stl_bent_pentagon`` row (module docstring): the bend written as a
    binary STL (float32), meshed; boundary distance from the file's triangles (VTK), volume
    against theirs (divergence theorem)."""
    import trimesh
    from shape_helpers import distance_to_triangles, surface_volume, turned_outline, turned_surface, write_surface

    kind, angle, _ = STL_BENDS[row]
    path = write_surface(folder / f"{row}.stl", *turned_surface(turned_outline(kind), angle, 25))
    read = trimesh.load(path, process=False, force="mesh")
    vertices, triangles = np.asarray(read.vertices, dtype=float), np.asarray(read.faces)
    start = time.perf_counter()
    made = mesh(str(path), dims, method=method)
    seconds = time.perf_counter() - start
    length = float(np.linalg.norm(vertices.max(axis=0) - vertices.min(axis=0)))
    distance = float(distance_to_triangles(patch_nodes(made), vertices, triangles).max()) / length
    return figures(made, dims, distance, surface_volume(vertices, triangles), seconds, folder)


def run(quick: bool = False) -> dict:
    """Rows ``sweep_<solid>`` -> {"tfi": figures, "elliptic": figures[, "neural": figures]} (module docstring); the
    cylinder's also ``pipe_min_angle_min`` (the built-in pipe's, elliptic, same counts)."""
    try:
        import gmsh  # noqa: F401
    except ImportError:
        print("sweeps: skipped, the gmsh Python package is not installed", flush=True)
        return {}
    results = {}
    dims_of = QUICK_DIMS if quick else DIMS
    with tempfile.TemporaryDirectory() as folder:
        os.environ["MESHGEN_CACHE_DIR"] = str(Path(folder) / "cache")
        for kind in SWEEP_SOLIDS:
            row = results[f"sweep_{kind}"] = {}
            for method in ("tfi", "elliptic") if quick else ("tfi", "elliptic", "neural"):
                m = row[method] = bench_solid(kind, Path(folder), dims_of[kind], method)
                print(
                    f"sweep_{kind:9s} {method:8s} {'x'.join(map(str, m['dims']))}  {m['blocks']:2d} blocks  inverted "
                    f"{m['inverted']}  scaled Jacobian {m['scaled_jacobian_min']:.3f}  min angle {m['min_angle_min']:.1f}  "
                    f"boundary {m['boundary_distance_max_rel']:.1e} L  volume {m['volume_rel_error']:.1e}  checkMesh "
                    f"{m['checkmesh_ok']}  {m['seconds']:.2f} s"
                    + (f"  (trained {m['training_seconds']:.0f} s)" if "training_seconds" in m else ""),
                    flush=True,
                )
        try:
            import trimesh  # noqa: F401
        except ImportError:
            print("sweep_stl_*: skipped, trimesh is not installed", flush=True)
        else:
            benches = {"stl_cylinder": lambda method: bench_stl(Path(folder), dims_of["cylinder"], method)}
            for name, (_, _, like) in STL_BENDS.items():
                benches[name] = lambda method, name=name, like=like: bench_stl_bend(name, Path(folder), dims_of[like], method)
            for name, bench in benches.items():
                row = results[f"sweep_{name}"] = {}
                for method in ("tfi", "elliptic"):
                    m = row[method] = bench(method)
                    print(
                        f"sweep_{name} {method:8s} {m['blocks']:2d} blocks  inverted {m['inverted']}  scaled Jacobian "
                        f"{m['scaled_jacobian_min']:.3f}  boundary {m['boundary_distance_max_rel']:.1e} L  volume "
                        f"{m['volume_rel_error']:.1e}  checkMesh {m['checkmesh_ok']}  {m['seconds']:.2f} s",
                        flush=True,
                    )
        pipe = mesh("pipe", dims_of["cylinder"], method="elliptic", params={"radius": 0.5, "length": 2.0})
        angle = float(pipe.report()["metrics"]["min_angle"]["min"])
        results["sweep_cylinder"]["pipe_min_angle_min"] = angle
        print(f"sweep_cylinder  the built-in pipe at the same counts (elliptic): min angle {angle:.1f}", flush=True)
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

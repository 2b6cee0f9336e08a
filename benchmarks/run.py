"""The speed and quality figures of meshgen, measured in one run, each beside its target.

    python benchmarks/run.py [--quick] [--json FILE] [--markdown FILE] [--only SECTION ...]
    python benchmarks/run.py --from-json FILE [--markdown FILE]    # the summary of an earlier run

Sections, in order (all on the semicylinder, the reference shape):

- ``machine``: cores, versions, memory, load average, and the float32 matrix-product rate
  (GFLOP/s of a 4096 x 4096 product with torch, best of several: the roof for inference;
  ``bench_inference.matmul_rates``);
- ``meshing``: ``tfi``, ``elliptic`` and ``neural`` (the bundled model, boundary corrected) at 30^3
  and 100^3 cells through ``meshgen.methods.registry.make_mesh``, median of several runs (--quick: 30^3, and
  elliptic 100^3 once, for its target; the first 100^3 elliptic run loads the compiled kernels,
  as a fresh process does); then the network's forward pass alone (``evaluate_network``: NumPy,
  what meshing on a CPU runs) for the bundled model and for a [85]*4 network on
  101^3 nodes, each as a fraction of the matrix-product roof;
- ``boundary_layout``: TFI and elliptic with the fixed and the smoothed boundary layout on every
  3D built-in at 30^3 and 100^3 cells (--quick: 30^3): mean minimum angle, inverted cells, boundary
  deviation, seconds (``bench_layout.py``);
- ``mesh_command``: ``meshgen mesh --dims 100 100 100 -o out.vtu`` in a fresh folder (so the bundled
  model), a subprocess timed from start to exit: imports, meshing, polishing, quality, writing
  (``bench_inference.mesh_command``; the bundled model's default is not to polish), and the same
  with ``--no-polish`` and with ``--polish``;
- ``training``: seconds per Adam step of every variant at the same point counts (4096 interior,
  16^3 grid nodes for finite differences, and 6000 boundary points), and the autograd / finite-
  difference ratio of the pairs that differ only in the derivatives (``bench_train.py``);
- ``time_to_quality``: ``exact``, ``default`` and ``paper`` (capped on a CPU) trained on 1 and 2
  CPU threads and on CUDA where torch sees a GPU (else skipped with the reason): seconds per Adam
  and L-BFGS step inside the loop, and the training seconds until the corrected 30^3 mesh
  (``meshgen mesh``'s) is valid and better than the TFI of the same boundary layout, and until its
  mean minimum angle is within 0.3 degrees of the elliptic mesh's on that layout (the run stops
  there; ``paper`` on CUDA runs its 12000 Adam steps whole), on the smoothed and the fixed layout
  (``bench_train.speed_table``);
- ``correction``: ``default`` trained on each 3D built-in, its corrected mesh at 30^3, 100^3 and
  200^3 against the converged elliptic mesh (``bench_correction.py``; the longest section);
- ``family``: one network per family of shapes (``meshgen train --vary``, ``bench_family.py``): flower
  (twist 0..180), the README's flower (twist 0..180, amplitude 0.1..0.3) and semicylinder (radius
  0.5..2, length 1..4), training time, per-member meshing time at 40^3, and the worst (inverted
  cells first, then angle) of the validation grid (3 values per parameter, corners included) and 10
  random members against its elliptic mesh;
- ``evaluate``: ``meshgen.quality.quality_report`` with boundary deviation on 1e6 hexahedra
  (``bench_quality.py``); the headline is the unstructured path ``meshgen evaluate`` takes for files;
  and ``meshgen evaluate`` of the 100^3 .vts end to end, a subprocess, median of 5 after a warm-up;
- ``formats``: write and read time and file size per output format at 100^3 (``formats.py``);
- ``solver_formats``: the 100^3 neural mesh with its quality arrays and patches written as .vtu,
  .vts, .cgns, OpenFOAM (binary, ASCII), .su2 and .msh: seconds and MB, and the .vts against the
  .vtu (``bench_solver_formats.py``);
- ``memory``: peak resident memory of ``meshgen mesh --dims 200 200 200 -o out.vtu``;
- ``chunked``: meshes larger than memory (``bench_chunked.py``): TFI to ``.cgns`` in memory and in
  blocks at 200^3 (throughput ratio), the chunked path at 400^3 and ``meshgen evaluate --chunked``
  of that file (peak memory), a neural mesh in blocks; the 1000^3 rows are
  ``bench_chunked.py --big-dims 1000`` by hand; the GPU row is skipped without a CUDA device;
- ``blocks_neural``: ``meshgen train -g pipe`` timed in a subprocess (the default configuration: the
  elliptic start), and that model (one network per block) against the multi-block elliptic mesh at
  --dims 8 4 4 and 16 8 4 (--quick: 4 2 4 and 8 4 4, not judged): the network's conforming mesh and
  the polished mesh, inverted cells, interface gaps (``bench_blocks_neural.py``);
- ``blocks``: multi-block meshes (``bench_blocks.py``): the pipe O-grid's worst angles against
  resolution and, at 40 around by 80 along with the elliptic solver's default tolerance,
  potentialFoam's largest |U - U_inlet|; the DFG 2D-1 benchmark (``examples/dfg/run_dfg.py``) at
  2.4k, 9.6k and 38k cells, drag, lift and dp against Schaefer and Turek's values (--quick: the
  small pipes only).

The summary at the end lists the headline figures with their targets and met /
not met; ``--json`` keeps everything measured, with keys that name their units (``seconds``,
``cpu_seconds``, ``megabytes``, ``gflops``), ``--markdown`` writes the summary as a Markdown table.

--quick (for CI, a few minutes on 2 cores): meshing at 30^3 only, 2 repeats, the default network
sizes only with few steps, time-to-quality with capped budgets (marked ``capped``; a capped run that
never reaches the bounds says little), formats and solver formats at 50^3, and the peak memory of the 100^3 command
instead of 200^3, chunked at 60^3 and 80^3. Targets are judged only on the figures they are set for.

Every timing gives wall seconds and, where it helps, process CPU seconds: on a machine shared with
other work the wall time grows with the load average (recorded before and after each section),
the CPU time much less. Figures are printed, never asserted: the exit status is 0 whether or not
a target is met.
"""

from __future__ import annotations

import os

# As ``meshgen train`` does, before torch is imported: spinning OpenMP threads waste a shared CPU.
_USER_ENVIRONMENT = dict(os.environ)
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

import argparse  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import statistics  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from datetime import datetime, timezone  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

BENCHMARKS = Path(__file__).resolve().parent
REPO = BENCHMARKS.parent
sys.path.insert(0, str(REPO))
sys.path.insert(1, str(BENCHMARKS))

GEOMETRY = "semicylinder"
PAPER_WIDTHS = [85, 85, 85, 85]  # the network the inference target is set for
SECTIONS = [
    "machine",
    "meshing",
    "boundary_layout",
    "mesh_command",
    "training",
    "time_to_quality",
    "correction",
    "family",
    "evaluate",
    "formats",
    "solver_formats",
    "memory",
    "chunked",
    "shapes",
    "fidelity",
    "blocks_neural",
    "blocks",
    "airfoil",
    "airfoil_family",
    "sweeps",
    "topology",
    "gpu",
]

# figure key -> (comparison, target, unit, what the figure measures)
TARGETS = {
    "neural_pipe_min_angle_degrees": (
        "<=",
        0.5,
        "deg",
        "neural pipe model: |mean min angle - multi-block elliptic's|, worst of --dims 8 4 4 and 16 8 4; 0 inverted, conforming",
    ),
    "train_pipe_seconds": (
        "<=",
        300.0,
        "s",
        "meshgen train -g pipe end to end (a subprocess, the default configuration), the model neural_pipe_min_angle_degrees judges",
    ),
    "inference_101_seconds": ("<=", 0.6, "s", "forward pass of a [85]*4 network on 101^3 nodes, 2 cores"),
    "mesh_command_100_seconds": (
        "<=",
        2.5,
        "s",
        "meshgen mesh --dims 100 100 100 -o out.vtu, end to end, bundled model, 2 cores",
    ),
    "mesh_command_100_no_polish_seconds": ("<=", 2.5, "s", "the same with --no-polish (the network's mesh, corrected)"),
    "elliptic_100_seconds": ("<=", 5.0, "s", "elliptic mesh of the semicylinder, 100^3 cells, converged, 2 cores"),
    "elliptic_30_seconds": ("<=", 3.0, "s", "elliptic mesh of the semicylinder, 30^3 cells, converged"),
    "elliptic_100_over_gmsh": (
        "<=",
        1.0,
        "x",
        "elliptic semicylinder 100^3 / gmsh's smoothed transfinite semicylinder 100^3 (its meshing walls), same run",
    ),
    "evaluate_1e6_seconds": ("<=", 3.0, "s", "quality report of 1e6 hexahedra, with boundary deviation"),
    "evaluate_cli_100_seconds": ("<=", 0.8, "s", "meshgen evaluate of a 100^3 .vts, end to end, 2 cores"),
    "quality_kernels_1e6_seconds": ("<=", 0.1, "s", "the seven per-cell metrics of 1e6 hexahedra in memory"),
    "quality_chunked_1e6_seconds": ("<=", 0.1, "s", "quality of 1e6 hexahedra block by block from a .cgns file"),
    "fd_ad_step_ratio": (">=", 10.0, "x", "autograd step / finite-difference step, same points"),
    "peak_memory_200_megabytes": ("<=", 6000.0, "MB", "peak memory of meshgen mesh --dims 200 200 200"),
    "vts_vtu_size_ratio": ("<=", 0.5, "x", ".vts size / .vtu size, 100^3 neural mesh with its quality arrays"),
    "vts_vtu_write_time_ratio": ("<=", 1.0, "x", ".vts write time / .vtu write time, same mesh"),
    "elliptic_min_angle_30": (">=", 74.4, "deg", "semicylinder 30^3, mean min angle; smoothed gmsh transfinite mesh 74.42"),
    "elliptic_min_angle_100": (">=", 74.8, "deg", "semicylinder 100^3, mean min angle; smoothed gmsh transfinite mesh 74.79"),
    "chunked_throughput_ratio": ("<=", 1.5, "x", "in-memory / chunked node throughput, 200^3 TFI to .cgns"),
    "chunked_openfoam_300_peak_megabytes": (
        "<=",
        1200.0,
        "MB",
        "peak memory of meshgen mesh --dims 300^3 --chunked --format openfoam (streamed polyMesh)",
    ),
    "chunked_openfoam_300_check_mesh": (">=", 1.0, "", "checkMesh says Mesh OK (1) on the chunked 300^3 OpenFOAM case"),
    "chunked_1000_peak_megabytes": ("<=", 4000.0, "MB", "peak memory of meshgen mesh --dims 1000 1000 1000 -o big.cgns"),
    "evaluate_chunked_1000_peak_megabytes": ("<=", 1500.0, "MB", "peak memory of meshgen evaluate of the 1000^3 file"),
    "evaluate_chunked_1000_seconds": ("<=", 600.0, "s", "meshgen evaluate of the 1000^3 .cgns file"),
    "chunked_500_quality_peak_megabytes": (
        "<=",
        1200.0,
        "MB",
        "peak memory of meshgen mesh --dims 500^3 --chunked, quality included",
    ),
    "chunked_1000_quality_peak_megabytes": (
        "<=",
        1500.0,
        "MB",
        "peak memory of meshgen mesh --dims 1000^3 --chunked, quality included",
    ),
    "shape_parametrise_seconds": ("<=", 2.0, "s", "one four-cornered patch of 200k triangles onto the square, 2 cores"),
    "shape_step_boundary_rel": (
        "<=",
        1e-7,
        "of L",
        "STEP loft, elliptic 20x20x40: largest boundary-node distance from the CAD surface",
    ),
    "shape_step_corners_rel": ("<=", 1e-9, "of L", "STEP loft: largest corner distance from the CAD vertices"),
    "shape_step_volume_rel": ("<=", 1e-3, "x", "STEP loft: mesh volume against OCC's mass, relative"),
    "shape_stl_boundary_rel": (
        "<=",
        1e-9,
        "of L",
        "bent STL duct, TFI and elliptic: largest boundary-node distance from the triangles",
    ),
    "fidelity_neural_ratio": (
        "<=",
        10.0,
        "x",
        "potentialFoam error of the bundled model's default mesh (meshgen mesh's) / the elliptic mesh's, semicylinder 20x20x40",
    ),
    "fidelity_neural_raw_ratio": (
        "<=",
        10.0,
        "x",
        "potentialFoam error of the bundled model's raw mesh (--no-polish) / the elliptic mesh's, semicylinder 20x20x40",
    ),
    "fidelity_neural_raw_ratio_60": (
        "<=",
        10.0,
        "x",
        "potentialFoam error of the bundled model's raw mesh (--no-polish) / the elliptic mesh's, semicylinder 60x60x120",
    ),
    "blocks_pipe_min_angle": (">=", 40.0, "deg", "pipe O-grid, elliptic: worst min angle at every resolution"),
    "blocks_pipe_max_angle": ("<=", 140.0, "deg", "pipe O-grid, elliptic: worst max angle at every resolution"),
    "blocks_pipe_potential": ("<=", 1e-6, "", "pipe 40 around x 80 along, elliptic, default tol: potentialFoam max |U - U_in|"),
    "blocks_dfg_34x20_elliptic_seconds": ("<=", 1.0, "s", "dfg-cylinder --dims 34 20 elliptic solve, warm process"),
    "blocks_pipe_1e6_ratio": (
        "<=",
        1.5,
        "x",
        "elliptic pipe 50 50 80 (1.0e6 hexahedra) / semicylinder 100^3 (1.0e6), seconds, one run",
    ),
    "sweep_worst_scaled_jacobian": (">=", 0.4, "", "swept CAD solids (the wing aside, TFI and elliptic): worst scaled Jacobian"),
    "sweep_wing_scaled_jacobian": (
        ">=",
        0.27,
        "",
        "swept NACA 0012 wing: worst scaled Jacobian (a cell holding the sharp trailing edge cannot exceed sin(16.5 deg) = 0.285)",
    ),
    "sweep_inverted": ("<=", 0, "", "swept CAD solids: inverted cells, all shapes and methods"),
    "sweep_boundary_distance": ("<=", 1e-6, "of L", "swept CAD solids: largest distance of a patch node from its CAD face"),
    "sweep_volume_error": (
        "<=",
        1e-2,
        "",
        "swept CAD solids: largest relative difference of the mesh's volume from the CAD volume",
    ),
    "sweep_cylinder_min_angle": (">=", 76.0, "deg", "CAD cylinder, elliptic: worst min angle (the built-in pipe's in the note)"),
    **{
        f"topology_{name}_{figure}": (
            comparison,
            target,
            unit,
            f"topology file {name} (TFI) against classy_blocks + blockMesh: {what}",
        )
        for name in ("karman", "elbow", "t_joint")
        for figure, comparison, target, unit, what in (
            ("non_orthogonality", "<=", 0.0, "deg", "checkMesh max non-orthogonality, meshgen's minus the anchor's"),
            ("skewness", "<=", 0.0, "", "checkMesh max skewness, meshgen's minus the anchor's"),
            ("cells", "abs<=", 0.1, "", "cell count / the anchor's - 1"),
            ("seconds", "<=", 1.0, "x", "seconds / the anchor's (script + blockMesh), same run"),
            ("elliptic", "<=", 0.0, "deg", "elliptic max non-orthogonality minus TFI's (blockMesh's at the same nodes)"),
        )
    },
    "dfg3d_drag_error": (
        "abs<=",
        1.0,
        "%",
        "DFG 3D-1Z from a topology file (at most 200,000 cells), simpleFoam: cD against 6.18533",
    ),
    "dfg3d_lift_error": (
        "abs<=",
        10.0,
        "%",
        "DFG 3D-1Z from a topology file (at most 200,000 cells), simpleFoam: cL against 0.009401",
    ),
    "gpu_elliptic_100_seconds": ("<=", 1.0, "s", "elliptic semicylinder 100^3 by the torch multigrid on the GPU"),
    "gpu_quality_1e9_seconds": ("<=", 60.0, "s", "the seven metrics and their summary of 1e9 hexahedra on one GPU"),
    "gpu_neural_1e9_seconds": (
        "<=",
        60.0,
        "s",
        "1e9 hexahedra of the bundled network made, corrected and quality-checked on one GPU, writing excluded",
    ),
    "airfoil_family_inverted": (
        "<=",
        0,
        "cells",
        "airfoil family: inverted cells over the held-out members (5^3 grid and 20 drawn)",
    ),
    "airfoil_family_first_cell_error": (
        "<=",
        0.03,
        "",
        "airfoil family: largest |first-cell height / asked - 1|, every wall node",
    ),
    "airfoil_family_wall_angle_degrees": (
        "<=",
        3.0,
        "deg",
        "airfoil family: largest angle of a first grid line off the wall normal",
    ),
    "airfoil_family_min_angle_below_elliptic": (
        "<=",
        1.0,
        "deg",
        "airfoil family: largest (member's elliptic mean min angle - its neural one) over the held-out members",
    ),
    "airfoil_family_mesh_seconds": ("<=", 0.05, "s", "airfoil family: a member's 57,344-cell mesh (network and finish), 2 cores"),
    "airfoil_family_training_seconds": ("<=", 1800.0, "s", "airfoil family: training the bundled model, 2 cores"),
    "airfoil_family_cl_difference": (
        "<=",
        0.5,
        "%",
        "airfoil family: |CL on the neural mesh / CL on the elliptic mesh - 1|, simpleFoam SA alpha 10, NACA 0012, 2412, 4415",
    ),
    "airfoil_family_cd_difference": ("<=", 2.0, "%", "airfoil family: the same of CD"),
    "airfoil_neural_mesh_seconds": ("<=", 0.1, "s", "airfoil C-grid 448 x 128 by a trained model (network and finish), 2 cores"),
    "airfoil_neural_min_angle_below_elliptic": (
        "<=",
        0.5,
        "deg",
        "airfoil: the elliptic mesh's mean min angle minus the neural mesh's, same run (negative: the network's is better)",
    ),
    "airfoil_neural_first_cell_error": ("<=", 0.02, "", "airfoil, neural: largest |first-cell height / asked - 1|"),
    "airfoil_mesh_seconds": ("<=", 5.0, "s", "airfoil C-grid 448 x 128 (57,344 cells, y+ 1 at Re 6e6), elliptic, 2 cores"),
    "airfoil_first_cell_error": ("<=", 0.02, "", "airfoil: largest |first-cell height / asked - 1| over the wall nodes"),
    "airfoil_wall_angle_degrees": ("<=", 2.0, "deg", "airfoil: largest angle of a first grid line off the wall normal"),
    "airfoil_expansion_ratio": ("<=", 1.15, "x", "airfoil: largest wall-normal expansion ratio (the cap)"),
    "airfoil_check_mesh_aspect_ratio": (
        "<=",
        1000.0,
        "",
        "airfoil C-grid 448 x 128, y+ 1: checkMesh max aspect ratio (its limit: above it, a failed check)",
    ),
    "airfoil_classy_blocks_non_orthogonality": (
        "<=",
        0.0,
        "deg",
        "NACA 2414 alpha 10, about 3,719 cells: checkMesh max non-orthogonality, meshgen minus classy_blocks' example",
    ),
    "airfoil_classy_blocks_skewness": (
        "<=",
        0.0,
        "",
        "NACA 2414 alpha 10, about 3,719 cells: checkMesh max skewness, meshgen minus classy_blocks' example",
    ),
    "airfoil_cl_alpha_10": (
        "abs<=",
        0.0125,
        "",
        "NACA 0012 alpha 10, simpleFoam SA, <= 60k cells: CL - 1.0875 (band 1.075-1.100)",
    ),
    "airfoil_cd_alpha_10": (
        "abs<=",
        0.0005,
        "",
        "NACA 0012 alpha 10, simpleFoam SA, <= 60k cells: CD - 0.0125 (band 0.0120-0.0130)",
    ),
    "dfg_10k_drag": ("abs<=", 0.1, "%", "DFG 2D-1 at most 10k cells: drag error against 5.5795"),
    "dfg_10k_lift": ("abs<=", 3.0, "%", "DFG 2D-1 at most 10k cells: lift error against 0.0106"),
    "dfg_10k_dp": ("abs<=", 0.5, "%", "DFG 2D-1 at most 10k cells: front-back pressure difference error against 0.1175"),
    "dfg_40k_drag": ("abs<=", 0.05, "%", "DFG 2D-1 at most 40k cells: drag error"),
    "dfg_40k_lift": ("abs<=", 1.0, "%", "DFG 2D-1 at most 40k cells: lift error"),
    "dfg_40k_dp": ("abs<=", 0.2, "%", "DFG 2D-1 at most 40k cells: pressure difference error"),
    "family_worst_degrees": ("<=", 0.5, "deg", "family: every member within 0.5 deg of its elliptic mesh, 0 inverted"),
    "exact_converged_seconds": ("<=", 15.0, "s", "training time of exact to converged quality on 2 cores"),
    "default_converged_seconds": ("<=", 90.0, "s", "training time of default to converged quality on 2 cores"),
    "train_exact_seconds": (
        "<=",
        30.0,
        "s",
        "meshgen train -g semicylinder --preset exact end to end (a subprocess: imports, layout, stages, checkpoints, summary), median of 3",
    ),
    "gpu_inference_501_seconds": ("<=", 1.0, "s", "forward pass of a [85]*4 network on 501^3 nodes on a GPU"),
    "paper_cuda_adam_seconds": ("<=", 60.0, "s", "paper's 12000 Adam steps, [85]*4, on a GPU"),
    "correction_angle_degrees": (
        ">=",
        -0.3,
        "deg",
        "corrected mesh within 0.3 degrees of the elliptic mesh, "
        "judged as at most 0.3 below it (a higher angle is a better mesh)",
    ),
}


# ---------------------------------------------------------------------------------------------
# helpers


def load_average() -> list[float]:
    return [round(value, 2) for value in os.getloadavg()]


def timed_runs(function, repeat: int) -> dict:
    """Wall and process CPU seconds of ``repeat`` calls of ``function``: median, min, max, all runs.
    The last call's return value is kept under ``"result"`` (not for JSON)."""
    walls, cpus, result = [], [], None
    for _ in range(repeat):
        wall, cpu = time.perf_counter(), time.process_time()
        result = function()
        walls.append(time.perf_counter() - wall)
        cpus.append(time.process_time() - cpu)
    return {
        "seconds": statistics.median(walls),
        "min_seconds": min(walls),
        "max_seconds": max(walls),
        "cpu_seconds": statistics.median(cpus),
        "runs_seconds": walls,
        "result": result,
    }


def judge(key: str, measured, judged: bool = True) -> dict:
    """A figure beside its target: {"measured", "target", "comparison", "unit", "source", "met"}
    (``met`` None when ``judged`` is False: the figure was measured at another size than the target's)."""
    comparison, target, unit, source = TARGETS[key]
    met = None
    if judged and measured is not None:
        met = {"<=": measured <= target, ">=": measured >= target, "abs<=": abs(measured) <= target}[comparison]
        met = bool(met)
    return {"measured": measured, "comparison": comparison, "target": target, "unit": unit, "source": source, "met": met}


def mark(met) -> str:
    return "not judged" if met is None else ("met" if met else "NOT met")


def section_header(title: str) -> None:
    print(f"\n== {title} (load average {load_average()[0]:.2f})", flush=True)


# ---------------------------------------------------------------------------------------------
# machine


def processor_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def git_commit() -> str | None:
    try:
        result = subprocess.run(
            ["git", "-C", str(REPO), "rev-parse", "--short", "HEAD"], capture_output=True, text=True, timeout=10
        )
        dirty = subprocess.run(
            ["git", "-C", str(REPO), "status", "--porcelain", "--untracked-files=no"], capture_output=True, text=True, timeout=10
        ).stdout.strip()
        return result.stdout.strip() + ("+modified" if dirty else "") if result.returncode == 0 else None
    except (OSError, subprocess.SubprocessError):
        return None


def memory_gigabytes() -> float | None:
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 1e9
    except (ValueError, OSError, AttributeError):
        return None


def machine(quick: bool) -> dict:
    import bench_inference
    import torch

    import meshgen

    memory = memory_gigabytes()
    data = {
        "cpus": os.cpu_count(),
        "usable_cpus": len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count(),
        "processor": processor_name(),
        "platform": platform.platform(),
        "memory_gigabytes": memory,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "torch": torch.__version__,
        "torch_threads": torch.get_num_threads(),
        "omp_wait_policy": os.environ.get("OMP_WAIT_POLICY"),
        "meshgen": meshgen.__version__,
        "git_commit": git_commit(),
        "matmul": bench_inference.matmul_rates(4096, 3 if quick else 5),
    }
    roof = data["matmul"]
    print(
        f"{data['processor']}, {data['usable_cpus']} of {data['cpus']} cores, {memory or 0:.0f} GB; python {data['python']}, "
        f"numpy {data['numpy']}, torch {data['torch']} ({data['torch_threads']} threads), meshgen {data['meshgen']} "
        f"({data['git_commit']})"
    )
    print(
        f"float32 matrix product {roof['size']}^2: {roof['gflops']:.0f} GFLOP/s (best of {roof['repeats']}), "
        f"{roof['gflops_per_cpu_second']:.0f} GFLOP per CPU second"
    )
    return data


# ---------------------------------------------------------------------------------------------
# meshing


def bundled_model():
    """The model bundled for the semicylinder (what ``meshgen mesh`` uses where ./runs/ has none)."""
    from meshgen.neural.models import bundled_models, load_model

    folder = bundled_models()[GEOMETRY]
    record = json.loads((folder / "model.json").read_text()) if (folder / "model.json").is_file() else {}
    return load_model(folder / "checkpoint.pt", source="bundled", record=record)


def meshing(quick: bool, roof: dict | None) -> dict:
    """Each method through ``make_mesh`` (as ``meshgen mesh`` calls it) at 30^3 (and 100^3), then
    the network's forward pass alone against the matrix-product roof."""
    import bench_inference
    import torch

    from meshgen.geometry.plugins import load_geometry
    from meshgen.methods.registry import make_mesh
    from meshgen.methods.tfi import parametric_grid
    from meshgen.neural.model import MLP, describe
    from meshgen.neural.network_map import evaluate_network

    geometry = load_geometry(GEOMETRY)
    model = bundled_model()
    sizes = [30] if quick else [30, 100]
    options = {"tfi": {}, "elliptic": {}, "neural": {"model": model}}
    rows = []
    print("method      cells  median s   min s   max s   cpu s  runs  notes")
    for method, extra in options.items():
        make_mesh(method, geometry, parametric_grid((8, 8, 8)), **extra)  # warm up: imports, threads
        # elliptic 100^3 has a target of its own (elliptic_100_seconds): measured in --quick too, once
        for n in [30, 100] if method == "elliptic" else sizes:
            repeat = (1 if n >= 100 else 2) if quick else (3 if method == "elliptic" and n >= 100 else 5)
            coords = parametric_grid((n, n, n))
            timing = timed_runs(lambda: make_mesh(method, geometry, coords, **extra), repeat)
            X, info = timing.pop("result")
            notes = {}
            if method == "elliptic":
                notes = {"iterations": info["iterations"], "converged": bool(info["converged"])}
            elif method == "neural":
                notes = {
                    "model": f"bundled {model.preset()} {list(model.checkpoint['model']['widths'])}",
                    "raw_boundary_error_max": info["correction"]["error_before"]["max"],
                }
            row = {"method": method, "cells_per_axis": n, "cells": n**3, "repeat": repeat, **timing, **notes}
            rows.append(row)
            print(
                f"{method:<10}{n:>5}^3{row['seconds']:>10.3f}{row['min_seconds']:>8.3f}{row['max_seconds']:>8.3f}"
                f"{row['cpu_seconds']:>8.3f}{repeat:>6}  " + ", ".join(f"{k} {v}" for k, v in notes.items()),
                flush=True,
            )

    # The forward pass alone: the bundled model at each size (a section network: the section's nodes,
    # which meshgen extrudes), and the [85]*4 network of the target.
    networks = [(f"bundled {model.preset()}", model.checkpoint["model"], n + 1) for n in sizes]
    torch.manual_seed(0)
    paper = describe(MLP(3, PAPER_WIDTHS), PAPER_WIDTHS, False, [0.0, 0.0, 0.0], 1.0)
    networks.append(("random [85]*4", paper, 101))
    forward = []
    print(f"\nforward pass alone (NumPy, evaluate_network){'':6}nodes  GFLOP  median s   cpu s  fraction of the roof")
    for label, description, nodes in networks:
        dim = int(description.get("dim", 3))
        coords = [np.linspace(0.0, 1.0, nodes)] * dim
        evaluate_network(description, coords)  # warm up
        timing = timed_runs(lambda: evaluate_network(description, coords), 3 if quick else 5)
        timing.pop("result")
        gflop = bench_inference.network_flops(description["widths"], dim, nodes**dim) / 1e9
        roof_seconds = gflop / roof["gflops"] if roof else None
        row = {
            "network": label,
            "widths": list(description["widths"]),
            "nodes_per_axis": nodes,
            "dim": dim,
            "nodes": nodes**dim,
            "gflop": gflop,
            **timing,
            "roof_seconds": roof_seconds,
            "fraction_of_roof": roof_seconds / timing["seconds"] if roof else None,
            # the same per CPU second: what a busy machine changes less
            "fraction_of_roof_per_cpu_second": gflop / timing["cpu_seconds"] / roof["gflops_per_cpu_second"] if roof else None,
        }
        forward.append(row)
        fraction = f"{row['fraction_of_roof']:.0%} (per CPU second {row['fraction_of_roof_per_cpu_second']:.0%})" if roof else "-"
        print(
            f"{label + ' ' + str(row['widths']):<38}{nodes:>6}^{dim}{gflop:>7.1f}{row['seconds']:>10.3f}"
            f"{row['cpu_seconds']:>8.3f}  {fraction}",
            flush=True,
        )
    # The anchor beside the elliptic 100^3 row: gmsh's smoothed transfinite semicylinder, the same mesh.
    import bench_layout

    gmsh = bench_layout.gmsh_extruded(100)
    if gmsh is not None:
        print(f"gmsh {gmsh['version']}, smoothed transfinite semicylinder 100^3: meshing {gmsh['meshing_seconds']:.2f} s "
              f"(process {gmsh['process_seconds']:.2f} s, {gmsh['smoothing_steps']} smoothing steps)", flush=True)  # fmt: skip
    return {"geometry": GEOMETRY, "methods": rows, "forward_pass": forward, "gmsh_100": gmsh}


# ---------------------------------------------------------------------------------------------
# the mesh command, end to end, and its memory


def mesh_command(cells: int, folder: Path, options=()) -> dict:
    """``bench_inference.mesh_command`` in the environment this process started with (so without
    the OMP_WAIT_POLICY set above, which ``meshgen mesh`` does not set)."""
    import bench_inference

    return bench_inference.mesh_command(cells, folder, _USER_ENVIRONMENT, options)


def mesh_command_section(quick: bool) -> dict:
    repeat = 1 if quick else 3
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        mesh_command(10, folder)  # warm the file cache (torch's libraries) for the timed runs
        runs = [mesh_command(100, folder) for _ in range(repeat)]
        unpolished = [mesh_command(100, folder, ["--no-polish"]) for _ in range(repeat)]
        polished = [mesh_command(100, folder, ["--polish"]) for _ in range(repeat)]
    seconds = [run["seconds"] for run in runs]
    data = {
        "command": "meshgen mesh --dims 100 100 100 -o out.vtu -q (bundled model)",
        "cells": 100**3,
        "repeat": repeat,
        "seconds": statistics.median(seconds),
        "min_seconds": min(seconds),
        "max_seconds": max(seconds),
        "cpu_seconds": statistics.median(run["cpu_seconds"] for run in runs),
        "peak_megabytes": max(run["peak_megabytes"] for run in runs),
        "megabytes_written": runs[-1]["megabytes_written"],
        "runs": runs,
        "no_polish_seconds": statistics.median(run["seconds"] for run in unpolished),
        "no_polish_cpu_seconds": statistics.median(run["cpu_seconds"] for run in unpolished),
        "no_polish_runs": unpolished,
        "default_polished": all(run["polished"] for run in runs),
        "polish_seconds": statistics.median(run["seconds"] for run in polished),
        "polish_cpu_seconds": statistics.median(run["cpu_seconds"] for run in polished),
        "polish_runs": polished,
    }
    print(
        f"{data['command']}: median {data['seconds']:.2f} s of {repeat} (CPU {data['cpu_seconds']:.2f} s), "
        f"peak memory {data['peak_megabytes']:.0f} MB (summed over its processes), {data['megabytes_written']:.0f} MB written; "
        f"{'polished' if data['default_polished'] else 'not polished'} (the model's default); "
        f"with --no-polish: median {data['no_polish_seconds']:.2f} s (CPU {data['no_polish_cpu_seconds']:.2f} s); "
        f"with --polish: median {data['polish_seconds']:.2f} s (CPU {data['polish_cpu_seconds']:.2f} s)"
    )
    return data


def memory_section(quick: bool) -> dict:
    cells = 100 if quick else 200
    with tempfile.TemporaryDirectory() as folder:
        run = mesh_command(cells, Path(folder))
    data = {
        "command": f"meshgen mesh --dims {cells} {cells} {cells} -o out.vtu -q (bundled model)",
        "cells_per_axis": cells,
        "cells": cells**3,
        **run,
    }
    print(
        f"{data['command']}: peak memory {run['peak_megabytes']:.0f} MB, {run['seconds']:.1f} s "
        f"(CPU {run['cpu_seconds']:.1f} s), {run['megabytes_written']:.0f} MB written"
    )
    return data


def chunked_section(quick: bool) -> dict:
    import bench_chunked

    return bench_chunked.measure(quick)


# ---------------------------------------------------------------------------------------------
# training


def training(quick: bool) -> dict:
    import bench_train
    import torch

    from meshgen.geometry.plugins import load_geometry

    geometry = load_geometry(GEOMETRY)
    sizes = {"default": bench_train.SIZES["default"]} if quick else bench_train.SIZES
    repeats = 5 if quick else 20
    print(
        f"seconds per Adam step, median of {repeats}; 4096 interior (16^3 grid nodes or random points) + "
        f"6000 boundary points; torch {torch.get_num_threads()} threads"
    )
    rows = bench_train.step_table(geometry, sizes, repeats, extras=not quick)
    ratios, cpu_ratios = bench_train.ratios(rows), bench_train.ratios(rows, "cpu_seconds_per_step")
    for size, values in ratios.items():
        for name, value in values.items():
            cpu = f" (of CPU seconds {cpu_ratios[size][name]:.2f}x)" if name in cpu_ratios[size] else ""
            print(f"  {size:8s} {name}: {value:.2f}{'' if 'overhead' in name else 'x'}{cpu}")
    return {
        "geometry": GEOMETRY,
        "interior_points": 4096,
        "boundary_points": 6000,
        "repeat": repeats,
        "sizes": {name: list(widths) for name, widths in sizes.items()},
        "steps": rows,
        "ratios": ratios,
        "ratios_of_cpu_seconds": cpu_ratios,
        "fd_ad_pairs": {name: list(pair) for name, pair in bench_train.AD_FD_PAIRS.items()},
    }


def time_to_quality(quick: bool) -> dict:
    import bench_train

    from meshgen.geometry.plugins import load_geometry

    table = bench_train.speed_table(load_geometry(GEOMETRY), quick=quick)
    table["train_exact"] = train_exact_command(quick)
    return table


def train_exact_command(quick: bool) -> dict:
    """``meshgen train -g semicylinder --preset exact`` as a user runs it, in a subprocess (imports,
    the layout, every stage, the checkpoints and the summary): wall and CPU seconds (the child's
    user + system), median of 3; --quick: once, with 50 Adam and 5 L-BFGS steps (not judged)."""
    capped = ["--set", "adam.steps=50", "--set", "lbfgs.steps=5"] if quick else []
    walls, cpus = [], []
    for _ in range(1 if quick else 3):
        with tempfile.TemporaryDirectory() as folder:
            command = [sys.executable, "-m", "meshgen", "train", "-g", GEOMETRY, "--preset", "exact", "--seed", "0"]
            command += ["--out", str(Path(folder) / "run"), "-q", *capped]
            before = os.times()
            start = time.perf_counter()
            subprocess.run(command, check=True, env={**os.environ, "PYTHONPATH": str(REPO)}, stdout=subprocess.DEVNULL)
            walls.append(time.perf_counter() - start)
            after = os.times()
            cpus.append(after.children_user - before.children_user + after.children_system - before.children_system)
    result = {"seconds": statistics.median(walls), "cpu_seconds": statistics.median(cpus), "runs_seconds": walls, "capped": quick}
    print(
        f"meshgen train --preset exact: {result['seconds']:.1f} s (CPU {result['cpu_seconds']:.1f} s){', capped' if quick else ''}"
    )
    return result


def correction(quick: bool) -> dict:
    import bench_correction

    return bench_correction.run(quick)


def boundary_layout(quick: bool) -> dict:
    import bench_layout

    results = bench_layout.run(quick)
    measured = {r["cells"]: r.get("gmsh_smoothed_min_angle_mean") for r in results if r["geometry"] == "semicylinder"}
    return {
        "results": results,
        "gmsh_smoothed_semicylinder": measured,
        "gmsh_smoothed_semicylinder_quoted": bench_layout.GMSH_SMOOTHED,
    }


def shapes(quick: bool) -> dict:
    import bench_shapes

    return bench_shapes.run(quick)


def fidelity(quick: bool) -> dict:
    import bench_fidelity

    return bench_fidelity.run(quick)


def blocks_neural(quick: bool) -> dict:
    import bench_blocks_neural

    return bench_blocks_neural.run(quick)


def blocks(quick: bool) -> dict:
    import bench_blocks

    return bench_blocks.run(quick)


def airfoil(quick: bool) -> dict:
    import bench_airfoil

    return bench_airfoil.run(quick)


def airfoil_family(quick: bool) -> dict:
    import bench_airfoil_family

    return bench_airfoil_family.run(quick)


def sweeps(quick: bool) -> dict:
    import bench_sweeps

    return {**bench_sweeps.run(quick), "quick": quick}  # --quick: about 10 cells across, not the targets' 20


def topology(quick: bool) -> dict:
    import bench_topology

    data = bench_topology.run(1 if quick else 3)
    if not quick:  # DFG 3D-1Z with simpleFoam on two levels (60,640 and 180,902 cells, the judged one): minutes
        sys.path.insert(0, str(REPO / "examples" / "dfg"))
        import run_dfg3d

        with tempfile.TemporaryDirectory() as folder:
            data["dfg3d"] = [run_dfg3d.run(r, case=Path(folder) / f"dfg3d-{r}", quiet=True) for r in (1.0, 1.45)]
    return data


def gpu(quick: bool) -> dict:
    import bench_gpu

    return bench_gpu.measure(("elliptic", "quality", "neural") if quick else bench_gpu.ROWS)


def family(quick: bool) -> dict:
    import bench_family

    return bench_family.run(quick)


# ---------------------------------------------------------------------------------------------
# evaluate, formats


def evaluate(quick: bool) -> dict:
    import bench_quality

    quick_cases = [
        ("structured", "cell_metrics"),
        ("unstructured", bench_quality.REPORT),
        ("chunked", bench_quality.CHUNKED_FILE),
    ]
    cases = quick_cases if quick else bench_quality.CASES
    data = bench_quality.measure((100, 100, 100), 2 if quick else 5, cases)
    data["first_call"] = bench_quality.first_call()
    data["cli"] = bench_quality.evaluate_cli((100, 100, 100), 5)
    data["cli_vtu"] = bench_quality.evaluate_cli((100, 100, 100), 5, ".vtu")
    bench_quality.print_table(data)
    rows = [
        {
            "path": r["path"],
            "what": r["what"],
            "cells": r["cells"],
            "seconds": r["median_s"],
            "min_seconds": r["min_s"],
            "max_seconds": r["max_s"],
            "cpu_seconds": r["median_cpu_s"],
            "runs_seconds": r["runs_s"],
            "cells_per_second": r["cells"] / r["median_s"],
        }
        for r in data["results"]
    ]
    return {
        "geometry": GEOMETRY,
        "mesh": "TFI",
        "dims": data["dims"],
        "cells": data["cells"],
        "repeat": data["repeat"],
        "results": rows,
        "first_call": data["first_call"],
        "cli": data["cli"],
        "cli_vtu": data["cli_vtu"],
    }


def formats(quick: bool) -> dict:
    import formats as formats_benchmark

    from meshgen.geometry.plugins import load_geometry
    from meshgen.methods.tfi import tfi

    cells = 50 if quick else 100
    repeat = 1 if quick else 3
    data = formats_benchmark.formats_table(tfi(load_geometry(GEOMETRY), (cells,) * 3), repeat)
    rows = [
        {
            "format": r["format"] + (" (baseline: meshio's own writer)" if r["format"] == "meshio vtu" else ""),
            "write_seconds": r["write_s"],
            "read_seconds": r["read_s"],
            "megabytes": r["size_mb"],
        }
        for r in data["results"]
    ]
    return {
        "geometry": GEOMETRY,
        "mesh": "TFI, one cell-data array and the metadata",
        "cells_per_axis": cells,
        "cells": cells**3,
        "repeat": repeat,
        "timing": f"best of {repeat}",
        "results": rows,
    }


def solver_formats(quick: bool) -> dict:
    import bench_solver_formats

    cells = 50 if quick else 100
    geometry, X = bench_solver_formats.make_mesh("neural", cells)
    data = bench_solver_formats.measure(X, geometry, 1 if quick else 3)
    bench_solver_formats.print_table(data)
    return data


# ---------------------------------------------------------------------------------------------
# the summary


def summary(sections: dict) -> list[dict]:  # noqa: C901 - one flat list of rows, one block per benchmark
    """The headline figures, each with its target (where one is set) and met / not met. ``cpu``:
    the process CPU seconds beside a wall time (all threads; on a loaded machine the wall time
    grows more), None where not measured."""
    rows = []

    def add(figure, value, unit, key=None, judged=True, note="", cpu=None):
        row = {"figure": figure, "value": value, "unit": unit, "cpu_seconds": cpu, "note": note}
        if key is not None:
            row.update(key=key, **{k: v for k, v in judge(key, value, judged).items() if k != "measured"})
        rows.append(row)

    if "machine" in sections:
        roof = sections["machine"]["matmul"]
        add(
            f"float32 matrix product {roof['size']}^2, {roof['threads']} threads (the roof)",
            roof["gflops"],
            "GFLOP/s",
            note=f"{roof['gflops_per_cpu_second']:.0f} GFLOP per CPU second",
        )
    if "meshing" in sections:
        for row in sections["meshing"]["methods"]:
            n = row["cells_per_axis"]
            key = {("elliptic", 100): "elliptic_100_seconds", ("elliptic", 30): "elliptic_30_seconds"}.get((row["method"], n))
            note = {"elliptic": f"{row.get('iterations')} cycles", "neural": f"{row.get('model')}, corrected"}.get(
                row["method"], ""
            )
            add(
                f"mesh {n}^3 cells, {row['method']} (median of {row['repeat']})",
                row["seconds"],
                "s",
                key,
                note=note,
                cpu=row["cpu_seconds"],
            )
        gmsh = sections["meshing"].get("gmsh_100")
        elliptic_100 = [
            row for row in sections["meshing"]["methods"] if row["method"] == "elliptic" and row["cells_per_axis"] == 100
        ]
        if gmsh and elliptic_100:
            add("elliptic 100^3 / gmsh smoothed transfinite 100^3", elliptic_100[0]["seconds"] / gmsh["meshing_seconds"], "x",
                key="elliptic_100_over_gmsh", note=f"gmsh {gmsh['version']} {gmsh['meshing_seconds']:.2f} s")  # fmt: skip
        for row in sections["meshing"]["forward_pass"]:
            n = row["nodes_per_axis"]
            fraction = (
                f"{row['fraction_of_roof']:.0%} of the roof ({row['fraction_of_roof_per_cpu_second']:.0%} per CPU second)"
                if row["fraction_of_roof"]
                else ""
            )
            add(
                f"network forward pass, {row['network']}, {n}^{row.get('dim', 3)} nodes",
                row["seconds"],
                "s",
                "inference_101_seconds" if row["widths"] == PAPER_WIDTHS and n == 101 else None,
                note=fraction,
                cpu=row["cpu_seconds"],
            )
    if "boundary_layout" in sections:
        for result in sections["boundary_layout"]["results"]:
            n = result["cells"]
            for method, row in result["methods"].items():
                key = f"elliptic_min_angle_{n}" if (result["geometry"], method) == (GEOMETRY, "elliptic smoothed") else None
                add(
                    f"mean min angle, {result['geometry']} {n}^3, {method} layout",
                    row["min_angle_mean"],
                    "deg",
                    key,
                    note=f"{row['inverted']} inverted, deviation {row['deviation_max_rel']:.1e}, "
                    f"{format_value(row['seconds'], 's')}",
                )
            if result.get("gmsh_smoothed_min_angle_mean") is not None:
                add(
                    f"mean min angle, {result['geometry']} {n}^3, gmsh's smoothed transfinite mesh (section, converged)",
                    result["gmsh_smoothed_min_angle_mean"],
                    "deg",
                    None,
                    note="the reference for the smoothed layout",
                )
    if "mesh_command" in sections:
        data = sections["mesh_command"]
        add(
            f"`meshgen mesh --dims 100 100 100 -o out.vtu`, end to end (median of {data['repeat']})",
            data["seconds"],
            "s",
            "mesh_command_100_seconds",
            cpu=data["cpu_seconds"],
            note=f"peak memory {data['peak_megabytes']:.0f} MB (its processes summed); "
            + (
                "polished (the model's default)"
                if data.get("default_polished", True)
                else "not polished (the model's default: exact boundary, trained on the lattice)"
            ),
        )
        if "no_polish_seconds" in data:
            add(
                f"`meshgen mesh --dims 100 100 100 -o out.vtu --no-polish`, end to end (median of {data['repeat']})",
                data["no_polish_seconds"],
                "s",
                "mesh_command_100_no_polish_seconds",
                cpu=data["no_polish_cpu_seconds"],
            )
        if "polish_seconds" in data:
            add(
                f"`meshgen mesh --dims 100 100 100 -o out.vtu --polish`, end to end (median of {data['repeat']})",
                data["polish_seconds"],
                "s",
                cpu=data["polish_cpu_seconds"],
                note="the network's mesh polished to the discrete Winslow equations (no target)",
            )
    if "training" in sections:
        data = sections["training"]
        for row in data["steps"]:
            if row["variant"] in bench_variants():
                add(
                    f"training step, {row['variant']} {row['widths']}",
                    row["seconds_per_step"],
                    "s",
                    cpu=row["cpu_seconds_per_step"],
                )
        for size, values in data["ratios"].items():
            for name in data["fd_ad_pairs"]:
                add(
                    f"FD/AD step ratio, {name}, {data['sizes'][size]}",
                    values[name],
                    "x",
                    "fd_ad_step_ratio",
                    note=f"{data['ratios_of_cpu_seconds'][size][name]:.2f}x of CPU seconds",
                )
    if "time_to_quality" in sections:
        data = sections["time_to_quality"]
        stepped = set()
        for row in data["rows"]:
            where = "cuda" if row["device"] == "cuda" else f"cpu x{row['threads']}"
            name = f"{row['preset']}, {where}"
            if name not in stepped:  # the step times do not depend on the layout
                stepped.add(name)
                add(f"training step, {name}, Adam", row["adam_seconds_per_step"], "s")
                add(f"training step, {name}, L-BFGS", row["lbfgs_seconds_per_step"], "s")
            name += f", {row.get('layout', 'smoothed')} layout"
            if row["device"] == "cuda" and row["preset"] == "paper":
                add(
                    f"whole run, {name}, {row['adam_steps']} Adam steps",
                    row["training_seconds"],
                    "s",
                    "paper_cuda_adam_seconds" if row["adam_steps"] >= 12000 else None,
                )
            for milestone, label in (("first_valid", "valid, better than TFI"), ("first_converged", "converged")):
                point = row[milestone]
                key = {
                    ("exact", "first_converged", "cpu", 2): "exact_converged_seconds",
                    ("default", "first_converged", "cpu", 2): "default_converged_seconds",
                }.get((row["preset"], milestone, row["device"], row["threads"]))
                note = f"step {point['step']} of {row['steps']}" if point else f"not reached in {row['steps']} steps"
                note += ", capped budget" if row["capped"] else ""
                add(
                    f"time to {label}, {name}, 30^3 corrected mesh",
                    point["seconds"] if point else None,
                    "s",
                    key,
                    judged=not (row["capped"] and row["preset"] != "paper"),
                    note=note,
                )
        if data["cuda_skipped"]:
            add("CUDA rows", None, "s", note=f"skipped: {data['cuda_skipped']}")
        if "train_exact" in data:
            run = data["train_exact"]
            add(
                "meshgen train --preset exact, end to end, cpu x2",
                run["seconds"],
                "s",
                "train_exact_seconds",
                judged=not run["capped"],
                cpu=run["cpu_seconds"],
                note="50 Adam + 5 L-BFGS steps (--quick)" if run["capped"] else f"median of {len(run['runs_seconds'])}",
            )
    if "correction" in sections:
        data = sections["correction"]
        for row in data["rows"]:
            c = row["corrected"]
            add(
                f"default on {row['geometry']}, corrected {row['cells_per_axis']}^3: min angle minus elliptic's",
                row["min_angle_mean_difference_degrees"],
                "deg",
                "correction_angle_degrees",
                judged=not data["capped"],
                note=f"{c['inverted']} inverted, boundary deviation {c['boundary_deviation_max_rel']:.1e} of the length; "
                f"raw network {row['raw_inverted']} inverted, boundary error {row['raw_boundary_error']['max_rel']:.1e}",
            )
    if "family" in sections:
        data = sections["family"]
        for name, case in data["cases"].items():
            ranges = " ".join(f"{k}={lo:g}:{hi:g}" for k, (lo, hi) in case["ranges"].items())
            capped = ", capped budget" if data["quick"] else ""
            add(
                f"family training, {name} {ranges}",
                case["training"]["seconds"],
                "s",
                cpu=case["training"]["cpu_seconds"],
                note=f"{case['training']['steps']} steps{capped}",
            )
            add(
                f"family member mesh {case['cells_per_axis']}^3, {name} (median of {len(case['members'])})",
                case["meshing_seconds_median"],
                "s",
            )
            worst = case["worst"]
            at = ", ".join(f"{k}={v:.3g}" for k, v in worst["params"].items())
            add(
                f"family worst member (inverted cells first, then angle), {name}: |min angle - elliptic's|",
                abs(worst["difference_degrees"]),
                "deg",
                "family_worst_degrees",
                judged=not data["quick"],
                note=f"{at}: {worst['inverted']} inverted, boundary deviation {worst['boundary_deviation_max_rel']:.1e} "
                f"of the length, {worst['min_angle_mean']:.2f} vs {worst['elliptic_min_angle_mean']:.2f}",
            )
            if worst["inverted"] and not data["quick"]:
                rows[-1]["met"] = False  # an inverted cell fails the target whatever the angles
    if "evaluate" in sections:
        data = sections["evaluate"]
        headlines = {
            ("unstructured", "quality_report + boundary deviation"): "evaluate_1e6_seconds",
            ("structured", "cell_metrics"): "quality_kernels_1e6_seconds",
            ("chunked", "chunked_report of the .cgns file"): "quality_chunked_1e6_seconds",
        }
        for row in data["results"]:
            add(
                f"evaluate {row['cells']:,} cells, {row['path']} {row['what']}",
                row["seconds"],
                "s",
                headlines.get((row["path"], row["what"])),
                judged=row["cells"] >= 1e6,
                cpu=row["cpu_seconds"],
            )
        if "cli" in data:
            cli = data["cli"]
            add(
                f"`meshgen evaluate` of the 100^3 .vts, end to end (median of {len(cli['runs_seconds'])}, after a warm-up)",
                cli["seconds"],
                "s",
                "evaluate_cli_100_seconds",
                cpu=cli["cpu_seconds"],
                note=f"bytecode {cli.get('bytecode', 'as found')}; a Python loop of 6e6 multiply-adds {cli.get('python_loop_seconds', float('nan')):.2f} s just before",
            )
        if "cli_vtu" in data:
            cli = data["cli_vtu"]
            add(
                f"`meshgen evaluate` of the 100^3 .vtu, end to end (median of {len(cli['runs_seconds'])}, after a warm-up)",
                cli["seconds"],
                "s",
                cpu=cli["cpu_seconds"],
                note="meshgen mesh's default format: no extent to read first",
            )
        if "first_call" in data:
            first = data["first_call"]
            add("first cell_metrics in a new installation (numba compiles; import included)", first["compile_seconds"], "s")
            add("first cell_metrics in a later process (numba's cache loaded; import included)", first["cached_seconds"], "s")
    if "formats" in sections:
        data = sections["formats"]
        for row in data["results"]:
            add(
                f"write {data['cells_per_axis']}^3 cells, {row['format']}",
                row["write_seconds"],
                "s",
                note=f"{row['megabytes']:.1f} MB; read {format_value(row['read_seconds'], 's')}",
            )
    if "solver_formats" in sections:
        data = sections["solver_formats"]
        n = data["cells_per_axis"]
        for row in data["results"]:
            add(
                f"write {n}^3 cells with patches, {row['format']} ({data['mesh']}, median of {data['repeat']})",
                row["write_seconds"],
                "s",
                cpu=row["write_cpu_seconds"],
                note=f"{row['megabytes']:.1f} MB; read {format_value(row['read_seconds'], 's')}",
            )
        ratios = data["vts_vs_vtu"]
        add(f".vts size / .vtu size, {n}^3", ratios["size_ratio"], "x", "vts_vtu_size_ratio", judged=n == 100)
        add(
            f".vts write time / .vtu write time, {n}^3",
            ratios["write_time_ratio"],
            "x",
            "vts_vtu_write_time_ratio",
            judged=n == 100,
        )
    if "memory" in sections:
        data = sections["memory"]
        add(
            f"peak memory, `meshgen mesh --dims {data['cells_per_axis']} {data['cells_per_axis']} "
            f"{data['cells_per_axis']} -o out.vtu`",
            data["peak_megabytes"],
            "MB",
            "peak_memory_200_megabytes",
            judged=data["cells_per_axis"] == 200,
            note=f"{format_value(data['seconds'], 's')} end to end",
        )
    if "chunked" in sections:
        data = sections["chunked"]
        same, big = data["same_size_cells_per_axis"], data["big_cells_per_axis"]
        for name, ratio in data["throughput_ratio_in_memory_over_chunked"].items():
            method = "neural" if name.startswith("neural") else "TFI"
            add(
                f"in-memory / chunked node throughput, {method} {same}^3 to .cgns, {name.replace('neural_', '').replace('_', ' ')}",
                ratio,
                "x",
                "chunked_throughput_ratio",
                judged=same == 200,
            )
        row = data["big"]
        add(
            f"peak memory, `meshgen mesh -m tfi --dims {big}^3 --chunked --no-quality -o big.cgns`",
            row["peak_megabytes"],
            "MB",
            "chunked_1000_peak_megabytes",
            judged=big == 1000,
            note=f"{row['seconds']:.0f} s, {row['nodes_per_second'] / 1e6:.2f} M nodes/s",
        )
        if "big_quality" in data:
            row = data["big_quality"]
            add(
                f"peak memory, `meshgen mesh -m tfi --dims {big}^3 --chunked -o big.cgns` (quality included)",
                row["peak_megabytes"],
                "MB",
                {500: "chunked_500_quality_peak_megabytes", 1000: "chunked_1000_quality_peak_megabytes"}.get(big),
                note=f"{row['seconds']:.0f} s",
            )
        row = data["evaluate_big"]
        add(
            f"peak memory, `meshgen evaluate --chunked` of the {big}^3 file",
            row["peak_megabytes"],
            "MB",
            "evaluate_chunked_1000_peak_megabytes",
            judged=big == 1000,
            note=f"{row['seconds']:.0f} s, {row['cells_per_second'] / 1e6:.2f} M cells/s",
        )
        add(
            f"`meshgen evaluate --chunked` of the {big}^3 file",
            row["seconds"],
            "s",
            "evaluate_chunked_1000_seconds",
            judged=big == 1000,
            cpu=row["cpu_seconds"],
        )
        if "openfoam" in data:
            row = data["openfoam"]
            cells = row["cells_per_axis"]
            add(
                f"peak memory, `meshgen mesh -m tfi --dims {cells}^3 --chunked --no-quality --format openfoam`",
                row["peak_megabytes"],
                "MB",
                "chunked_openfoam_300_peak_megabytes",
                judged=cells == 300,
                note=f"{row['seconds']:.0f} s, {row['megabytes_written']:.0f} MB written",
            )
            checked = row["check_mesh"]
            add(
                f"checkMesh on the chunked {cells}^3 OpenFOAM case: Mesh OK (1) or not (0)",
                None if "skipped" in checked else float(checked["mesh_ok"]),
                "",
                "chunked_openfoam_300_check_mesh",
                judged=cells == 300 and "skipped" not in checked,
                note=checked.get("skipped") or f"checkMesh {checked['seconds']:.0f} s, peak {checked['peak_megabytes']:.0f} MB",
            )
        gpu = data["gpu_inference"]
        add(
            "GPU inference, 501^3 nodes, [85]*4",
            gpu.get("seconds"),
            "s",
            "gpu_inference_501_seconds",
            note=gpu.get("skipped") or f"{gpu['device']}, into one float64 host array",
        )
    if "shapes" in sections:
        shape = sections["shapes"]
        row = shape["parametrise"]
        add(f"parametrise a patch of {row['triangles']} triangles (median of 3)", row["seconds_median"], "s",
            key="shape_parametrise_seconds", judged=row["triangles"] >= 150_000,
            note=f"foldover-free: {row['foldover_free']}")  # fmt: skip
        if "step_loft" in shape:
            row = shape["step_loft"]
            note = f"elliptic {'x'.join(map(str, row['dims']))}, {row['inverted']} inverted"
            add(
                "STEP loft: boundary nodes from the CAD surface",
                row["boundary_distance_max_rel"],
                "of L",
                key="shape_step_boundary_rel",
                note=note,
            )
            add("STEP loft: corners from the CAD vertices", row["corner_distance_max_rel"], "of L", key="shape_step_corners_rel")
            add("STEP loft: mesh volume against OCC's mass", row["volume_rel_error"], "x", key="shape_step_volume_rel")
        row = shape["stl_duct"]
        for method in ("tfi", "elliptic"):
            add(f"STL duct ({row['triangles']} triangles), {method}: boundary nodes from the triangles",
                row[method]["boundary_distance_max_rel"], "of L", key="shape_stl_boundary_rel",
                note=f"{row[method]['inverted']} inverted")  # fmt: skip
    if "fidelity" in sections and sections["fidelity"].get("rows"):
        for row in sections["fidelity"]["rows"]:
            label = row["method"]
            if row.get("default") and label.startswith("bundled") and tuple(row["dims"]) == (20, 20, 40):
                add(  # the mesh a user gets: polished or not, as the model's default says
                    f"potentialFoam error, bundled network's default mesh ({'raw' if 'raw' in label else 'polished'}) "
                    f"/ elliptic, {'x'.join(map(str, row['dims']))}",
                    row["max_velocity_error"] / row["elliptic_error"],
                    "x",
                    key="fidelity_neural_ratio",
                )
            if row.get("elliptic_error") and "raw" not in label:  # a polished network's mesh
                add(
                    f"potentialFoam error, {label} network polished / elliptic, {'x'.join(map(str, row['dims']))}",
                    row["max_velocity_error"] / row["elliptic_error"],
                    "x",
                )
            elif row.get("elliptic_error"):  # the network's own mesh, no polish
                add(
                    f"potentialFoam error, {label} network / elliptic, {'x'.join(map(str, row['dims']))}",
                    row["max_velocity_error"] / row["elliptic_error"],
                    "x",
                    key={(20, 20, 40): "fidelity_neural_raw_ratio", (60, 60, 120): "fidelity_neural_raw_ratio_60"}.get(
                        tuple(row["dims"])
                    )
                    if label == "bundled, raw"
                    else None,
                )
    if "blocks_neural" in sections and not sections["blocks_neural"].get("skipped"):
        data = sections["blocks_neural"]
        model = data["model"]
        for row in data["rows"]:
            if row["mesh"] == "elliptic":
                continue
            add(
                f"pipe {' '.join(map(str, row['dims']))}, {row['mesh']}: mean min angle - elliptic's",
                row["difference_degrees"],
                "deg",
                note=f"{row['inverted']} inverted, interface gap {row['interface_gap_max']:.0e}, {row['sweeps']} sweeps",
            )
        add(
            "neural pipe model (default mesh): worst |mean min angle - elliptic's| of 2 resolutions",
            data["worst_difference_degrees"],
            "deg",
            "neural_pipe_min_angle_degrees",
            judged=data["judged"],
            note=f"model {model['bytes'] // 1000} kB, {model['steps']} steps, trained {model['training_seconds']:.0f} s",
        )
        if data["judged"] and not data["met"]:
            rows[-1]["met"] = False  # an inverted cell or a gap fails the target whatever the angles
        if "training" in data:
            add(
                "meshgen train -g pipe, end to end, cpu x2",
                data["training"]["seconds"],
                "s",
                "train_pipe_seconds",
                cpu=data["training"]["cpu_seconds"],
                note="the model of the rows above, trained in this run",
            )
    if "blocks" in sections:
        data = sections["blocks"]
        elliptic = [row for row in data.get("pipe", []) if row["method"] == "elliptic"]
        if elliptic:
            sizes = ", ".join(" ".join(map(str, row["dims"])) for row in elliptic)
            add(f"pipe elliptic ({sizes}): worst min angle", min(row["worst_min_angle"] for row in elliptic), "deg",
                key="blocks_pipe_min_angle", note=f"{sum(row['inverted'] for row in elliptic)} inverted")  # fmt: skip
            add(f"pipe elliptic ({sizes}): worst max angle", max(row["worst_max_angle"] for row in elliptic), "deg",
                key="blocks_pipe_max_angle")  # fmt: skip
        for row in data.get("pipe", []):
            if row.get("potential_error") is not None:
                add(f"pipe {' '.join(map(str, row['dims']))} elliptic: potentialFoam max |U - U_in|", row["potential_error"], "",
                    key="blocks_pipe_potential", note=f"{row['sweeps']} sweeps, default tol")  # fmt: skip
        speed = data.get("speed")
        if speed:
            add("dfg-cylinder 34 20 elliptic solve", speed["dfg_34x20"]["seconds"], "s", key="blocks_dfg_34x20_elliptic_seconds",
                note=f"{speed['dfg_34x20']['cycles']} V-cycles")  # fmt: skip
            add("elliptic pipe 50 50 80 / semicylinder 100^3", speed["pipe_over_semicylinder"], "x", key="blocks_pipe_1e6_ratio",
                note=f"{speed['pipe_50_50_80']['seconds']:.2f} s (section, extruded) / {speed['semicylinder_100']['seconds']:.2f} s")  # fmt: skip
            if "pipe_50_50_80_3d" in speed:
                add("elliptic pipe 50 50 80 by the 3D multigrid / semicylinder 100^3", speed["pipe_3d_over_semicylinder"], "x",
                    note=f"{speed['pipe_50_50_80_3d']['seconds']:.1f} s, {speed['pipe_50_50_80_3d']['cycles']} V-cycles; not an extrusion's path")  # fmt: skip
        for row in data.get("dfg", []):
            budget = {0.001: "10k", 0.0005: "40k"}.get((row.get("targets") or {}).get("drag"))
            for name in ("drag", "lift", "dp"):
                add(f"DFG 2D-1 --dims {' '.join(map(str, row['dims']))} ({row['cells']} cells): {name} error",
                    100 * row[f"{name}_error"], "%", key=f"dfg_{budget}_{name}" if budget else None,
                    note="" if row["converged"] else "simpleFoam did not converge")  # fmt: skip
    if "airfoil" in sections:
        mesh = sections["airfoil"]["mesh"]
        add(f"airfoil C-grid {mesh['cells']} cells, elliptic", mesh["seconds"], "s", key="airfoil_mesh_seconds")
        add("airfoil: first-cell height error, every wall node", mesh["first_cell_error"], "", key="airfoil_first_cell_error",
            note=f"h = {mesh['first_cell_height']:.3e} chord")  # fmt: skip
        add("airfoil: first grid line off the wall normal", mesh["worst_wall_angle_degrees"], "deg", key="airfoil_wall_angle_degrees",
            note="trailing edge excepted")  # fmt: skip
        add("airfoil: wall-normal expansion ratio", mesh["largest_expansion_ratio"], "x", key="airfoil_expansion_ratio",
            note=f"{mesh['inverted']} inverted")  # fmt: skip
        if mesh.get("check_mesh"):
            cm = mesh["check_mesh"]
            add("airfoil: checkMesh max non-orthogonality", cm["max_non_orthogonality"], "deg",
                note=f"max skewness {cm['max_skewness']}; {'Mesh OK' if cm['mesh_ok'] else str(cm['failed_checks']) + ' failed'}")  # fmt: skip
            add("airfoil: checkMesh max aspect ratio", cm["max_aspect_ratio"], "", key="airfoil_check_mesh_aspect_ratio")
        anchor = sections["airfoil"].get("classy_blocks") or {}
        ours, theirs = anchor.get("meshgen"), anchor.get("classy_blocks")
        if ours and theirs:
            said = f"meshgen {ours['cells']} cells {ours['seconds']:.1f} s; classy_blocks {theirs['version']} {theirs['cells']} cells {theirs['seconds']:.1f} s"
            add("NACA 2414 alpha 10: max non-orthogonality, meshgen - classy_blocks",
                ours["max_non_orthogonality"] - theirs["max_non_orthogonality"], "deg", key="airfoil_classy_blocks_non_orthogonality",
                note=f"{ours['max_non_orthogonality']:.1f} vs {theirs['max_non_orthogonality']:.1f}; {said}")  # fmt: skip
            add("NACA 2414 alpha 10: max skewness, meshgen - classy_blocks", ours["max_skewness"] - theirs["max_skewness"], "",
                key="airfoil_classy_blocks_skewness", note=f"{ours['max_skewness']:.2f} vs {theirs['max_skewness']:.2f}")  # fmt: skip
        elif ours:
            add("NACA 2414 alpha 10 (3,700 cells): meshgen max non-orthogonality", ours["max_non_orthogonality"], "deg",
                note=f"max skewness {ours['max_skewness']:.2f}; classy_blocks skipped: {anchor.get('skipped')}")  # fmt: skip
        neural = sections["airfoil"].get("neural")
        if neural:
            add(f"airfoil C-grid {neural['cells']} cells, neural (trained model)", neural["seconds"], "s", key="airfoil_neural_mesh_seconds",
                note=f"meshgen.mesh {neural['request_seconds']:.3f} s; trained {neural['training_seconds']:.0f} s")  # fmt: skip
            add("airfoil: elliptic mean min angle - neural's", neural["min_angle_below_elliptic"], "deg",
                key="airfoil_neural_min_angle_below_elliptic", note=f"{neural['inverted']} inverted")  # fmt: skip
            add("airfoil, neural: first-cell height error", neural["first_cell_error"], "", key="airfoil_neural_first_cell_error",
                note=f"wall angle {neural['worst_wall_angle_degrees']:.2f} deg")  # fmt: skip
        solved = sections["airfoil"].get("simplefoam_alpha_10")
        if solved:
            note = f"{solved['cells']} cells, y+ mean {solved['yplus']['average']:.2f} max {solved['yplus']['max']:.2f}"
            add("NACA 0012 alpha 10: CL - 1.0875", solved["CL"] - 1.0875, "", key="airfoil_cl_alpha_10",
                note=f"CL {solved['CL']:.4f} (x Prandtl-Glauert {solved['CL_prandtl_glauert']:.4f}); {note}")  # fmt: skip
            add("NACA 0012 alpha 10: CD - 0.0125", solved["CD"] - 0.0125, "", key="airfoil_cd_alpha_10",
                note=f"CD {solved['CD']:.5f}; {'converged' if solved['converged'] else 'NOT converged'}")  # fmt: skip
    if sections.get("airfoil_family"):
        family_rows(sections["airfoil_family"], add)
    if sections.get("sweeps"):
        sweep_rows(sections["sweeps"], add)
    if sections.get("topology"):
        topology_rows(sections["topology"], add)
        if sections["topology"].get("dfg3d"):
            dfg3d_rows(sections["topology"]["dfg3d"], add)
    if "gpu" in sections and "skipped" not in sections["gpu"]:
        gpu_rows(sections["gpu"], add)
    return rows


def family_rows(data: dict, add) -> None:
    """The airfoil family's rows (``bench_airfoil_family``)."""
    held, speed, trained = data["held_out"], data["speed"], data["training"]
    grid = f"{held['grid_points']}^3 grid and {held['drawn']} drawn"
    full = held["grid_points"] == 5 and held["drawn"] == 20  # the targets' members (--quick: fewer, not judged)
    add(f"airfoil family, {held['members']} held-out members ({grid}): inverted cells", held["inverted"], "cells",
        key="airfoil_family_inverted", judged=full, note=", ".join(str(m) for m in held["members_with_inverted"][:3]))  # fmt: skip
    add("airfoil family: first-cell height error, every wall node", held["first_cell_error"], "",
        key="airfoil_family_first_cell_error", judged=full)  # fmt: skip
    add("airfoil family: first grid line off the wall normal", held["wall_angle_degrees"], "deg",
        key="airfoil_family_wall_angle_degrees", judged=full)  # fmt: skip
    worst = ", ".join(f"{k} {v:.3g}" for k, v in held["worst_member"].items())
    add("airfoil family: worst member's elliptic mean min angle - neural's", held["worst_below_elliptic"], "deg",
        key="airfoil_family_min_angle_below_elliptic", judged=full, note=worst)  # fmt: skip
    add(f"airfoil family: a member's {speed['cells']}-cell mesh (median of {len(speed['runs_seconds'])})", speed["seconds"], "s",
        key="airfoil_family_mesh_seconds", note=f"elliptic {speed['elliptic_seconds']:.2f} s, {speed['elliptic_over_network']:.0f}x")  # fmt: skip
    solved = data.get("solver")
    if solved:  # a full run with OpenFOAM
        iterations = f"{solved['iterations']} iterations at most, {' x '.join(map(str, solved['dims']))}"
        add("airfoil family: simpleFoam CL, neural vs elliptic mesh (worst of 3 members)", 100 * solved["cl_difference"], "%",
            key="airfoil_family_cl_difference", note=iterations)  # fmt: skip
        add("airfoil family: simpleFoam CD, neural vs elliptic mesh (worst of 3 members)", 100 * solved["cd_difference"], "%",
            key="airfoil_family_cd_difference", note=iterations)  # fmt: skip
    add("airfoil family: training (the model's own clock)", trained["seconds"], "s", key="airfoil_family_training_seconds",
        note=f"{data['checkpoint']}, {data['model_bytes'] // 1000} kB, {trained['steps']} steps")  # fmt: skip


def sweep_rows(data: dict, add) -> None:
    """The rows of the ``sweeps`` section (``bench_sweeps.run``): each target over every shape and
    method, the worst case named."""
    shapes = {name: row for name, row in data.items() if name.startswith("sweep_")}
    judged = not data.get("quick")
    methods = ("tfi", "elliptic", "neural")
    figures = [
        (name[len("sweep_") :], method, row[method]) for name, row in shapes.items() for method in methods if method in row
    ]

    def worst(key, largest=True):
        pick = max if largest else min
        shape, method, row = pick(figures, key=lambda f: f[2][key])
        return row[key], f"{shape} ({method})"

    wing = [f for f in figures if f[0] == "wing"]
    figures_without_wing = [f for f in figures if f[0] != "wing"]
    shape, method, row = min(figures_without_wing, key=lambda f: f[2]["scaled_jacobian_min"])
    add("swept CAD solids (the wing aside): worst scaled Jacobian", row["scaled_jacobian_min"], "",
        key="sweep_worst_scaled_jacobian", judged=judged, note=f"{shape} ({method})")  # fmt: skip
    if wing:
        add("swept NACA 0012 wing: worst scaled Jacobian", min(f[2]["scaled_jacobian_min"] for f in wing), "",
            key="sweep_wing_scaled_jacobian", judged=judged, note="the cell at the trailing edge; elliptic keeps the TFI mesh")  # fmt: skip
    add("swept CAD solids: inverted cells", sum(f[2]["inverted"] for f in figures), "", key="sweep_inverted", judged=judged,
        note=f"{len(shapes)} shapes, {len(figures)} meshes (neural: {sum(f[1] == 'neural' for f in figures)}); checkMesh OK on {sum(bool(f[2]['checkmesh_ok']) for f in figures)} of {len(figures)}")  # fmt: skip
    trained = [f[2]["training_seconds"] for f in figures if "training_seconds" in f[2]]
    if trained:
        add("swept CAD solids: meshgen train, longest", max(trained), "s", judged=judged,
            note=f"{len(trained)} solids, the networks fitted to each one's elliptic mesh; median {sorted(trained)[len(trained) // 2]:.0f} s")  # fmt: skip
    value, where = worst("boundary_distance_max_rel")
    add(
        "swept CAD solids: patch node distance from its CAD face",
        value,
        "of L",
        key="sweep_boundary_distance",
        judged=judged,
        note=where,
    )
    value, where = worst("volume_rel_error")
    add("swept CAD solids: volume error", value, "", key="sweep_volume_error", judged=judged, note=where)
    cylinder = data.get("sweep_cylinder")
    if cylinder:
        add("CAD cylinder, elliptic: worst min angle", cylinder["elliptic"]["min_angle_min"], "deg", key="sweep_cylinder_min_angle", judged=judged,
            note=f"built-in pipe at the same counts: {cylinder['pipe_min_angle_min']:.1f} deg")  # fmt: skip


def topology_rows(data: dict, add) -> None:
    """The rows of the ``topology`` section (``bench_topology.run``): meshgen's TFI mesh of each
    example's topology file against classy_blocks' script + blockMesh in the same run, and the
    elliptic mesh's max non-orthogonality beside the TFI's (blockMesh's, at the same nodes)."""
    for name, entry in data.get("examples", {}).items():
        anchor, tfi, elliptic = entry.get("anchor"), entry.get("tfi"), entry.get("elliptic")
        if anchor is None or tfi is None:
            why = entry.get("anchor_skipped") or entry.get("tfi_skipped")
            add(f"topology {name}: classy_blocks anchor", None, "", note=f"skipped: {why}")
        if tfi is not None and elliptic is not None:
            add(f"topology {name} (elliptic): max non-orthogonality - blockMesh's", elliptic["max_non_orthogonality"] - tfi["max_non_orthogonality"],
                "deg", key=f"topology_{name}_elliptic", note=f"{elliptic['max_non_orthogonality']:.1f}; max skewness {elliptic['max_skewness']:.3f}; {elliptic['seconds']:.1f} s")  # fmt: skip
        if anchor is None or tfi is None:
            continue
        lines = f"{tfi['input_lines']} input lines against {anchor['input_lines']}"
        add(f"topology {name} (TFI): max non-orthogonality - classy_blocks'", tfi["max_non_orthogonality"] - anchor["max_non_orthogonality"],
            "deg", key=f"topology_{name}_non_orthogonality", note=f"{tfi['max_non_orthogonality']:.1f} against {anchor['max_non_orthogonality']:.1f}")  # fmt: skip
        add(f"topology {name} (TFI): max skewness - classy_blocks'", tfi["max_skewness"] - anchor["max_skewness"], "",
            key=f"topology_{name}_skewness", note=f"{'Mesh OK' if tfi['mesh_ok'] else 'checkMesh FAILED'}; {lines}")  # fmt: skip
        add(f"topology {name} (TFI): cells / classy_blocks' - 1", tfi["cells"] / anchor["cells"] - 1.0, "",
            key=f"topology_{name}_cells", note=f"{tfi['cells']} cells")  # fmt: skip
        add(f"topology {name} (TFI): seconds / classy_blocks + blockMesh's", tfi["seconds"] / anchor["seconds"], "x",
            key=f"topology_{name}_seconds", note=f"{tfi['seconds']:.1f} s against {anchor['seconds']:.1f} s")  # fmt: skip


def dfg3d_rows(levels: list, add) -> None:
    """DFG 3D-1Z (``examples/dfg/run_dfg3d.py``): drag and lift errors per level, the finest judged."""
    for number, row in enumerate(levels):
        finest = number == len(levels) - 1
        note = f"{row['cells']} cells, {row['iterations']} iterations"
        add(f"DFG 3D-1Z refine {row['refine']:g}: cD error", 100 * row["drag_error"], "%",
            key="dfg3d_drag_error" if finest else None, note=f"cD {row['drag']:.5f}; {note}")  # fmt: skip
        add(f"DFG 3D-1Z refine {row['refine']:g}: cL error", 100 * row["lift_error"], "%",
            key="dfg3d_lift_error" if finest else None, note=f"cL {row['lift']:.6f}")  # fmt: skip


def gpu_rows(data: dict, add) -> None:
    """The rows of the ``gpu`` section (``bench_gpu.measure``), each with its CPU figure of the same
    run in the note."""
    device = data["device"]
    row = data.get("elliptic", {})
    if "seconds_extruded" in row:
        add(f"elliptic {row['cells']}^3 on {device} (the method's path: section on the device, extruded; tol {row['tol']:g})",
            row["seconds_extruded"], "s", key="gpu_elliptic_100_seconds",
            note=f"CPU solver {row['cpu_seconds']:.2f} s, same mesh to {row['diff_extruded']:.1e} L; "
            f"full 3D grid on the device {row['seconds_3d']:.2f} s ({row['diff_3d']:.1e} L)")  # fmt: skip
    row = data.get("quality", {})
    if "seconds" in row:
        worst = max(row["agreement"]["max_abs_difference"].values())
        add(f"quality of {row['cells']:.1e} hexahedra on {device}", row["seconds"], "s", key="gpu_quality_1e9_seconds",
            note=f"numba on the host's {row['cpu']['cores']} cores: {row['cpu']['cells_per_second']:.2e} cells/s; "
            f"a 1e6-cell block agrees with numba to {worst:.1e}")  # fmt: skip
    row = data.get("neural", {})
    if "seconds" in row:
        add(f"neural {row['cells']:.1e} hexahedra made, corrected, checked on {device}", row["seconds"], "s",
            key="gpu_neural_1e9_seconds",
            note=f"copy to host {row['copy_to_host_seconds'] or 0:.1f} s apart; CPU path {row['cpu']['cells_per_second']:.2e} cells/s")  # fmt: skip
    for name, row in data.get("training", {}).items():
        if "training_seconds" in row:
            add(f"train {name.replace('_', ' ')}", row["training_seconds"], "s",
                note=f"test loss {row['test_loss']['total']:.4g}, mean min angle {row['min_angle_mean']:.2f}")  # fmt: skip


def bench_variants():
    import bench_train

    return bench_train.VARIANTS


def format_value(value, unit) -> str:
    if value is None:
        return "-"
    if unit in ("GFLOP/s", "MB"):
        return f"{value:.0f} {unit}"
    if unit == "x":
        return f"{value:.2f}x" if value >= 0.01 or value == 0 else f"{value:.2g}x"
    if unit not in ("s", "deg"):  # a relative figure ("of L") or a count
        return f"{value:.3g} {unit}"
    if unit == "deg":
        return f"{value:.3f}°"
    if unit == "s" and value < 1:
        return f"{value * 1e3:.3g} ms"
    return f"{value:.3g} s" if value < 100 else f"{value:.0f} s"


def target_text(row) -> str:
    if "target" not in row:
        return ""
    unit = "x" if row["unit"] == "x" else f" {row['unit']}"
    if row["comparison"] == "abs<=":
        return f"within ±{row['target']:g}{unit}"
    return f"{row['comparison']} {row['target']:g}{unit}"


def print_summary(rows: list[dict]) -> None:
    width = max(len(row["figure"]) for row in rows)
    print(f"\n{'figure':<{width}}  {'measured':>11}  {'CPU':>9}  {'target':>11}  {'verdict':<10}  note")
    print("-" * (width + 60))
    for row in rows:
        verdict = mark(row["met"]) if "target" in row else ""
        print(
            f"{row['figure']:<{width}}  {format_value(row['value'], row['unit']):>11}  "
            f"{format_value(row['cpu_seconds'], 's') if row['cpu_seconds'] is not None else '':>9}  "
            f"{target_text(row):>11}  {verdict:<10}  {row['note']}"
        )


def markdown(results: dict) -> str:
    """The summary as a README section: date, machine, a table of figures and targets, what the
    figures mean, how to repeat them."""
    machine_data = results["sections"].get("machine", {})
    lines = [
        f"Measured {results['date'][:10]} by `{results['command']}` (meshgen {machine_data.get('meshgen', '?')}, "
        f"commit {machine_data.get('git_commit') or git_commit() or '?'}) on {machine_data.get('processor') or processor_name()}, "
        f"{machine_data.get('usable_cpus') or len(os.sched_getaffinity(0))} cores, {machine_data.get('memory_gigabytes') or memory_gigabytes() or 0:.0f} GB, "
        f"Python {machine_data.get('python', '?')}, torch {machine_data.get('torch', '?')}, numpy "
        f"{machine_data.get('numpy', '?')}; load average {results['load_average']['start'][0]:.1f} at the start and "
        f"{results['load_average']['end'][0]:.1f} at the end (other jobs shared the machine); the whole run took "
        f"{results['run']['wall_seconds'] / 60:.0f} min.",
        "",
        "| figure | measured | CPU | target | met | note |",
        "|---|---:|---:|---|---|---|",
    ]
    for row in results["summary"]:
        verdict = mark(row["met"]) if "target" in row else ""
        cpu = format_value(row["cpu_seconds"], "s") if row["cpu_seconds"] is not None else ""
        lines.append(
            f"| {row['figure']} | {format_value(row['value'], row['unit'])} | {cpu} | "
            f"{target_text(row).replace('<=', '≤').replace('>=', '≥')} | {verdict} | {row['note']} |"
        )
    lines += [
        "",
        "Times are wall seconds (medians); CPU is the process's CPU time over all threads: on a busy "
        "machine the wall time grows with the load, the CPU time much less. A row that names no geometry is "
        "of the semicylinder; a neural row says which model it meshes with (the bundled one, or one the run trains).",
    ]
    if results["sections"].get("time_to_quality"):
        lines += [
            "",
            "Time to quality: training seconds (the measurements' own time left out) until the 30^3 mesh of "
            "the network, corrected to N + TFI[g - N] as `meshgen mesh` writes it, has no inverted cell and a "
            "mean minimum angle above TFI's (valid, better than TFI), and until that angle is within 0.3° of "
            "the elliptic mesh's (converged; the run stops there).",
        ]
    lines += [
        "",
        "Reproduce (10 to 15 minutes on 2 cores; `--quick`, for CI, under 2 minutes with smaller sizes and capped training):",
        "",
        "    python benchmarks/run.py --json benchmarks.json --markdown benchmarks.md",
        "",
    ]
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="small sizes and budgets, for CI (a few minutes)")
    parser.add_argument("--json", type=Path, default=None, help="write every figure to this JSON file")
    parser.add_argument("--markdown", type=Path, default=None, help="write the summary table as Markdown")
    parser.add_argument("--only", choices=SECTIONS, action="append", help="run only this section (repeatable)")
    parser.add_argument(
        "--from-json",
        type=Path,
        default=None,
        metavar="FILE",
        help="measure nothing: print (and with --markdown write) the summary of an earlier run's JSON",
    )
    args = parser.parse_args(argv)
    if args.from_json:
        results = json.loads(args.from_json.read_text())
        results["summary"] = summary(results["sections"])
        print_summary(results["summary"])
        if args.markdown:
            args.markdown.write_text(markdown(results))
            print(f"wrote {args.markdown}")
        return 0

    chosen = [name for name in SECTIONS if not args.only or name in args.only]
    command = "python benchmarks/run.py" + (" --quick" if args.quick else "") + "".join(f" --only {s}" for s in args.only or [])
    started, started_cpu = time.perf_counter(), time.process_time()
    results = {
        "benchmark": "meshgen",
        "command": command,
        "quick": args.quick,
        "date": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "load_average": {"start": load_average()},
        "targets": {key: {"comparison": c, "target": t, "unit": u, "source": src} for key, (c, t, u, src) in TARGETS.items()},
        "sections": {},
    }
    print(f"{command}  ({results['date']})")
    from bytecode import compile_bytecode

    results["bytecode"] = compile_bytecode()  # the commands timed in subprocesses start as a user's do
    runners = {
        "machine": lambda: machine(args.quick),
        "meshing": lambda: meshing(args.quick, results["sections"].get("machine", {}).get("matmul")),
        "boundary_layout": lambda: boundary_layout(args.quick),
        "mesh_command": lambda: mesh_command_section(args.quick),
        "training": lambda: training(args.quick),
        "time_to_quality": lambda: time_to_quality(args.quick),
        "family": lambda: family(args.quick),
        "correction": lambda: correction(args.quick),
        "evaluate": lambda: evaluate(args.quick),
        "formats": lambda: formats(args.quick),
        "solver_formats": lambda: solver_formats(args.quick),
        "memory": lambda: memory_section(args.quick),
        "chunked": lambda: chunked_section(args.quick),
        "shapes": lambda: shapes(args.quick),
        "fidelity": lambda: fidelity(args.quick),
        "blocks_neural": lambda: blocks_neural(args.quick),
        "blocks": lambda: blocks(args.quick),
        "airfoil": lambda: airfoil(args.quick),
        "airfoil_family": lambda: airfoil_family(args.quick),
        "sweeps": lambda: sweeps(args.quick),
        "topology": lambda: topology(args.quick),
        "gpu": lambda: gpu(args.quick),
    }
    for name in chosen:
        section_header(name)
        before, wall, cpu = load_average(), time.perf_counter(), time.process_time()
        data = runners[name]()
        data["section"] = {
            "wall_seconds": time.perf_counter() - wall,
            "cpu_seconds": time.process_time() - cpu,
            "load_average_before": before,
            "load_average_after": load_average(),
        }
        results["sections"][name] = data
    results["load_average"]["end"] = load_average()
    results["run"] = {
        "wall_seconds": time.perf_counter() - started,
        "cpu_seconds": time.process_time() - started_cpu,
        "note": "cpu_seconds: this process only (subprocess commands are in their sections)",
    }
    results["summary"] = summary(results["sections"])
    print_summary(results["summary"])
    print(
        f"\nwhole run: {results['run']['wall_seconds']:.0f} s wall, {results['run']['cpu_seconds']:.0f} s CPU; "
        f"load average {results['load_average']['start'][0]:.2f} -> {results['load_average']['end'][0]:.2f}"
    )
    if args.json:
        args.json.write_text(json.dumps(results, indent=2, default=float) + "\n")
        print(f"wrote {args.json}")
    if args.markdown:
        args.markdown.write_text(markdown(results))
        print(f"wrote {args.markdown}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Benchmark of ``meshgen train``: seconds per training step of every variant at the same point
counts (finite differences against autograd), the per-step overhead beyond the network's forward
and backward passes, and time-to-quality of the ``default`` and ``exact`` presets on the
semicylinder (30^3 mesh: inverted cells, inverted after snapping the boundary, boundary deviation,
mean minimum angle, next to TFI's).

    python benchmarks/bench_train.py [--quick] [--json FILE] [--threads N]

--quick: fewer repetitions, default sizes only, and shortened training runs (a smoke test, not
the figures to report).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")  # as meshgen train does, before torch is imported

import numpy as np  # noqa: E402
import torch  # noqa: E402

from meshgen.geometry import load_geometry  # noqa: E402
from meshgen.neural.checkpoint import load_checkpoint  # noqa: E402
from meshgen.neural.config import resolve_config  # noqa: E402
from meshgen.neural.model import MLP, mesh_from_checkpoint, normalisation, normalised_boundary  # noqa: E402
from meshgen.neural.reweighting import UncertaintyWeights  # noqa: E402
from meshgen.neural.train import Problem, adam_step, boundary_pool, make_optimizer, snapped, train  # noqa: E402
from meshgen.quality import quality_report  # noqa: E402
from meshgen.tfi import parametric_grid  # noqa: E402

VARIANTS = ["default", "fd-pinn", "exact", "pinn", "mgnet", "rwgp-pinn"]
SIZES = {"default": [48, 48, 48], "paper": [85, 85, 85, 85]}


def setup(preset, widths, geometry, interior=4096, boundary=6000):
    """A network, weights, optimiser and the problem of ``preset`` at the given sizes (16^3 grid
    nodes for fd, as many random points for autograd)."""
    config = resolve_config(preset, None, [f"model.widths={widths}", f"points.interior={interior}",
                                           f"points.boundary={boundary}"])
    center, scale = normalisation(geometry)
    problem = Problem(geometry.dim, normalised_boundary(geometry, center, scale), center, scale,
                      config.model.exact_boundary, torch.device("cpu"))
    torch.manual_seed(0)
    network = MLP(geometry.dim, config.model.widths)
    weights = UncertaintyWeights(learned=config.method.reweighting)
    optimizer, scheduler = make_optimizer("adam", network, weights, config)
    return config, problem, network, weights, optimizer, scheduler, boundary_pool(problem, config)


def step_times(presets, widths, geometry, repeats):
    """{preset: (wall, process CPU) seconds of one Adam step}, each the median of ``repeats`` steps
    after three warm-up steps. The presets take their steps in turn (one step of each per round),
    so a change in the load of a shared machine slows all of them alike and leaves their ratios."""
    states = {}
    for preset in presets:
        config, problem, network, weights, optimizer, scheduler, pool = setup(preset, widths, geometry)
        generator = torch.Generator().manual_seed(0)
        step = (lambda network=network, weights=weights, problem=problem, config=config, optimizer=optimizer,
                scheduler=scheduler, generator=generator, pool=pool:
                adam_step(network, weights, problem, config, optimizer, scheduler, generator, pool))
        for _ in range(3):
            step()
        states[preset] = (step, [], [])
    for _ in range(repeats):
        for step, walls, cpus in states.values():
            wall, cpu = time.perf_counter(), time.process_time()
            step()
            walls.append(time.perf_counter() - wall)
            cpus.append(time.process_time() - cpu)
    return {preset: (float(np.median(walls)), float(np.median(cpus))) for preset, (_, walls, cpus) in states.items()}


def seconds_per_step(preset, widths, geometry, repeats):
    return step_times([preset], widths, geometry, repeats)[preset][0]


def forward_backward_seconds(widths, dim, points, repeats):
    """The floor of a step: forward and backward of the MLP on ``points`` inputs, nothing else."""
    torch.manual_seed(0)
    network = MLP(dim, widths)
    inputs = torch.rand((points, dim))
    times = []
    for _ in range(repeats + 3):
        start = time.perf_counter()
        network(inputs).square().sum().backward()
        times.append(time.perf_counter() - start)
    return float(np.median(times[3:]))


def step_table(geometry, sizes, repeats, extras=True):
    """Seconds per Adam step of every variant at each of ``sizes`` ({name: widths}); ``extras``
    adds the default preset inside the training loop and the forward+backward floor."""
    rows = []
    for size_name, widths in sizes.items():
        times = step_times(VARIANTS, widths, geometry, repeats)
        for preset in VARIANTS:
            seconds, cpu = times[preset]
            derivatives = resolve_config(preset).method.derivatives
            rows.append({"sizes": size_name, "widths": widths, "variant": preset, "derivatives": derivatives,
                         "seconds_per_step": seconds, "cpu_seconds_per_step": cpu})
            print(f"  {size_name:8s} {preset:10s} {derivatives:9s} {seconds * 1e3:8.2f} ms/step ({cpu * 1e3:.2f} ms CPU)",
                  flush=True)
        if not extras:
            continue
        loop = loop_seconds_per_step(geometry, widths, 60 + 2 * repeats)
        rows.append({"sizes": size_name, "widths": widths, "variant": "default inside the training loop",
                     "derivatives": "fd", "seconds_per_step": loop})
        print(f"  {size_name:8s} default inside the training loop: {loop * 1e3:.2f} ms/step", flush=True)
        # the floor: one forward and backward pass over the points an fd step evaluates
        grid_nodes = (16 + 2) ** geometry.dim + 6000
        floor = forward_backward_seconds(widths, geometry.dim, grid_nodes, repeats)
        rows.append({"sizes": size_name, "widths": widths, "variant": "forward+backward only",
                     "derivatives": "-", "seconds_per_step": floor})
        print(f"  {size_name:8s} forward+backward of {grid_nodes} points: {floor * 1e3:.2f} ms", flush=True)
    return rows


# autograd variant / finite-difference variant with the same switches otherwise: the FD/AD step ratio
AD_FD_PAIRS = {"pinn / fd-pinn": ("pinn", "fd-pinn"), "rwgp-pinn / default (3dmeshnet)": ("rwgp-pinn", "default")}


def ratios(rows, key="seconds_per_step"):
    """autograd / fd seconds per step (``key``: or ``cpu_seconds_per_step``) for the matching pairs
    (same switches otherwise), and the overheads when ``step_table`` measured its extras."""
    by = {(r["sizes"], r["variant"]): r.get(key) for r in rows}
    out = {}
    for size in dict.fromkeys(r["sizes"] for r in rows):
        out[size] = {name: by[(size, ad)] / by[(size, fd)] for name, (ad, fd) in AD_FD_PAIRS.items()}
        if key != "seconds_per_step":
            continue
        if (size, "forward+backward only") in by:
            out[size]["default overhead over forward+backward"] = by[(size, "default")] / by[(size, "forward+backward only")] - 1
            out[size]["training-loop overhead over the step"] = by[(size, "default inside the training loop")] / by[(size, "default")] - 1
    return out


class RowKeeper:
    """A reporter that keeps the history rows."""

    def __init__(self):
        self.rows = []

    def stage(self, name, done, total):
        pass

    def message(self, text):
        pass

    def update(self, row, done, total):
        self.rows.append(row)


def loop_seconds_per_step(geometry, widths, steps):
    """Seconds per Adam step inside ``train``: the step plus what the loop adds (divergence-guard
    snapshot, history row, finiteness check), from the rows' clocks between steps 50 and ``steps``."""
    config = resolve_config("default", None, [f"model.widths={widths}", "points.interior=4096", "pretrain.steps=0",
                                              f"adam.steps={steps}", "lbfgs.steps=0", "checkpoint.every=100000"])
    keeper = RowKeeper()
    with tempfile.TemporaryDirectory() as folder:
        train(config, geometry, folder, reporter=keeper, summary=False)
    return (keeper.rows[-1]["seconds"] - keeper.rows[50]["seconds"]) / (steps - 1 - 50)


def figures(report: dict) -> dict:
    """The few figures of a ``meshgen.quality`` report that time-to-quality follows."""
    deviation = report.get("boundary_deviation") or {}
    return {
        "inverted": report["inverted"]["count"],
        "min_angle_mean": report["metrics"]["min_angle"]["mean"],
        "max_angle_mean": report["metrics"]["max_angle"]["mean"],
        "boundary_deviation_max": deviation.get("max"),
        "boundary_deviation_mean": deviation.get("mean"),
        "boundary_deviation_max_rel": deviation.get("max_rel"),
    }


# When a network's mesh counts as good, for time-to-quality: its 30^3 mesh of the semicylinder
# (boundary nodes where the network puts them, not snapped) against these bounds. The angle bound
# is relative to the two classical meshes of the same size: a mean minimum angle only just above
# TFI's is reached within a few steps by any map that starts from TFI.
QUALITY_BOUNDS = {
    "inverted_at_most": 0,  # cells with a scaled Jacobian <= 0 (meshgen.quality)
    "inverted_after_snapping_at_most": 0,  # the same after moving the boundary nodes onto the geometry
    "boundary_deviation_max_rel_at_most": 1e-2,  # boundary nodes' largest distance from the geometry / characteristic length
    # mean minimum angle at least TFI's + this share of (elliptic's - TFI's)
    "min_angle_mean_share_from_tfi_to_elliptic_at_least": 0.9,
}


def reference_figures(geometry, cells: int = 30) -> dict:
    """The ``figures`` of TFI's and the elliptic solver's ``cells``^d meshes of ``geometry``: the
    yardsticks of the angle bound."""
    from meshgen.elliptic import elliptic
    from meshgen.tfi import tfi

    dims = [cells] * geometry.dim
    return {"tfi": figures(quality_report(tfi(geometry, dims), geometry)),
            "elliptic": figures(quality_report(elliptic(geometry, dims)[0], geometry))}


def min_angle_threshold(references: dict, bounds: dict = QUALITY_BOUNDS) -> float:
    """The mean minimum angle (degrees) a mesh needs under ``bounds``."""
    tfi, elliptic = references["tfi"]["min_angle_mean"], references["elliptic"]["min_angle_mean"]
    return tfi + bounds["min_angle_mean_share_from_tfi_to_elliptic_at_least"] * (elliptic - tfi)


def meets_bounds(point: dict, references: dict, bounds: dict = QUALITY_BOUNDS) -> bool:
    """Whether a probe ``point`` (``figures`` + inverted_after_snapping) is within ``bounds``;
    ``references``: from ``reference_figures``."""
    deviation = point["boundary_deviation_max_rel"]
    return (point["inverted"] <= bounds["inverted_at_most"]
            and point["inverted_after_snapping"] <= bounds["inverted_after_snapping_at_most"]
            and deviation is not None and deviation <= bounds["boundary_deviation_max_rel_at_most"]
            and point["min_angle_mean"] >= min_angle_threshold(references, bounds))


class QualityProbe:
    """A reporter that measures the 30^3 mesh at every saved checkpoint; its own time is excluded."""

    def __init__(self, folder, geometry, every, verbose=True):
        self.folder, self.geometry, self.every, self.verbose = Path(folder), geometry, every, verbose
        self.coords = parametric_grid([30] * geometry.dim)
        self.points, self.probe_seconds = [], 0.0

    def stage(self, name, done, total):
        pass

    def message(self, text):
        if self.verbose:
            print("   ", text, flush=True)

    def update(self, row, done, total):
        if row["step"] % self.every or row["step"] == 0:
            return
        start = time.perf_counter()
        # saved after ``row["step"]`` steps, just before the step of this row; its clock, less the
        # probes before it, is the training time to that state (checkpoint saves included)
        checkpoint = load_checkpoint(self.folder / "checkpoint.pt")
        X = mesh_from_checkpoint(checkpoint, self.coords, self.geometry)
        point = {"step": checkpoint["step"], "stage": checkpoint["stage"],
                 "seconds": checkpoint["elapsed_seconds"] - self.probe_seconds,
                 **figures(quality_report(X, self.geometry)),
                 "inverted_after_snapping": quality_report(snapped(X, self.geometry, self.coords))["inverted"]["count"]}
        self.points.append(point)
        self.probe_seconds += time.perf_counter() - start
        if self.verbose:
            print(f"    step {point['step']:5d} {point['seconds']:7.1f} s  inverted {point['inverted']} "
                  f"(snapped {point['inverted_after_snapping']})  boundary deviation max {point['boundary_deviation_max']:.4f} "
                  f"mean {point['boundary_deviation_mean']:.5f}  min angle {point['min_angle_mean']:.2f}", flush=True)


def time_to_quality(preset, geometry, overrides, bounds=QUALITY_BOUNDS, references=None, verbose=True):
    """Train ``preset`` (with ``overrides``, ``key=value`` strings) on ``geometry``, measuring the
    30^3 mesh at every checkpoint (``checkpoint.every`` steps) and at the end: the first state
    within ``bounds`` (``first_valid``, None if none), the final state, and the trajectory.
    ``references``: ``reference_figures(geometry)``, computed when not given. Seconds are
    training seconds, the probes' own time excluded."""
    references = references or reference_figures(geometry)
    config = resolve_config(preset, None, overrides)
    with tempfile.TemporaryDirectory() as folder:
        probe = QualityProbe(folder, geometry, config.checkpoint.every, verbose)
        start = time.perf_counter()
        result = train(config, geometry, folder, reporter=probe)
        wall = time.perf_counter() - start - probe.probe_seconds
    training_seconds = result.checkpoint["elapsed_seconds"] - probe.probe_seconds
    final = {"step": result.step, "stage": result.stage, "seconds": training_seconds,
             **figures(result.summary["network"]), "inverted_after_snapping": result.summary["inverted_after_snapping"]}
    trajectory = probe.points + ([final] if not probe.points or probe.points[-1]["step"] < final["step"] else [])
    valid = [p for p in trajectory if meets_bounds(p, references, bounds)]
    return {
        "preset": preset,
        "overrides": list(overrides),
        "adam_steps": config.adam.steps,
        "lbfgs_steps": config.lbfgs.steps,
        "pretrain_steps": config.pretrain.steps,
        "probe_every_steps": config.checkpoint.every,
        "bounds": dict(bounds),
        "min_angle_mean_threshold_degrees": min_angle_threshold(references, bounds),
        "steps": result.step,
        "training_seconds": training_seconds,
        "wall_seconds_with_summary": wall,
        "first_valid": valid[0] if valid else None,
        "final": final,
        "tfi": references["tfi"],
        "elliptic": references["elliptic"],
        "test_loss": result.test_loss,
        "trajectory": trajectory,
    }


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a smoke test: fewer repetitions, short runs")
    parser.add_argument("--json", type=Path, help="write the results to this JSON file")
    parser.add_argument("--threads", type=int, default=None, help="torch CPU threads [default: torch's choice]")
    args = parser.parse_args()
    if args.threads:
        torch.set_num_threads(args.threads)
    geometry = load_geometry("semicylinder")
    repeats = 5 if args.quick else 20
    sizes = {"default": SIZES["default"]} if args.quick else SIZES
    print(f"torch {torch.__version__}, {torch.get_num_threads()} threads (OMP_WAIT_POLICY={os.environ['OMP_WAIT_POLICY']}), "
          f"load average {os.getloadavg()[0]:.2f}")
    print("Seconds per Adam step, semicylinder, 4096 interior (16^3 grid nodes or random points) + 6000 boundary points:")
    rows = step_table(geometry, sizes, repeats)
    step_ratios = ratios(rows)
    for size, values in step_ratios.items():
        for name, value in values.items():
            print(f"  {size:8s} {name}: {value:.2f}{'' if 'overhead' in name else 'x'}")
    quick = ["lbfgs.steps=40", "checkpoint.every=20"] if args.quick else []
    print("Time to quality, semicylinder, 30^3 mesh (probe time excluded):")
    runs = []
    references = reference_figures(geometry)
    for preset, overrides in (("exact", ["checkpoint.every=50"] + (["adam.steps=200", "lbfgs.steps=0"] if args.quick else [])),
                              ("default", ["checkpoint.every=100"] + quick)):
        print(f"  {preset} {' '.join(overrides)}", flush=True)
        run = time_to_quality(preset, geometry, overrides, references=references)
        runs.append(run)
        first, final, reference = run["first_valid"], run["final"], run["tfi"]
        print(f"  {preset}: {run['steps']} steps in {run['training_seconds']:.1f} s; first mesh within the bounds "
              f"(no inverted cell, also snapped; boundary deviation <= {QUALITY_BOUNDS['boundary_deviation_max_rel_at_most']:g} "
              f"of the length; mean min angle >= {run['min_angle_mean_threshold_degrees']:.2f}): "
              + (f"step {first['step']} at {first['seconds']:.1f} s" if first else "never"))
        print(f"    final: inverted {final['inverted']} (snapped {final['inverted_after_snapping']}), "
              f"boundary deviation max {final['boundary_deviation_max']:.4f} mean {final['boundary_deviation_mean']:.5f}, "
              f"mean min angle {final['min_angle_mean']:.2f} (TFI {reference['min_angle_mean']:.2f}, "
              f"inverted {reference['inverted']})")
    results = {
        "machine": {"platform": platform.platform(), "processor": platform.processor(), "cpus": os.cpu_count(),
                    "threads": torch.get_num_threads(), "torch": torch.__version__,
                    "omp_wait_policy": os.environ.get("OMP_WAIT_POLICY"),
                    "load_average_at_end": os.getloadavg()[0]},
        "quick": args.quick,
        "step_seconds": rows,
        "ratios": step_ratios,
        "time_to_quality": runs,
    }
    if args.json:
        args.json.write_text(json.dumps(results, indent=2) + "\n")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()

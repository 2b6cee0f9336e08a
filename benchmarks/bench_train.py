"""Benchmark of ``meshgen train``: seconds per training step of every variant at the same point
counts (finite differences against autograd), the per-step overhead beyond the network's forward
and backward passes, and, for ``exact``, ``default`` and ``paper`` on 1 and 2 CPU threads, seconds per step inside
the loop and the time to a valid corrected 30^3 mesh of the semicylinder better than TFI and to
converged quality (mean minimum angle within 0.3 degrees of the elliptic mesh's).

    python benchmarks/bench_train.py [--quick] [--json FILE] [--threads N]

--quick: fewer repetitions, default sizes only, and shortened training runs (a smoke test, not
the figures to report).
"""

from __future__ import annotations

import argparse
import functools
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

from meshgen.geometry.plugins import load_geometry  # noqa: E402
from meshgen.methods.tfi import parametric_grid  # noqa: E402
from meshgen.neural.checkpoint import load_checkpoint  # noqa: E402
from meshgen.neural.config import resolve_config  # noqa: E402
from meshgen.neural.model import MLP, mesh_from_checkpoint, normalisation, normalised_boundary  # noqa: E402
from meshgen.neural.problem import Problem  # noqa: E402
from meshgen.neural.reweighting import UncertaintyWeights  # noqa: E402
from meshgen.neural.steps import DEVICE_BLOCK, TermRunner, Training, make_optimizer  # noqa: E402
from meshgen.neural.train import adam_steps, corrected, train  # noqa: E402
from meshgen.quality import quality_report  # noqa: E402

VARIANTS = ["default", "fd-pinn", "exact", "pinn", "mgnet", "rwgp-pinn"]
SIZES = {"default": [48, 48, 48], "paper": [85, 85, 85, 85]}


def setup(preset, widths, geometry, interior=4096, boundary=6000):
    """The Adam stage's steps (``meshgen.neural.train.adam_steps``: the training loop's own step,
    terms one after the other) with their optimiser and scheduler, for ``preset`` at the given sizes
    (16^3 grid nodes for fd, as many random points for autograd)."""
    config = resolve_config(
        preset, None, [f"model.widths={widths}", f"points.interior={interior}", f"points.boundary={boundary}"]
    )
    center, scale = normalisation(geometry)
    problem = Problem(
        geometry.dim,
        normalised_boundary(geometry, center, scale),
        center,
        scale,
        config.model.exact_boundary,
        torch.device("cpu"),
    )
    torch.manual_seed(0)
    network = MLP(geometry.dim, config.model.widths)
    weights = UncertaintyWeights(learned=config.method.reweighting)
    training = Training(network, weights, problem, config, torch.Generator().manual_seed(0), TermRunner(False))
    optimizer, scheduler = make_optimizer("adam", network, weights, config)
    return adam_steps(training), optimizer, scheduler


def step_times(presets, widths, geometry, repeats):
    """{preset: (wall, process CPU) seconds of one Adam step}, each the median of ``repeats`` steps
    after three warm-up steps. The presets take their steps in turn (one step of each per round),
    so a change in the load of a shared machine slows all of them alike and leaves their ratios."""
    states = {}
    for preset in presets:
        steps, optimizer, scheduler = setup(preset, widths, geometry)
        step = functools.partial(steps, optimizer, scheduler)
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
            rows.append(
                {
                    "sizes": size_name,
                    "widths": widths,
                    "variant": preset,
                    "derivatives": derivatives,
                    "seconds_per_step": seconds,
                    "cpu_seconds_per_step": cpu,
                }
            )
            print(
                f"  {size_name:8s} {preset:10s} {derivatives:9s} {seconds * 1e3:8.2f} ms/step ({cpu * 1e3:.2f} ms CPU)",
                flush=True,
            )
        if not extras:
            continue
        loop = loop_seconds_per_step(geometry, widths, 60 + 2 * repeats)
        rows.append(
            {
                "sizes": size_name,
                "widths": widths,
                "variant": "default inside the training loop",
                "derivatives": "fd",
                "seconds_per_step": loop,
            }
        )
        print(f"  {size_name:8s} default inside the training loop: {loop * 1e3:.2f} ms/step", flush=True)
        # the floor: one forward and backward pass over the points an fd step evaluates
        grid_nodes = (16 + 2) ** geometry.dim + 6000
        floor = forward_backward_seconds(widths, geometry.dim, grid_nodes, repeats)
        rows.append(
            {
                "sizes": size_name,
                "widths": widths,
                "variant": "forward+backward only",
                "derivatives": "-",
                "seconds_per_step": floor,
            }
        )
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
            out[size]["training-loop overhead over the step"] = (
                by[(size, "default inside the training loop")] / by[(size, "default")] - 1
            )
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
    config = resolve_config(
        "default",
        None,
        [
            f"model.widths={widths}",
            "points.interior=4096",
            "pretrain.steps=0",
            f"adam.steps={steps}",
            "lbfgs.steps=0",
            "checkpoint.every=100000",
        ],
    )
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


# When a network's mesh counts as good, for time-to-quality: its 30^3 mesh of the semicylinder,
# corrected to N + TFI[g - N] as ``meshgen mesh`` writes it (so its boundary is exact), against
# two milestones relative to the two classical meshes of the same size.
QUALITY_BOUNDS = {
    "inverted_at_most": 0,  # cells with a scaled Jacobian <= 0 (meshgen.quality), corrected mesh
    # "valid and better than TFI": mean minimum angle above TFI's
    # "converged": mean minimum angle within this many degrees of the elliptic mesh's
    "converged_within_degrees_of_elliptic": 0.3,
}


def reference_figures(geometry, cells: int = 30, layout: str = "smoothed") -> dict:
    """The ``figures`` of TFI's and the elliptic solver's ``cells``^d meshes of ``geometry`` on the
    boundary ``layout`` a network is trained on ("smoothed": the faces' own Winslow grids, what
    ``meshgen mesh --method elliptic`` makes; "fixed": the Coons faces): the yardsticks of the
    angle bounds."""
    from meshgen.geometry.layout import with_layout
    from meshgen.methods.elliptic import elliptic
    from meshgen.methods.tfi import tfi

    dims = [cells] * geometry.dim
    return {
        "layout": layout,
        "tfi": figures(quality_report(tfi(with_layout(geometry, layout), dims), geometry)),
        "elliptic": figures(quality_report(elliptic(geometry, dims, boundary_layout=layout)[0], geometry)),
    }


def milestones(point: dict, references: dict, bounds: dict = QUALITY_BOUNDS) -> dict:
    """Which milestones a probe ``point`` (``figures`` of the corrected mesh) has reached:
    {"valid_better_than_tfi": bool, "converged": bool}."""
    valid = point["inverted"] <= bounds["inverted_at_most"]
    angle = point["min_angle_mean"]
    return {
        "valid_better_than_tfi": bool(valid and angle > references["tfi"]["min_angle_mean"]),
        "converged": bool(
            valid and abs(angle - references["elliptic"]["min_angle_mean"]) <= bounds["converged_within_degrees_of_elliptic"]
        ),
    }


class QualityProbe:
    """A reporter that measures the corrected 30^3 mesh at every saved checkpoint; its own time is
    excluded. ``done`` turns True once both milestones are reached (the run may stop there)."""

    def __init__(self, folder, geometry, every, references, verbose=True):
        self.folder, self.geometry, self.every, self.verbose = Path(folder), geometry, every, verbose
        self.references = references
        self.coords = parametric_grid([30] * geometry.dim)
        self.points, self.probe_seconds, self.done = [], 0.0, False

    def stage(self, name, done, total):
        pass

    def message(self, text):
        if self.verbose:
            print("   ", text, flush=True)

    def measure(self, checkpoint, seconds) -> dict:
        from meshgen.geometry.layout import trained_layout, with_layout
        from meshgen.methods.correction import boundary_errors, error_figures

        # the boundary the network was trained on (the smoothed layout for today's presets): its
        # error and the correction are measured against it, as ``meshgen mesh`` does
        geometry = with_layout(self.geometry, trained_layout(checkpoint))
        X = mesh_from_checkpoint(checkpoint, self.coords, geometry)
        raw_error = error_figures(boundary_errors(X, geometry, self.coords), geometry)
        point = {
            "step": checkpoint["step"],
            "stage": checkpoint["stage"],
            "seconds": seconds,
            **figures(quality_report(corrected(X, geometry, self.coords), geometry)),
            "raw_boundary_error_max_rel": raw_error["max_rel"],
        }
        point.update(milestones(point, self.references))
        return point

    def update(self, row, done, total):
        if row["step"] % self.every or row["step"] == 0:
            return
        start = time.perf_counter()
        # saved after ``row["step"]`` steps, just before the step of this row; its clock, less the
        # probes before it, is the training time to that state (checkpoint saves included)
        checkpoint = load_checkpoint(self.folder / "checkpoint.pt")
        point = self.measure(checkpoint, checkpoint["elapsed_seconds"] - self.probe_seconds)
        self.points.append(point)
        self.done = point["valid_better_than_tfi"] and point["converged"]
        self.probe_seconds += time.perf_counter() - start
        if self.verbose:
            print(
                f"    step {point['step']:5d} {point['seconds']:7.1f} s  corrected: inverted {point['inverted']} "
                f"min angle {point['min_angle_mean']:.2f}; raw boundary error {point['raw_boundary_error_max_rel']:.2e}",
                flush=True,
            )


def time_to_quality(
    preset,
    geometry,
    overrides,
    bounds=QUALITY_BOUNDS,
    references=None,
    verbose=True,
    threads=None,
    stop_when_converged=False,
    device="cpu",
):
    """Train ``preset`` (with ``overrides``, ``key=value`` strings) on ``geometry`` with ``threads``
    torch threads (default: as set), measuring the corrected 30^3 mesh at every checkpoint
    (``checkpoint.every`` steps) and at the end: the first state that is valid and better than TFI
    (``first_valid``) and the first within the converged bound (``first_converged``; None if
    never), the final state, and the trajectory. ``stop_when_converged``: end training there.
    Seconds are training seconds, the probes' own time excluded; CPU seconds are the process's.
    ``references``: :func:`reference_figures` on the layout the run trains on (default: computed)."""
    config = resolve_config(preset, None, overrides)
    references = references or reference_figures(geometry, layout=config.boundary_layout)
    previous = torch.get_num_threads()
    torch.set_num_threads(threads or previous)
    try:
        with tempfile.TemporaryDirectory() as folder:
            probe = QualityProbe(folder, geometry, config.checkpoint.every, references, verbose)
            start, cpu = time.perf_counter(), time.process_time()
            result = train(
                config,
                geometry,
                folder,
                reporter=probe,
                summary=False,
                device=device,
                stop=(lambda: probe.done) if stop_when_converged else None,
            )
            wall = time.perf_counter() - start - probe.probe_seconds
            cpu = time.process_time() - cpu
            training_seconds = result.checkpoint["elapsed_seconds"] - probe.probe_seconds
            final = probe.measure(result.checkpoint, training_seconds)
    finally:
        torch.set_num_threads(previous)
    trajectory = probe.points + ([final] if not probe.points or probe.points[-1]["step"] < final["step"] else [])
    first = {name: next((p for p in trajectory if p[name]), None) for name in ("valid_better_than_tfi", "converged")}
    return {
        "preset": preset,
        "overrides": list(overrides),
        "device": device,
        "layout": config.boundary_layout,
        "threads": threads or previous,
        "adam_steps": config.adam.steps,
        "lbfgs_steps": config.lbfgs.steps,
        "pretrain_steps": config.pretrain.steps,
        "probe_every_steps": config.checkpoint.every,
        "bounds": dict(bounds),
        "steps": result.step,
        "stopped_when_converged": bool(result.interrupted),
        "training_seconds": training_seconds,
        "wall_seconds": wall,
        "cpu_seconds_with_probes": cpu,
        "first_valid": first["valid_better_than_tfi"],
        "first_converged": first["converged"],
        "final": final,
        "tfi": references["tfi"],
        "elliptic": references["elliptic"],
        "test_loss": result.test_loss,
        "trajectory": trajectory,
    }


def loop_step_seconds(preset, geometry, stage, steps, threads, device="cpu") -> float:
    """Seconds per step of ``stage`` (adam or lbfgs) of ``preset`` inside ``train`` with ``threads``
    torch threads on ``device``, from the history rows' clocks (the first fifth, warm-up, left out;
    on a GPU the rows of a block are read together, so the clock spans whole blocks)."""
    others = {"adam": "lbfgs.steps=0", "lbfgs": "adam.steps=0"}[stage]
    # a section network (an extruded shape under ``exact``) takes its own step counts, 0 in the
    # preset: null makes it take these, so the step is timed whatever network the preset trains
    section = ["adam.section_steps=null", "lbfgs.section_steps=null"]
    config = resolve_config(
        preset, None, ["pretrain.steps=0", f"{stage}.steps={steps}", others, "checkpoint.every=100000", *section]
    )
    keeper = RowKeeper()
    previous = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        with tempfile.TemporaryDirectory() as folder:
            train(config, geometry, folder, reporter=keeper, summary=False, device=device)
    finally:
        torch.set_num_threads(previous)
    rows = [row for row in keeper.rows if row["stage"] == stage]
    skip = max(1, len(rows) // 5)
    if device == "cuda" and stage == "adam":  # from a block's end to the last block's end
        skip = max(skip, DEVICE_BLOCK - 1)
    return (rows[-1]["seconds"] - rows[skip]["seconds"]) / (len(rows) - 1 - skip)


SPEED_PRESETS = ("exact", "default", "paper")
# The runs of the speed table: the presets as they are, paper capped on a CPU (12000 Adam steps
# are the GPU target's; on a CPU the table reports how far a capped run gets)
SPEED_OVERRIDES = {
    "exact": ["checkpoint.every=25"],
    "default": ["checkpoint.every=50"],
    "paper": ["checkpoint.every=100", "adam.steps=500", "lbfgs.steps=0"],
}
CUDA_OVERRIDES = {
    "exact": ["checkpoint.every=25"],
    "default": ["checkpoint.every=50"],
    "paper": ["checkpoint.every=1000", "lbfgs.steps=0"],
}
QUICK_SPEED_OVERRIDES = {
    "exact": ["checkpoint.every=25", "adam.steps=100", "lbfgs.steps=0"],
    "default": ["checkpoint.every=25", "pretrain.steps=5", "adam.steps=50", "lbfgs.steps=5"],
    "paper": ["checkpoint.every=25", "adam.steps=50", "lbfgs.steps=0"],
}
# the boundary layouts of the time-to-quality runs: on the smoothed layout (the presets' default)
# the semicylinder's TFI is already within 0.01 degrees of the elliptic mesh, so the network has
# little to learn there; on the fixed (Coons) layout it must move the interior 2 degrees
LAYOUTS = ("smoothed", "fixed")


def speed_table(geometry, threads=(1, 2), quick=False, verbose=True, cuda=None) -> dict:
    """Training speed: per preset, device (CPU with each of ``threads``, and CUDA where torch sees
    a GPU) and boundary layout (both on 2 threads and CUDA, the smoothed one alone on 1 thread),
    seconds per Adam and L-BFGS step inside the loop and the time to a valid corrected mesh better
    than TFI and to converged quality (runs stopped there, but for ``paper`` on CUDA, whose 12000
    Adam steps are timed whole). ``cuda``: force the CUDA rows on or off (default: when available;
    else skipped, with the reason)."""
    layouts = (LAYOUTS[0],) if quick else LAYOUTS
    references = {layout: reference_figures(geometry, layout=layout) for layout in layouts}
    cuda = torch.cuda.is_available() if cuda is None else cuda
    runs = [("cpu", count) for count in threads] + ([("cuda", 1)] if cuda else [])
    rows = []
    for preset in SPEED_PRESETS:
        for device, count in runs:
            steps = {"adam": 20 if quick else 60, "lbfgs": 4 if quick else 8}
            if device == "cuda":
                steps["adam"] = 3 * DEVICE_BLOCK
            adam = loop_step_seconds(preset, geometry, "adam", steps["adam"], count, device)
            lbfgs = loop_step_seconds(preset, geometry, "lbfgs", steps["lbfgs"], count, device)
            for layout in layouts if (device == "cuda" or count >= 2) else layouts[:1]:
                overrides = (
                    CUDA_OVERRIDES if device == "cuda" and not quick else QUICK_SPEED_OVERRIDES if quick else SPEED_OVERRIDES
                )[preset] + [f"boundary_layout={layout}"]
                whole = device == "cuda" and preset == "paper"
                run = time_to_quality(
                    preset,
                    geometry,
                    overrides,
                    references=references[layout],
                    verbose=False,
                    threads=count,
                    stop_when_converged=not whole,
                    device=device,
                )
                row = {
                    "preset": preset,
                    "device": device,
                    "threads": count,
                    "adam_seconds_per_step": adam,
                    "lbfgs_seconds_per_step": lbfgs,
                    "capped": quick or (preset == "paper" and device == "cpu"),
                    **run,
                }
                rows.append(row)
                if verbose:
                    valid, converged = run["first_valid"], run["first_converged"]
                    where = "cuda" if device == "cuda" else f"cpu x{count}"
                    print(
                        f"  {preset:8s} {where:6s} {layout:8s}: Adam {adam * 1e3:6.1f} ms/step, L-BFGS {lbfgs:6.3f} s/step; "
                        f"valid, better than TFI: {_when(valid)}; converged: {_when(converged)}; "
                        f"{run['steps']} steps, {run['training_seconds']:.1f} s",
                        flush=True,
                    )
    skipped = None if cuda else "no CUDA device is available to torch on this machine"
    if skipped and verbose:
        print(f"  CUDA rows skipped: {skipped}")
    return {"geometry": geometry.name, "references": references, "rows": rows, "cuda_skipped": skipped}


def _when(point) -> str:
    return f"step {point['step']} at {point['seconds']:.1f} s" if point else "not reached"


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
    print(
        f"torch {torch.__version__}, {torch.get_num_threads()} threads (OMP_WAIT_POLICY={os.environ['OMP_WAIT_POLICY']}), "
        f"load average {os.getloadavg()[0]:.2f}"
    )
    print("Seconds per Adam step, semicylinder, 4096 interior (16^3 grid nodes or random points) + 6000 boundary points:")
    rows = step_table(geometry, sizes, repeats)
    step_ratios = ratios(rows)
    for size, values in step_ratios.items():
        for name, value in values.items():
            print(f"  {size:8s} {name}: {value:.2f}{'' if 'overhead' in name else 'x'}")
    print("Speed: seconds per step and time to quality of the corrected 30^3 mesh, CPU threads 1 and 2:")
    speed = speed_table(geometry, quick=args.quick)
    results = {
        "machine": {
            "platform": platform.platform(),
            "processor": platform.processor(),
            "cpus": os.cpu_count(),
            "threads": torch.get_num_threads(),
            "torch": torch.__version__,
            "omp_wait_policy": os.environ.get("OMP_WAIT_POLICY"),
            "load_average_at_end": os.getloadavg()[0],
        },
        "quick": args.quick,
        "step_seconds": rows,
        "ratios": step_ratios,
        "speed": speed,
    }
    if args.json:
        args.json.write_text(json.dumps(results, indent=2) + "\n")
        print(f"wrote {args.json}")


if __name__ == "__main__":
    main()

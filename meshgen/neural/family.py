"""One network for a family of shapes: the geometry's parameters as extra network inputs.

A family is a geometry with some parameters varied over ranges (``--vary twist=0:180``), the
others fixed. Each varied parameter p in [lo, hi] enters the network normalised to
q = 2 (p - lo) / (hi - lo) - 1 in [-1, 1], beside u = 2 xi - 1. The map is the exact-boundary form
(design notes §10) of the member:

    X(xi; p) = TFI[g_p](xi) + S b(xi) N(xi, q(p)),    b = 4^d prod_i xi_i (1 - xi_i),

with g_p the plugin's boundary map at the member's parameters and S one length for the whole
family (the largest extent of the union of the members' bounding boxes, sampled at the range's
corners and middle). TFI reproduces every member's boundary exactly, so the network only learns
the interior correction, and it is trained on the Winslow residual alone. Each step samples
``MEMBERS_PER_STEP`` members uniformly in the ranges and one shifted training grid shared by them;
the TFI of each member comes from the plugin (NumPy), the network and the residual run for all
members in one batch. An L-BFGS stage follows on the unshifted grid, with members that cover the
range: its corners, its middle and stratified samples drawn again every few steps
(``lbfgs_batch``). A member's residual is weighted by (S / s_p)^2, s_p its own size, so that a
small member counts as much as a large one (the residual is of degree one in length).

Meshing one member is one forward pass: the varied inputs are constant over the grid, so they fold
into the first layer's bias, which leaves a plain exact-boundary model description
(``member_model``) for the fast inference of ``meshgen.neural.inference``.

Derivatives with respect to the parameters (``FamilyMesher``): the network term by autograd; the
TFI term by a custom autograd function whose backward takes central differences of the plugin's TFI
in each parameter (one-sided at the range's ends). TFI is linear in the boundary map, so this is
TFI[dg/dp] up to the difference quotient's O(h^2); it works for any plugin, whose code stays NumPy.
"""

from __future__ import annotations

import itertools
import math
import re
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from meshgen.errors import GeometryError, MeshgenError
from meshgen.neural import checkpoint as checkpoints
from meshgen.neural.derivatives import grid_derivatives, grid_points, training_grid
from meshgen.neural.model import INPUT_MAP, bubble
from meshgen.neural.winslow import winslow_residual

MEMBERS_PER_STEP = 4  # members sampled per training step (their residuals are one batch)
TEST_MEMBERS = 8  # fixed held-out members of the test loss
TEST_SEED = 271828
LBFGS_INTERIOR = 8  # stratified members of the L-BFGS batch, beside the range's corners and middle
LBFGS_RESAMPLE = 5  # L-BFGS steps between two draws of its stratified members
SUMMARY_CELLS = 30
FD_STEP = 1e-5  # parameter step of the TFI's difference quotient, as a fraction of the range
STAGES = ("adam", "lbfgs")
_NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_VARY = re.compile(rf"^\s*([A-Za-z_]\w*)\s*=\s*({_NUMBER})\s*:\s*({_NUMBER})\s*$")


# ---------------------------------------------------------------------------------------------
# the family: ranges and members


def parse_vary(items) -> dict[str, tuple[float, float]]:
    """``["twist=0:180"]`` -> {"twist": (0.0, 180.0)}; malformed, empty or reversed ranges raise."""
    ranges = {}
    for item in items:
        match = _VARY.match(item)
        if match is None:
            raise MeshgenError(f"malformed --vary {item!r}: expected name=low:high, e.g. twist=0:180")
        name, low, high = match.group(1), float(match.group(2)), float(match.group(3))
        if not (math.isfinite(low) and math.isfinite(high)):
            raise MeshgenError(f"--vary {item}: the range's ends must be finite numbers")
        if low == high:
            raise MeshgenError(f"--vary {item}: the range is empty (low = high); fix the parameter with --param {name}={low:g}")
        if low > high:
            raise MeshgenError(f"--vary {item}: the range is reversed (low > high); write {name}={high:g}:{low:g}")
        if name in ranges:
            raise MeshgenError(f"--vary {name} is given twice")
        ranges[name] = (low, high)
    return ranges


@dataclass(frozen=True)
class Family:
    """A geometry with parameters ``ranges`` varied; ``base`` holds the fixed values (and, for the
    varied ones, values that are never used). ``spec``: how to load the geometry again."""

    base: object  # Geometry
    spec: str
    ranges: dict  # name -> (low, high), in the order of the network's inputs

    @property
    def names(self) -> list[str]:
        return list(self.ranges)

    @property
    def fixed(self) -> dict[str, float]:
        return {k: v for k, v in self.base.values.items() if k not in self.ranges}

    def middle(self) -> dict[str, float]:
        return {name: (low + high) / 2 for name, (low, high) in self.ranges.items()}

    def normalised(self, values) -> np.ndarray:
        """q = 2 (p - lo) / (hi - lo) - 1 of ``values`` (name -> number), (k,)."""
        return np.array([2 * (values[n] - lo) / (hi - lo) - 1 for n, (lo, hi) in self.ranges.items()])

    def values(self, q) -> dict[str, float]:
        """The parameter values of normalised inputs ``q`` (k,)."""
        return {n: lo + (float(t) + 1) / 2 * (hi - lo) for t, (n, (lo, hi)) in zip(q, self.ranges.items())}

    def member(self, values):
        """The bound Geometry of the member with varied ``values`` (name -> number, unchecked)."""
        return self.base.with_params(**values)

    def check_values(self, given: dict, where: str = "") -> dict[str, float]:
        """The varied values of a member from ``given`` (name -> number): every name must be a
        varied parameter inside its range or a fixed one at its trained value; a varied parameter
        not given takes its range's middle. Raises MeshgenError otherwise."""
        values = self.middle()
        for name, value in given.items():
            value = float(value)
            if name in self.ranges:
                low, high = self.ranges[name]
                if not low <= value <= high:
                    raise MeshgenError(
                        f"{name}={value:g} is outside the trained range {low:g}..{high:g}{where} "
                        f"(the network knows only {', '.join(range_text(self.ranges))})"
                    )
                values[name] = value
            elif name in self.base.values:
                if not np.isclose(value, self.base.values[name], rtol=1e-12, atol=0.0):
                    raise MeshgenError(
                        f"{name}={value:g}: the family{where} was trained with {name}={self.base.values[name]:g} "
                        f"fixed (varied: {', '.join(range_text(self.ranges))})"
                    )
            else:
                raise MeshgenError(
                    f"geometry '{self.base.name}' has no parameter {name!r} (varied: "
                    f"{', '.join(range_text(self.ranges))}; fixed: {', '.join(self.fixed) or 'none'})"
                )
        return values

    def corners(self) -> list[dict[str, float]]:
        """The range's 2^k corners and its middle (where the geometry is checked and sized)."""
        ends = [[(n, lo), (n, hi)] for n, (lo, hi) in self.ranges.items()]
        return [dict(corner) for corner in itertools.product(*ends)] + [self.middle()]


def range_text(ranges) -> list[str]:
    return [f"{name}={low:g}:{high:g}" for name, (low, high) in ranges.items()]


def make_family(geometry, spec: str, ranges: dict) -> Family:
    """The family of ``geometry`` (bound to its fixed values) with ``ranges`` varied, checked: every
    varied name is a parameter of the geometry not also fixed by --param, and the geometry accepts
    every corner of the ranges and their middle (boundary map checked as on load)."""
    from meshgen.geometry import check_boundary

    if not ranges:
        raise MeshgenError("a family needs at least one --vary name=low:high")
    for name in ranges:
        if name not in geometry.defaults:
            import difflib

            close = difflib.get_close_matches(name, list(geometry.defaults), n=1)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            raise MeshgenError(
                f"--vary {name}: geometry '{geometry.name}' has no parameter {name!r} "
                f"(parameters: {', '.join(geometry.defaults) or 'none'}){hint}"
            )
    family = Family(geometry, spec, dict(ranges))
    for values in family.corners():
        try:
            check_boundary(family.member(values))
        except GeometryError as exc:
            at = ", ".join(f"{k}={v:g}" for k, v in values.items())
            raise MeshgenError(
                f"--vary {' '.join(range_text(ranges))}: geometry '{geometry.name}' rejects the member {at}: {exc}"
            ) from None
    return family


def family_scale(family: Family) -> tuple[np.ndarray, float]:
    """Centre and largest extent of the union of the bounding boxes of the range's corners and
    middle: one normalisation for every member."""
    lows, highs = [], []
    for values in family.corners():
        points = _box_samples(family.member(values))
        lows.append(points.min(axis=0)), highs.append(points.max(axis=0))
    low, high = np.min(lows, axis=0), np.max(highs, axis=0)
    return (low + high) / 2, float(np.max(high - low))


def _box_samples(geometry, samples: int = 17) -> np.ndarray:
    from meshgen.cube import face_samples

    return geometry.boundary(face_samples(geometry.dim, samples))


def member_size(geometry) -> float:
    """A member's own size: the largest extent of its boundary (sampled coarsely)."""
    points = _box_samples(geometry, 5)
    return float(np.max(points.max(axis=0) - points.min(axis=0)))


# ---------------------------------------------------------------------------------------------
# the network


class FamilyMLP(torch.nn.Module):
    """tanh MLP of (xi (N, d), q (N, k)) -> (N, d): inputs 2 xi - 1 and q. Its state dict has the
    layout of ``meshgen.neural.model.MLP`` with a first layer of d + k inputs."""

    def __init__(self, dim: int, parameters: int, widths: list[int]):
        super().__init__()
        sizes = [dim + parameters, *widths, dim]
        self.layers = torch.nn.ModuleList(torch.nn.Linear(a, b) for a, b in zip(sizes[:-1], sizes[1:]))

    def forward(self, xi: torch.Tensor, q: torch.Tensor) -> torch.Tensor:
        hidden = torch.cat([2.0 * xi - 1.0, q], dim=-1)
        for layer in self.layers[:-1]:
            hidden = torch.tanh(layer(hidden))
        return self.layers[-1](hidden)


def describe_family_model(network: FamilyMLP, widths, family: Family, center, scale) -> dict:
    """The plain-data description of a family map (``checkpoint["model"]``)."""
    dim = network.layers[-1].out_features
    return {
        "dim": dim,
        "inputs": dim + len(family.ranges),
        "params": family.names,
        "widths": [int(w) for w in widths],
        "activation": "tanh",
        "input": INPUT_MAP + ", then 2*(p-lo)/(hi-lo)-1 per varied parameter",
        "exact_boundary": True,
        "center": [float(c) for c in center],
        "scale": float(scale),
        "state_dict": {k: v.detach().cpu().clone() for k, v in network.state_dict().items()},
    }


def network_from_model(model: dict) -> FamilyMLP:
    dim, inputs = int(model["dim"]), int(model["inputs"])
    network = FamilyMLP(dim, inputs - dim, list(model["widths"]))
    network.load_state_dict(model["state_dict"])
    return network.eval()


def member_model(model: dict, q) -> dict:
    """The plain exact-boundary model description (``meshgen.neural.model``) of the member with
    normalised inputs ``q`` (k,): the constant inputs folded into the first layer's bias,
    b0 + W0[:, d:] q, so that meshing a member is the ordinary one forward pass."""
    dim = int(model["dim"])
    state = dict(model["state_dict"])
    weight, bias = state["layers.0.weight"], state["layers.0.bias"]
    q = torch.as_tensor(np.asarray(q, dtype=np.float64))
    state["layers.0.weight"] = weight[:, :dim].clone()
    state["layers.0.bias"] = (bias.double() + weight[:, dim:].double() @ q).float()
    plain = {k: v for k, v in model.items() if k not in ("inputs", "params")}
    return {**plain, "input": INPUT_MAP, "state_dict": state}


# ---------------------------------------------------------------------------------------------
# training


@dataclass
class FamilyProblem:
    family: Family
    center: np.ndarray
    scale: float
    device: torch.device

    def boundary(self, values):
        """The member's boundary map in the family's normalised units: (N, d) -> (N, d)."""
        member = self.family.member(values)
        return lambda points: (member.boundary(points) - self.center) / self.scale


def sample_members(problem: FamilyProblem, count: int, generator: torch.Generator):
    """``count`` members uniform in the ranges: q (count, k) float64 and the loss weights
    (S / s_p)^2 (count,)."""
    q = 2 * torch.rand((count, len(problem.family.ranges)), generator=generator, dtype=torch.float64) - 1
    return q, member_weights(problem, q)


def member_weights(problem: FamilyProblem, q) -> torch.Tensor:
    sizes = [member_size(problem.family.member(problem.family.values(row))) for row in q.tolist()]
    return torch.tensor([(problem.scale / size) ** 2 for size in sizes])


def members_tfi(problem: FamilyProblem, q: torch.Tensor, axes) -> torch.Tensor:
    """Normalised TFI of each member of ``q`` (B, k) at the grid of ``axes``: (B, n1, .., d) float32."""
    from meshgen.tfi import transfinite

    dim = len(axes)
    broadcast = [a.numpy().reshape([-1 if d == i else 1 for d in range(dim)]) for i, a in enumerate(axes)]
    values = [transfinite(problem.boundary(problem.family.values(row)), broadcast) for row in q.tolist()]
    return torch.from_numpy(np.stack(values)).float().to(problem.device)


def family_residual_loss(network, problem: FamilyProblem, q, weights, axes, spacing, tfi_values=None):
    """Weighted mean over members of the mean squared Winslow residual on the grid ``axes`` (halo
    included), every member on the same grid, one batched forward pass."""
    nodes = grid_points(axes).float().to(problem.device)  # (n1, .., d)
    if tfi_values is None:
        tfi_values = members_tfi(problem, q, axes)
    count, dim = len(q), nodes.shape[-1]
    shape = nodes.shape[:-1]
    flat = nodes.reshape(-1, dim)
    inputs_xi = flat.repeat(count, 1)
    inputs_q = q.float().to(problem.device).repeat_interleave(len(flat), dim=0)
    output = network(inputs_xi, inputs_q).reshape(count, *shape, dim)
    values = tfi_values + bubble(nodes)[..., None] * output
    _, first, second = grid_derivatives(values, spacing)
    residual = winslow_residual(first, second)  # (B, m1, .., d)
    per_member = residual.square().sum(-1).flatten(1).mean(1)
    return (per_member * weights.to(per_member)).mean()


def fixed_members(problem: FamilyProblem, count: int, seed: int, nodes: int):
    """``count`` members and the unshifted training grid with their TFI, from ``seed`` (the test
    loss)."""
    generator = torch.Generator().manual_seed(seed)
    q, weights = sample_members(problem, count, generator)
    return members_on_grid(problem, q, weights, nodes)


def members_on_grid(problem: FamilyProblem, q, weights, nodes: int):
    """Members ``q`` (B, k) with their loss ``weights`` on the unshifted training grid and their TFI
    there: the fixed batch of ``fixed_loss``."""
    axes, spacing = training_grid(problem.family.base.dim, nodes)
    return {"q": q, "weights": weights, "axes": axes, "spacing": spacing, "tfi": members_tfi(problem, q, axes)}


def covering_members(parameters: int, interior: int, generator: torch.Generator) -> torch.Tensor:
    """Normalised members (2^k + 1 + interior, k) float64 that cover the box [-1, 1]^k: its corners,
    its middle and ``interior`` stratified samples (a Latin hypercube: each axis cut into
    ``interior`` equal slices, one sample in each, the slices paired at random between axes)."""
    corners = torch.tensor(list(itertools.product((-1.0, 1.0), repeat=parameters)), dtype=torch.float64)
    middle = torch.zeros((1, parameters), dtype=torch.float64)
    jitter = torch.rand((interior, parameters), generator=generator, dtype=torch.float64)
    slices = torch.stack([torch.randperm(interior, generator=generator) for _ in range(parameters)], dim=1)
    stratified = 2 * (slices + jitter) / interior - 1
    return torch.cat([corners, middle, stratified])


def lbfgs_batch(problem: FamilyProblem, nodes: int, seed: int, draw: int):
    """The L-BFGS stage's batch number ``draw``: the covering members (the range's corners, its
    middle and ``LBFGS_INTERIOR`` stratified samples) on the unshifted training grid. The stage
    draws new stratified members every ``LBFGS_RESAMPLE`` steps, so that it fits the whole range
    rather than a few members (8 uniform members, the earlier batch, left the slender corner of the
    semicylinder's range 0.85 deg below its elliptic mesh). The grid stays fixed: shifting it with
    every draw changes the objective too much for L-BFGS's curvature history (measured: the flower's
    worst member fell from +0.25 to -0.70 deg). Each draw has its own seed, so a resumed run draws
    the same batches."""
    generator = torch.Generator().manual_seed(seed + 1000003 * (draw + 1))
    q = covering_members(len(problem.family.ranges), LBFGS_INTERIOR, generator)
    return members_on_grid(problem, q, member_weights(problem, q), nodes)


def fixed_loss(network, problem, fixed) -> torch.Tensor:
    return family_residual_loss(network, problem, fixed["q"], fixed["weights"], fixed["axes"], fixed["spacing"], fixed["tfi"])


def train_family(
    config,
    family: Family,
    run_dir,
    *,
    device: str = "cpu",
    resume: dict | None = None,
    reporter=None,
    stop=None,
    summary: bool = True,
):
    """Train one network for ``family`` (exact-boundary form, PDE loss alone): Adam on
    ``MEMBERS_PER_STEP`` members sampled per step, then L-BFGS on members covering the range
    (``lbfgs_batch``). Writes ``checkpoint.pt``, ``config.yaml``, ``history.csv`` and
    ``summary.json`` in ``run_dir``, as ``meshgen.neural.train.train`` does, and returns its
    TrainResult; ``resume`` continues a saved family checkpoint."""
    from meshgen import __version__
    from meshgen.neural.config import to_dict, to_yaml
    from meshgen.neural.train import CONFIG_HEADER, TrainResult, open_history

    run_dir = Path(run_dir)
    device = torch.device(device)
    stop = stop or (lambda: False)
    dim = family.base.dim
    center, scale = family_scale(family)
    if resume is not None:
        center, scale = np.asarray(resume["model"]["center"]), float(resume["model"]["scale"])
    problem = FamilyProblem(family, center, scale, device)
    nodes = max(1, round(config.points.interior ** (1.0 / dim)))  # per axis, as for one shape

    torch.manual_seed(config.seed)
    network = FamilyMLP(dim, len(family.ranges), config.model.widths)
    torch.nn.init.zeros_(network.layers[-1].weight)  # N = 0: every member starts from its TFI
    torch.nn.init.zeros_(network.layers[-1].bias)
    network.to(device)
    generator = torch.Generator().manual_seed(config.seed)
    stage, stage_step, step, elapsed = STAGES[0], 0, 0, 0.0
    if resume is not None:
        network.load_state_dict(resume["model"]["state_dict"])
        generator.set_state(resume["rng"]["sampler"])
        stage, stage_step, step, elapsed = resume["stage"], resume["stage_step"], resume["step"], resume["elapsed_seconds"]
    test_members = fixed_members(problem, TEST_MEMBERS, TEST_SEED, nodes)
    checkpoint_path = run_dir / "checkpoint.pt"
    (run_dir / "config.yaml").write_text(CONFIG_HEADER + to_yaml(config))
    history_file, history = open_history(run_dir / "history.csv", step if resume is not None else None)
    optimizer = scheduler = None
    started = time.perf_counter()

    def save(stage_name):
        history_file.flush()
        with torch.no_grad():
            pde = float(fixed_loss(network, problem, test_members))
        state = {
            "format": checkpoints.FORMAT,
            "format_version": checkpoints.FORMAT_VERSION,
            "meshgen_version": __version__,
            "model": describe_family_model(network, config.model.widths, family, center, scale),
            "family": {
                "ranges": {k: [float(lo), float(hi)] for k, (lo, hi) in family.ranges.items()},
                "members_per_step": MEMBERS_PER_STEP,
            },
            "geometry": {"name": family.base.name, "spec": family.spec, "dim": dim, "params": dict(family.base.values)},
            "config": to_dict(config),
            "stage": stage_name,
            "stage_step": stage_step,
            "step": step,
            "elapsed_seconds": elapsed + (time.perf_counter() - started),
            "optimizer": optimizer.state_dict() if optimizer is not None else {},
            "scheduler": scheduler.state_dict() if scheduler is not None else {},
            "rng": {"sampler": generator.get_state(), "torch": torch.get_rng_state()},
            "history": {"rows": step},
            "test_loss": {
                "pde": pde,
                "boundary": 0.0,
                "total": pde,
                "definition": f"weighted Winslow residual of {TEST_MEMBERS} fixed members on the unshifted training grid",
            },
            "guard": {"lr_reductions": 0},
            "device": str(device),
        }
        checkpoints.save_checkpoint(checkpoint_path, state)
        return state

    interrupted = False
    try:
        for stage in STAGES[STAGES.index(stage) :] if stage != "done" else ():  # noqa: B020
            total = getattr(config, stage).steps
            if stage_step >= total:
                stage_step = 0
                continue
            optimizer, scheduler = _optimizer(stage, network, config)
            if resume is not None and resume["stage"] == stage and resume["optimizer"]:
                optimizer.load_state_dict(resume["optimizer"])
                if scheduler is not None:
                    scheduler.load_state_dict(resume["scheduler"])
            fixed = None
            if reporter is not None:
                reporter.stage(stage, stage_step, total)
            while stage_step < total:
                if stop():
                    interrupted = True
                    break
                lr = optimizer.param_groups[0]["lr"]
                if stage == "adam":
                    loss = _adam_step(network, problem, config, optimizer, scheduler, generator, nodes)
                else:
                    if fixed is None or stage_step % LBFGS_RESAMPLE == 0:
                        fixed = lbfgs_batch(problem, nodes, config.seed, stage_step // LBFGS_RESAMPLE)
                    loss = _lbfgs_step(network, problem, optimizer, fixed)
                if not math.isfinite(loss):
                    save(stage)
                    raise MeshgenError(
                        f"family training diverged at step {step} ({stage}): non-finite loss; "
                        f"the last state is in {checkpoint_path}"
                    )
                row = {
                    "stage": stage,
                    "step": step,
                    "L1": loss,
                    "L2": 0.0,
                    "total": loss,
                    "lr": lr,
                    "seconds": elapsed + time.perf_counter() - started,
                }
                history.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in row.items()})
                stage_step += 1
                step += 1
                if reporter is not None:
                    reporter.update({**row, "a1": 1.0, "a2": 1.0}, stage_step, total)  # as an exact run shows them
                if step % config.checkpoint.every == 0:
                    save(stage)
            if interrupted:
                break
            stage_step = 0
        final_stage = stage if interrupted else "done"
        state = save(final_stage)
    finally:
        history_file.close()
    seconds = elapsed + time.perf_counter() - started
    quality = write_family_summary(state, run_dir) if summary and not interrupted else None
    return TrainResult(checkpoint_path, final_stage, step, interrupted, seconds, state["test_loss"], state, quality)


def _optimizer(stage: str, network, config):
    if stage == "adam":
        optimizer = torch.optim.Adam(network.parameters(), lr=config.adam.lr)
        return optimizer, torch.optim.lr_scheduler.StepLR(optimizer, config.adam.decay_every, gamma=config.adam.decay)
    lbfgs = config.lbfgs
    return torch.optim.LBFGS(
        network.parameters(),
        lr=lbfgs.lr,
        max_iter=lbfgs.max_iter,
        history_size=lbfgs.history_size,
        line_search_fn="strong_wolfe",
        tolerance_grad=0.0,
        tolerance_change=0.0,
    ), None


def _adam_step(network, problem, config, optimizer, scheduler, generator, nodes) -> float:
    min_scale = config.points.grid_min_scale if config.points.random_grid else 1.0
    axes, spacing = training_grid(problem.family.base.dim, nodes, generator, min_scale)
    q, weights = sample_members(problem, MEMBERS_PER_STEP, generator)
    optimizer.zero_grad(set_to_none=True)
    loss = family_residual_loss(network, problem, q, weights, axes, spacing)
    if torch.isfinite(loss):
        loss.backward()
        optimizer.step()
        scheduler.step()
    return loss.item()


def _lbfgs_step(network, problem, optimizer, fixed) -> float:
    def closure():
        optimizer.zero_grad(set_to_none=True)
        loss = fixed_loss(network, problem, fixed)
        if torch.isfinite(loss):
            loss.backward()
        return loss

    optimizer.step(closure)
    with torch.no_grad():
        return fixed_loss(network, problem, fixed).item()


# ---------------------------------------------------------------------------------------------
# meshing members


def family_from_checkpoint(checkpoint: dict) -> Family:
    """The Family a checkpoint was trained on (its geometry loaded by name, or by a plugin path the
    user gave: ``meshgen.trust``)."""
    from meshgen.geometry import load_recorded_geometry

    entry = checkpoint["geometry"]
    ranges = {k: (float(lo), float(hi)) for k, (lo, hi) in checkpoint["family"]["ranges"].items()}
    base = load_recorded_geometry(entry["spec"], dict(entry["params"]), check=False, where="the checkpoint")
    return Family(base, entry["spec"], ranges)


def is_family(checkpoint: dict) -> bool:
    return isinstance(checkpoint.get("family"), dict)


def mesh_member(checkpoint: dict, values: dict, coords) -> np.ndarray:
    """Node array of the member with ``values`` (name -> number, checked against the ranges) on the
    tensor grid of ``coords``: one forward pass of the family network, exact boundary."""
    from meshgen.neural.inference import mesh_from_model

    family = family_from_checkpoint(checkpoint)
    values = family.check_values(values)
    return mesh_from_model(member_model(checkpoint["model"], family.normalised(values)), coords, family.member(values))


def load_family_member(path, values: dict, geometry_name: str | None = None):
    """The member of the family checkpoint at ``path`` with the parameters ``values`` given on the
    command line, as a ``meshgen.neural.models.TrainedModel`` whose model is the member's plain
    description (so ``meshgen mesh`` meshes it like any exact-boundary model), and its geometry.
    Returns None when ``path`` is no family checkpoint."""
    from meshgen.geometry import load_recorded_geometry
    from meshgen.neural.models import TrainedModel, display_path

    path = Path(path)
    checkpoint = checkpoints.load_checkpoint(path)
    if not is_family(checkpoint):
        return None
    family = family_from_checkpoint(checkpoint)
    if geometry_name is not None and geometry_name != family.base.name:
        raise MeshgenError(
            f"checkpoint {path} was trained on '{family.base.name}', not on '{geometry_name}': "
            f"leave out --geometry (the checkpoint sets it)"
        )
    values = family.check_values(values, f" of {display_path(path)}")
    model = member_model(checkpoint["model"], family.normalised(values))

    class FamilyMember(TrainedModel):
        """A member of a family checkpoint: described and recorded with its ranges and values."""

        def describe(self) -> str:
            at = ", ".join(f"{k}={v:g}" for k, v in values.items())
            return f"{super().describe()}; member {at} of {' '.join(range_text(family.ranges))}"

        def metadata(self) -> dict:
            return {**super().metadata(), "family": {"ranges": checkpoint["family"]["ranges"], "member": values}}

    member = FamilyMember(path, {**checkpoint, "model": model}, "checkpoint")
    entry = checkpoint["geometry"]
    return member, load_recorded_geometry(entry["spec"], {**entry["params"], **values}, where=f"checkpoint {path}")


# ---------------------------------------------------------------------------------------------
# the mesh as a differentiable function of the parameters


class _MemberTFI(torch.autograd.Function):
    """TFI of the member with parameters ``p`` (k,) float64 on the tensor grid ``coords``; backward:
    the TFI of central differences of the plugin in each parameter (one-sided at a range's end)."""

    @staticmethod
    def forward(ctx, p, family, coords):
        from meshgen.tfi import transfinite_on_grid

        values = dict(zip(family.names, p.tolist()))
        ctx.family, ctx.coords, ctx.values = family, coords, values
        return torch.from_numpy(transfinite_on_grid(family.member(values).boundary, coords))

    @staticmethod
    def backward(ctx, grad):
        from meshgen.tfi import transfinite_on_grid

        family, values = ctx.family, ctx.values
        grads = []
        for name, (low, high) in family.ranges.items():
            step = FD_STEP * (high - low)
            ahead, behind = min(values[name] + step, high), max(values[name] - step, low)
            plus = transfinite_on_grid(family.member({**values, name: ahead}).boundary, ctx.coords)
            minus = transfinite_on_grid(family.member({**values, name: behind}).boundary, ctx.coords)
            derivative = torch.from_numpy((plus - minus) / (ahead - behind))
            grads.append((grad * derivative).sum())
        return torch.stack(grads), None, None


class FamilyMesher:
    """A trained family as a torch function of its parameters::

        mesher = FamilyMesher.load("runs/flower/checkpoint.pt")
        twist = torch.tensor(73.0, requires_grad=True)
        X = mesher.mesh({"twist": twist}, (20, 20, 20))   # (21, 21, 21, 3) float64, differentiable
        X[..., 0].mean().backward()                        # twist.grad = d mean(x) / d twist

    Parameters not given take their range's middle; a value outside the trained range raises
    MeshgenError. The network runs in float64 here (gradients through a float32 network are
    noisier); memory grows with the nodes: keep the grid moderate when differentiating.
    """

    def __init__(self, checkpoint: dict):
        self.checkpoint = checkpoint
        self.family = family_from_checkpoint(checkpoint)
        self.network = network_from_model(checkpoint["model"]).double()
        self.scale = float(checkpoint["model"]["scale"])

    @classmethod
    def load(cls, path) -> FamilyMesher:
        checkpoint = checkpoints.load_checkpoint(path)
        if not is_family(checkpoint):
            raise MeshgenError(f"checkpoint {path} holds one shape, not a family (train one with --vary)")
        return cls(checkpoint)

    @property
    def ranges(self) -> dict:
        return dict(self.family.ranges)

    def mesh(self, params: dict, dims=None, coords=None) -> torch.Tensor:
        """Node array of the member ``params`` (name -> float or 0-d tensor) on ``dims`` cells (or
        the tensor grid of 1D ``coords`` from 0 to 1): (n1+1, .., d) float64 tensor."""
        from meshgen.tfi import parametric_grid

        if coords is None:
            coords = parametric_grid(dims)
        coords = [np.asarray(c, dtype=float) for c in coords]
        family = self.family
        given = {k: float(torch.as_tensor(v).detach()) for k, v in params.items()}
        middle = family.check_values(given)
        p = torch.stack([torch.as_tensor(params.get(n, middle[n]), dtype=torch.float64) for n in family.names])
        low = torch.tensor([lo for lo, _ in family.ranges.values()], dtype=torch.float64)
        high = torch.tensor([hi for _, hi in family.ranges.values()], dtype=torch.float64)
        q = 2 * (p - low) / (high - low) - 1
        shape = tuple(len(c) for c in coords)
        nodes = grid_points([torch.from_numpy(c) for c in coords])
        flat = nodes.reshape(-1, len(coords))
        output = self.network(flat, q.expand(len(flat), -1)).reshape(*shape, -1)
        return _MemberTFI.apply(p, family, coords) + self.scale * bubble(nodes)[..., None] * output


# ---------------------------------------------------------------------------------------------
# the end-of-training summary


def write_family_summary(checkpoint: dict, run_dir) -> dict:
    """Mesh ``SUMMARY_CELLS``^d cells of the range's corners and middle with the family network and
    with TFI, measure them (``meshgen.quality``, boundary deviation included), write
    ``summary.json`` in ``run_dir`` and return it; ``worst`` indexes the member of the lowest mean
    minimum angle."""
    from meshgen.quality import quality_report, write_json
    from meshgen.tfi import parametric_grid, tfi

    family = family_from_checkpoint(checkpoint)
    coords = parametric_grid([SUMMARY_CELLS] * family.base.dim)
    members = []
    for values in family.corners():
        geometry = family.member(values)
        start = time.perf_counter()
        X = mesh_member(checkpoint, values, coords)
        seconds = time.perf_counter() - start
        members.append(
            {
                "params": values,
                "network": quality_report(X, geometry),
                "tfi": quality_report(tfi(geometry, None, coords), geometry),
                "meshing_seconds": seconds,
            }
        )
    angles = [m["network"]["metrics"]["min_angle"]["mean"] for m in members]
    summary = {
        "dims": [SUMMARY_CELLS] * family.base.dim,
        "ranges": checkpoint["family"]["ranges"],
        "members": members,
        "worst": int(np.argmin(angles)),
        "test_loss": checkpoint["test_loss"],
        "step": checkpoint["step"],
        "training_seconds": checkpoint["elapsed_seconds"],
    }
    write_json(Path(run_dir) / "summary.json", summary)  # atomic; non-finite figures as null
    return summary


def summary_table(summary: dict) -> list[str]:
    """Lines for the terminal: per summarised member, inverted cells and mean minimum angle of the
    network's mesh and of TFI's."""
    size = " x ".join(str(n) for n in summary["dims"])
    lines = [f"{size} meshes of the range's corners and middle (inverted cells, mean min angle):"]
    for index, member in enumerate(summary["members"]):
        at = ", ".join(f"{k}={v:g}" for k, v in member["params"].items())
        net, ref = member["network"], member["tfi"]
        lines.append(
            f"  {at}: network {net['inverted']['count']} inverted, {net['metrics']['min_angle']['mean']:.2f} deg; "
            f"TFI {ref['inverted']['count']} inverted, {ref['metrics']['min_angle']['mean']:.2f} deg"
            + ("  (worst)" if index == summary["worst"] else "")
        )
    return lines

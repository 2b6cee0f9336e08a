"""One network for a family of shapes: the geometry's parameters as extra network inputs.

A family is a geometry with some parameters varied over ranges (``--vary twist=0:180``), the
others fixed. Each varied parameter p in [lo, hi] enters the network normalised to
q = 2 (p - lo) / (hi - lo) - 1 in [-1, 1], beside u = 2 xi - 1. The map is the exact-boundary form
(design notes §10) of the member:

    X(xi; p) = TFI[g_p](xi) + S b(xi) N(xi, q(p)),    b = 4^d prod_i xi_i (1 - xi_i),

with g_p the plugin's boundary map at the member's parameters and S one length for the whole
family (the largest extent of the union of the members' bounding boxes, sampled at the range's
corners and middle). TFI reproduces every member's boundary exactly, so the network only learns
the interior correction, and it is trained on the Winslow residual alone
(``meshgen.neural.family_train``). This module holds the family itself (ranges, members, checks),
its network and model description, and meshing a member.

Meshing one member is one forward pass: the varied inputs are constant over the grid, so they fold
into the first layer's bias, which leaves a plain exact-boundary model description
(``member_model``) for the fast inference of ``meshgen.neural.network_map``.

Derivatives with respect to the parameters (``FamilyMesher``): the network term by autograd; the
TFI term by a custom autograd function whose backward takes central differences of the plugin's TFI
in each parameter (one-sided at the range's ends). TFI is linear in the boundary map, so this is
TFI[dg/dp] up to the difference quotient's O(h^2); it works for any plugin, whose code stays NumPy.
"""

from __future__ import annotations

import itertools
import math
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from meshgen.errors import GeometryError, MeshgenError
from meshgen.geometry.cube import face_samples
from meshgen.geometry.layout_family import FamilyLayout, interpolated_member, solve_family_layout
from meshgen.geometry.plugins import check_boundary, load_recorded_geometry
from meshgen.methods.polish import polishes_by_default
from meshgen.methods.tfi import parametric_grid, transfinite_on_grid
from meshgen.neural import checkpoint as checkpoints
from meshgen.neural.derivatives import grid_points
from meshgen.neural.model import INPUT_MAP, bubble
from meshgen.neural.models import TrainedModel, display_path
from meshgen.neural.network_map import mesh_from_model

__all__ = [
    "Family",
    "FamilyMLP",
    "FamilyMesher",
    "VALIDATION_POINTS",
    "describe_family_model",
    "family_from_checkpoint",
    "family_scale",
    "is_family",
    "load_family_member",
    "make_family",
    "member_model",
    "member_size",
    "mesh_member",
    "network_from_model",
    "parse_vary",
    "range_text",
    "validation_note",
]

VALIDATION_POINTS = 3  # members per varied parameter on the validation grid: both ends (the box's corners) and the middle
FD_STEP = 1e-5  # parameter step of the TFI's difference quotient, as a fraction of the range
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
    layout: FamilyLayout | None = None  # the smoothed layout over the box; None: each member's own map (fixed layout)

    @property
    def layout_name(self) -> str:
        return "fixed" if self.layout is None else "smoothed"

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
        """The bound Geometry of the member with varied ``values`` (name -> number, unchecked), with
        the family's boundary layout (the smoothed one interpolated over the box, or its own map)."""
        member = self.base.with_params(**values)
        return member if self.layout is None else interpolated_member(member, self.layout)

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

    def grid(self, points: int = VALIDATION_POINTS) -> list[dict[str, float]]:
        """The members of the tensor grid of ``points`` equally spaced values per varied parameter,
        ends included (so the 2^k corners of the box are members): ``points``^k dicts."""
        axes = [[(n, float(v)) for v in np.linspace(lo, hi, points)] for n, (lo, hi) in self.ranges.items()]
        return [dict(member) for member in itertools.product(*axes)]

    def corners(self) -> list[dict[str, float]]:
        """The range's 2^k corners and its middle (where the geometry is checked and sized)."""
        ends = [[(n, lo), (n, hi)] for n, (lo, hi) in self.ranges.items()]
        return [dict(corner) for corner in itertools.product(*ends)] + [self.middle()]


def range_text(ranges) -> list[str]:
    return [f"{name}={low:g}:{high:g}" for name, (low, high) in ranges.items()]


def make_family(geometry, spec: str, ranges: dict, layout: str = "fixed") -> Family:
    """The family of ``geometry`` (bound to its fixed values) with ``ranges`` varied, checked: every
    varied name is a parameter of the geometry not also fixed by --param, and the geometry accepts
    every corner of the ranges and their middle (boundary map checked as on load). ``layout``
    "smoothed": the smoothed layout solved on a grid over the box and interpolated
    (``meshgen.geometry.layout_family``); "fixed": each member's own map."""
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
    if layout == "smoothed":
        try:
            family = Family(geometry, spec, dict(ranges), solve_family_layout(geometry, family.ranges))
        except GeometryError as exc:
            raise MeshgenError(
                f"--vary {' '.join(range_text(ranges))}: {exc}; narrow the range, or train on the fixed layout "
                f"(--set boundary_layout=fixed), which a flow solver may see as skewed cells"
            ) from None
    elif layout != "fixed":
        raise MeshgenError(f"unknown boundary layout '{layout}' (layouts: smoothed, fixed)")
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
# meshing members


def family_from_checkpoint(checkpoint: dict) -> Family:
    """The Family a checkpoint was trained on (its geometry loaded by name, or by a plugin path the
    user gave: ``meshgen.run.trust``)."""
    entry = checkpoint["geometry"]
    ranges = {k: (float(lo), float(hi)) for k, (lo, hi) in checkpoint["family"]["ranges"].items()}
    base = load_recorded_geometry(entry["spec"], dict(entry["params"]), check=False, where="the checkpoint")
    layout = checkpoint["family"].get("layout")
    return Family(base, entry["spec"], ranges, None if layout is None else FamilyLayout.from_record(layout))


def is_family(checkpoint: dict) -> bool:
    return isinstance(checkpoint.get("family"), dict)


def mesh_member(checkpoint: dict, values: dict, coords) -> np.ndarray:
    """Node array of the member with ``values`` (name -> number, checked against the ranges) on the
    tensor grid of ``coords``: one forward pass of the family network, exact boundary."""
    family = family_from_checkpoint(checkpoint)
    values = family.check_values(values)
    return mesh_from_model(member_model(checkpoint["model"], family.normalised(values)), coords, family.member(values))


def load_family_member(path, values: dict, geometry_name: str | None = None, warn=None, polished: bool | None = True):
    """The member of the family checkpoint at ``path`` with the parameters ``values`` given on the
    command line, as a ``meshgen.neural.models.TrainedModel`` whose model is the member's plain
    description (so ``meshgen mesh`` meshes it like any exact-boundary model), and its geometry.
    ``warn`` (a callable taking one line; else Python's ``warnings``) hears :func:`validation_note`'s
    line when there is one (``polished``: whether the mesh will be polished; None: as
    ``meshgen.methods.polish.polishes_by_default`` decides for the checkpoint).
    Returns None when ``path`` is no family checkpoint."""
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
    if polished is None:
        polished = polishes_by_default(checkpoint)
    note = validation_note(checkpoint, values, polished)
    if note is not None:
        warn(note) if warn is not None else warnings.warn(note, stacklevel=2)
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
    geometry = load_recorded_geometry(entry["spec"], {**entry["params"], **values}, where=f"checkpoint {path}")
    return member, geometry if family.layout is None else interpolated_member(geometry, family.layout)


def validation_note(checkpoint: dict, values: dict, polished: bool = True) -> str | None:
    """One line on what the training's validation says of the member ``values`` (name -> number,
    inside the ranges), or None when it has nothing to warn of. The validation
    (``checkpoint["family"]["validation"]``, written at the end of training) meshed every member of
    a grid of ``points`` values per parameter and counted the inverted cells of the network's own
    mesh and of the polished mesh (what ``meshgen mesh`` writes by default). The count that is
    judged is that of the mesh the user gets: the polished one (``polished``) or the network's own.
    A grid member is judged by its own count; a member between grid values by the grid members
    around it (the corners of its grid cell): it is warned of when one of them failed. A checkpoint
    without the record (training stopped early) is warned of for every member."""
    family = family_from_checkpoint(checkpoint)
    record = checkpoint["family"].get("validation")
    at = ", ".join(f"{k}={v:g}" for k, v in values.items())
    if not isinstance(record, dict) or not record.get("members"):
        return f"member {at} is not validated: this family checkpoint has no validation record (its training did not finish, or an older meshgen made it)"
    points = int(record["points"])
    positions = [(values[n] - lo) / (hi - lo) * (points - 1) for n, (lo, hi) in family.ranges.items()]
    around = [sorted({math.floor(t + 1e-9), math.ceil(t - 1e-9)}) for t in positions]
    neighbours = {tuple(index) for index in itertools.product(*around)}
    failed = []
    for member in record["members"]:
        index = tuple(round((member["params"][n] - lo) / (hi - lo) * (points - 1)) for n, (lo, hi) in family.ranges.items())
        if index in neighbours and member["polished_inverted" if polished else "network_inverted"]:
            failed.append(member)
    if not failed:
        return None
    size = " x ".join(str(n) for n in record["dims"])
    counts = "; ".join(
        f"{', '.join(f'{k}={v:g}' for k, v in m['params'].items())}: {m['network_inverted']} inverted in the network's mesh, "
        f"{m['polished_inverted']} polished"
        for m in failed
    )
    if len(neighbours) == 1:
        return f"member {at} failed the training's {size} validation: {counts}"
    return f"member {at} lies between validated members, and some of them failed the training's {size} validation: {counts}"


# ---------------------------------------------------------------------------------------------
# the mesh as a differentiable function of the parameters


class _MemberTFI(torch.autograd.Function):
    """TFI of the member with parameters ``p`` (k,) float64 on the tensor grid ``coords``; backward:
    the TFI of central differences of the plugin in each parameter (one-sided at a range's end)."""

    @staticmethod
    def forward(ctx, p, family, coords):
        values = dict(zip(family.names, p.tolist()))
        ctx.family, ctx.coords, ctx.values = family, coords, values
        return torch.from_numpy(transfinite_on_grid(family.member(values).boundary, coords))

    @staticmethod
    def backward(ctx, grad):
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

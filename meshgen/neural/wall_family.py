"""One wall-layer network for a family of sections: the varied parameters as extra inputs of the
network of ``meshgen.neural.wall_map`` (``meshgen train -g airfoil --vary thickness=0.08:0.18``).

A family model is a wall-layer model with ``model["family"]``: ``ranges`` (name -> [lo, hi], in the
order of the extra inputs), ``base`` (every parameter of the training's middle member), ``free``
(the parameters a member may set at will: the wall spacing's, which the frame applies exactly) and
``train_dims`` (the --dims of the teachers). Each varied parameter p enters normalised,
2 (p - lo) / (hi - lo) - 1, after the inputs of ``wall_map.network_inputs``. The frame (wall,
normals, distances) is the member's own, exact; q is the index fraction in the member's own xi
nodes at ``train_dims`` (with the base's spacing parameters), as the training measured it.

Meshing a member is one forward pass: its inputs are constant over the grid, so they fold into the
first layer's bias (``member_layers``), which leaves the plain wall-layer forward pass.

Derivatives with respect to the parameters: ``meshgen.neural.wall_derivatives``.
"""

from __future__ import annotations

import numpy as np

from meshgen.errors import MeshgenError
from meshgen.geometry.plugins import plugin_module

__all__ = [
    "check_member_values",
    "is_wall_family",
    "member_layers",
    "member_values",
    "member_tables",
    "normalised",
    "range_text",
]

_RANGE_TOL = 1e-9  # relative slack at the ranges' ends


def is_wall_family(model) -> bool:
    """Whether a wall-layer model description is a family's."""
    return isinstance(model, dict) and isinstance(model.get("family"), dict)


def range_text(ranges: dict) -> str:
    """``"name=lo:hi, ..."``: the ranges as ``--vary`` writes them."""
    return ", ".join(f"{name}={lo:g}:{hi:g}" for name, (lo, hi) in ranges.items())


def check_member_values(family: dict, values: dict, where: str = "") -> None:
    """MeshgenError (one line) unless ``values`` (every parameter of a member) lie in the family:
    varied ones inside their ranges, free ones anything, the others at the training's values."""
    ranges, base, free = family["ranges"], family["base"], set(family["free"])
    for name, (lo, hi) in ranges.items():
        value, slack = float(values[name]), _RANGE_TOL * (hi - lo)
        if not lo - slack <= value <= hi + slack:
            raise MeshgenError(
                f"{name}={value:g} is outside the trained range {lo:g}..{hi:g}{where} (the family: {range_text(ranges)})"
            )
    for name, value in values.items():
        if name in ranges or name in free or name not in base:
            continue
        if not np.isclose(float(value), float(base[name]), rtol=1e-12, atol=0.0):
            raise MeshgenError(
                f"{name}={float(value):g}: the family{where} was trained with {name}={float(base[name]):g} fixed "
                f"(varied: {range_text(ranges)}; free: {', '.join(sorted(free))})"
            )


def member_values(family: dict, defaults: dict, given: dict) -> dict:
    """Every parameter of the member that ``given`` (the --param values) asks for: the geometry's
    ``defaults``, then the family's fixed parameters (the section's and the far field's: neither
    varied nor free), then ``given``. A varied parameter not given is the geometry's default."""
    ranges, free = family["ranges"], set(family["free"])
    fixed = {k: float(v) for k, v in family["base"].items() if k not in ranges and k not in free}
    return {**{k: float(v) for k, v in defaults.items()}, **fixed, **{k: float(v) for k, v in given.items()}}


def normalised(family: dict, values: dict) -> np.ndarray:
    """The extra inputs (k,) of a member: 2 (p - lo) / (hi - lo) - 1 per varied parameter."""
    return np.array([2.0 * (float(values[n]) - lo) / (hi - lo) - 1.0 for n, (lo, hi) in family["ranges"].items()])


def member_layers(layers: list, family: dict, values: dict, dtype=np.float32) -> list:
    """``layers`` [(W, b), ...] with the member's constant inputs folded into the first bias:
    the layers of the plain (2- or 3-input) forward pass, in ``dtype``."""
    k = len(family["ranges"])
    (weight, bias), rest = layers[0], layers[1:]
    weight64, q = weight.astype(np.float64), normalised(family, values)
    folded = [(weight64[:, :-k], bias.astype(np.float64) + weight64[:, -k:] @ q)]
    return [(w.astype(dtype), b.astype(dtype)) for w, b in folded + list(rest)]


def member_tables(family: dict, block_set) -> list:
    """Per block the xi nodes of the member ``block_set`` at the family's ``train_dims`` (with the
    base's spacing parameters): the tables its q is measured in (its own when it is so made)."""
    values = block_set.values
    dims = [sum(len(c[0]) - 1 for c in block_set.coords), len(block_set.coords[0][1]) - 1]
    same = dims == list(family["train_dims"]) and all(values.get(k) == family["base"].get(k) for k in family["free"])
    if same:
        return [np.asarray(c[0], dtype=float) for c in block_set.coords]
    module = plugin_module(block_set.name)[0]
    at = {**family["base"], **{n: float(values[n]) for n in family["ranges"]}}
    coords = module.block_coords(tuple(family["train_dims"]), **at)
    return [np.asarray(coords[block][0], dtype=float) for block in module.blocks]

"""Wall-layer networks: the trained map of a 2D row of blocks round a wall (the airfoil's C- and
O-grids, ``geometries/airfoil.py``) with the wall-normal distances applied analytically.

A plugin declares it with the hooks of ``HOOKS``: ``wall_layout(values) -> {"distance": D,
"closed": bool, "blend_distance": d0}``, ``wall_teacher(block_set)`` (the mesh to learn, per block:
the airfoil's marched layers) and ``wall_finish(block_set, Xs, check)`` (what the plugin makes of a
learned mesh, and of the teacher: its elliptic mesh, ``elliptic_reference``; the airfoil blends it
beyond a chord into straight lines to its far-field nodes). Its
blocks lie in a row along xi (block b's xi1 face is block b+1's xi0; ``closed``: the last's xi1 is
the first's xi0), eta runs from the wall (or a cut) at eta0 to the far field at eta1, and a node at
parametric eta lies at the wall-normal distance d = eta D (``meshgen.geometry.wall_spacing``).
The learned mesh is

    X(xi, d) = w(xi) + d ((1 - phi(d)) n(xi) + phi(d) N(q, tau)),   phi(d) = d^2 / (d^2 + d0^2),

w the wall (the boundary map at eta0), n its unit normal (the mean of the two blocks' at a node
where blocks meet), N the network's 2-vector (a direction times a stretch, O(1) everywhere), q the
position along the row (block index plus the index fraction of xi in the training's node
distribution, over the block count: the trailing and leading edges get as much of q as of the
nodes) and tau = log(1 + d/h) / log(1 + D/h) (h the training's first cell). w, n, d and the sum
are float64 (first cells of 1e-6 next to coordinates of 100); the network runs in float32, its
output multiplied by d. At the first node phi is (h/d0)^2 (2e-5 for the airfoil's C-grid): the
first grid line is the normal and its height h, whatever the network. Patch faces at xi ends (the
C-grid's outlet) are put on their boundary map, the move blended linearly in xi.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from meshgen.errors import GeometryError
from meshgen.geometry.blocks import BlockSet, check_handedness
from meshgen.geometry.plugins import plugin_module
from meshgen.neural.checkpoint_data import CheckpointError
from meshgen.neural.wall_family import check_member_values, member_layers, member_tables

__all__ = [
    "BLEND_DISTANCE",
    "HOOKS",
    "KIND",
    "WallFrame",
    "assemble",
    "check_wall_model",
    "elliptic_reference",
    "forward",
    "forward_grid",
    "forward_with",
    "has_wall_hooks",
    "is_wall_model",
    "network_inputs",
    "network_layers",
    "onto_end_patches",
    "wall_frame",
    "neural_wall_blocks",
    "wall_hooks",
    "wall_nodes",
]

KIND = "wall_map"  # checkpoint["model"]["kind"] of a wall-layer model
BLEND_DISTANCE = 1e-3  # d0 where the plugin's wall_layout names none: below it the grid lines are the wall normals
_STEP = 1e-6  # parametric step of the wall's finite-difference tangent


HOOKS = ("wall_layout", "wall_teacher", "wall_finish")  # what a plugin defines to have wall-layer models


def wall_hooks(block_set: BlockSet):
    """The plugin module of ``block_set`` when it defines every hook of ``HOOKS``, else None."""
    try:
        module = plugin_module(block_set.name)[0]
    except GeometryError:  # not a plugin of that name (a geometry given by a path that is gone)
        return None
    return module if has_wall_hooks(module) else None


def has_wall_hooks(module) -> bool:
    """Whether a plugin ``module`` defines every hook of ``HOOKS`` (it has wall-layer models)."""
    return all(callable(getattr(module, hook, None)) for hook in HOOKS)


@dataclass
class WallFrame:
    """Per block: wall points ``walls`` (n_b, 2), unit normals ``normals`` (n_b, 2), the networks'
    along-row input ``q`` (n_b,), in [0, 1]; the distances ``d`` (m + 1,) of every block, the far
    field's distance ``distance``, ``closed`` (a ring of blocks)."""

    walls: list
    normals: list
    q: list
    d: np.ndarray
    distance: float
    closed: bool


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def wall_frame(block_set: BlockSet, layout: dict, tables=None) -> WallFrame:
    """The frame of ``block_set`` (2D, a row of blocks, ``layout`` its plugin's ``wall_layout``).
    ``tables``: per block the training's xi nodes (q is their index fraction there, linear between);
    None: the block set's own (the training's frame)."""
    distance, closed, count = float(layout["distance"]), bool(layout["closed"]), len(block_set.names)
    walls, normals, q = [], [], []
    for b, (geometry, coords) in enumerate(zip(block_set.geometries, block_set.coords)):
        xi = np.asarray(coords[0], dtype=float)
        lo, hi = np.clip(xi - _STEP, 0.0, 1.0), np.clip(xi + _STEP, 0.0, 1.0)
        # the wall alone (a plugin that caches its wall nodes finds them again in its finish), then the tangents
        walls.append(geometry.boundary(np.stack([xi, np.zeros_like(xi)], axis=1)))
        sides = np.concatenate([lo, hi])
        images = geometry.boundary(np.stack([sides, np.zeros_like(sides)], axis=1)).reshape(2, len(xi), 2)
        tangent = images[1] - images[0]
        normals.append(_unit(np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)))  # (xi, eta) right-handed: eta to the left
        table = xi if tables is None else np.asarray(tables[b], dtype=float)
        q.append((b + np.interp(xi, table, np.linspace(0.0, 1.0, len(table)))) / count)
    pairs = [(b, b + 1) for b in range(count - 1)] + ([(count - 1, 0)] if closed else [])
    for a, b in pairs:  # one normal where two blocks meet: the mean of theirs
        mean = _unit(normals[a][-1] + normals[b][0])
        normals[a][-1] = normals[b][0] = mean
    d = np.asarray(block_set.coords[0][1], dtype=float) * distance
    return WallFrame(walls, normals, q, d, distance, closed)


def network_inputs(q: np.ndarray, d: np.ndarray, scales: dict) -> np.ndarray:
    """The network's inputs (len(q) * len(d), 2 or 3) on the tensor grid of ``q`` (n,) and ``d``
    (m + 1,), i-major: (2q - 1, 2 tau - 1), or (cos 2 pi q, sin 2 pi q, 2 tau - 1) for a ring."""
    h, distance = float(scales["first_height"]), float(scales["distance"])
    tau = np.log1p(d / h) / math.log1p(distance / h)
    qq, tt = np.meshgrid(q, 2.0 * tau - 1.0, indexing="ij")
    if scales["closed"]:
        angle = 2.0 * np.pi * qq
        return np.stack([np.cos(angle), np.sin(angle), tt], axis=-1).reshape(-1, 3)
    return np.stack([2.0 * qq - 1.0, tt], axis=-1).reshape(-1, 2)


def blend(d: np.ndarray, d0: float) -> np.ndarray:
    """phi(d) = d^2 / (d^2 + d0^2) (d (k,) -> (k,)): the network's share of the grid lines' direction."""
    d0 = float(d0)
    return d * d / (d * d + d0 * d0)


def assemble(wall: np.ndarray, normal: np.ndarray, d: np.ndarray, N: np.ndarray, d0: float) -> np.ndarray:
    """Nodes (n, m + 1, 2) float64 from the wall (n, 2), normals (n, 2), distances (m + 1,) and the
    network's vectors N (n, m + 1, 2): w + d ((1 - phi) n + phi N), phi = ``blend(d, d0)``."""
    phi = blend(d, d0)
    out = N.astype(np.float64)
    out *= (d * phi)[None, :, None]
    out += (d * (1.0 - phi))[None, :, None] * normal[:, None, :]
    out += wall[:, None, :]
    return out


def is_wall_model(model) -> bool:
    """Whether a ``checkpoint["model"]`` description is a wall-layer model."""
    return isinstance(model, dict) and model.get("kind") == KIND


def network_layers(model: dict) -> list:
    """The layers [(W (out, in), b (out,)), ...] of a wall-layer model, float32."""
    state, layers = model["state_dict"], []
    for index in range(len(model["widths"]) + 1):
        weight = np.asarray(state[f"layers.{index}.weight"], dtype=np.float32)
        bias = np.asarray(state[f"layers.{index}.bias"], dtype=np.float32)
        layers.append((weight, bias))
    return layers


def check_wall_model(model: dict) -> None:
    """CheckpointError (one line) unless ``model`` is a well-formed wall-layer model: its layers fit
    its widths and inputs, its numbers are finite, its tables one increasing xi list per block."""
    try:
        inputs = (3 if model["scales"]["closed"] else 2) + len(model.get("family", {}).get("ranges", {}))
        sizes = [inputs, *[int(w) for w in model["widths"]], 2]
        layers = network_layers(model)
        for index, ((weight, bias), fan_in, fan_out) in enumerate(zip(layers, sizes[:-1], sizes[1:])):
            if weight.shape != (fan_out, fan_in) or bias.shape != (fan_out,):
                raise ValueError(f"layer {index} has shape {weight.shape}, expected {(fan_out, fan_in)}")
        if len(model["state_dict"]) != 2 * len(layers):
            raise ValueError("extra weights")
        tables = [np.asarray(t, dtype=float) for t in model["tables"]]
        if len(tables) != len(model["blocks"]) or any(len(t) < 2 or np.any(np.diff(t) <= 0) for t in tables):
            raise ValueError("the xi tables are not one increasing list per block")
        scales = [float(model["scales"][k]) for k in ("first_height", "distance", "blend_distance")]
        if "family" in model:
            family = model["family"]
            ends = np.asarray([family["ranges"][n] for n in family["ranges"]], dtype=float).reshape(-1, 2)
            if not (len(ends) and np.isfinite(ends).all() and np.all(ends[:, 0] < ends[:, 1])):
                raise ValueError("the family's ranges are not finite increasing pairs")
            base = {str(k): float(v) for k, v in family["base"].items()}  # numbers, or the file is damaged
            if (
                not all(n in base for n in family["ranges"])
                or len(family["train_dims"]) != 2
                or not isinstance(family["free"], list)
            ):
                raise ValueError("the family's base member, free parameters or --dims are missing")
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise CheckpointError(f"the checkpoint's wall-layer model is damaged ({exc})") from None
    finite = all(np.isfinite(w).all() and np.isfinite(b).all() for w, b in layers) and np.isfinite(scales).all()
    if not finite or min(scales) <= 0:
        raise CheckpointError("the checkpoint's wall-layer model holds non-finite or non-positive numbers: the file is damaged")


def forward(layers: list, inputs: np.ndarray) -> np.ndarray:
    """The tanh MLP ``layers`` [(W, b), ...] on ``inputs`` (k, n_in), float32: (k, 2)."""
    return forward_with(layers, inputs, np.float32)


def forward_with(layers: list, inputs: np.ndarray, dtype) -> np.ndarray:
    """:func:`forward` in ``dtype`` (the layers already in it): (k, 2)."""
    hidden = inputs.astype(dtype)
    for weight, bias in layers[:-1]:
        hidden = np.tanh(hidden @ weight.T + bias)
    weight, bias = layers[-1]
    return hidden @ weight.T + bias


def forward_grid(layers: list, q: np.ndarray, d: np.ndarray, scales: dict) -> np.ndarray:
    """:func:`forward` on the tensor grid of ``q`` (n,) and ``d`` (m + 1,), float32: (n, m + 1, 2),
    the values of ``forward(layers, network_inputs(q, d, scales))``. The first layer is separable on
    a tensor grid (its input is a q part plus a tau part), so its product is one broadcast sum of an
    (n, h) and an (m + 1, h) array; the others run in place."""
    grid = network_inputs(q[:1], d, scales)[:, -1:]  # 2 tau - 1 (m + 1, 1)
    along = network_inputs(q, d[:1], scales)[:, :-1]  # the q inputs (n, 1 or 2)
    weight, bias = layers[0]
    weight = weight.astype(np.float32)
    hidden = (along.astype(np.float32) @ weight[:, :-1].T)[:, None, :] + (grid.astype(np.float32) @ weight[:, -1:].T + bias)[None]
    hidden = np.tanh(hidden, out=hidden).reshape(len(q) * len(d), -1)
    for weight, bias in layers[1:-1]:
        hidden = hidden @ weight.T
        hidden += bias
        np.tanh(hidden, out=hidden)
    weight, bias = layers[-1]
    out = hidden @ weight.T
    out += bias
    return out.reshape(len(q), len(d), 2)


def wall_nodes(model: dict, block_set: BlockSet, layout: dict) -> list[np.ndarray]:
    """Every block's nodes (n_b, m + 1, 2) float64 from the wall-layer ``model`` (not yet conforming).
    GeometryError when the block set is not the row the model was trained on."""
    if list(model["blocks"]) != list(block_set.names) or bool(model["scales"]["closed"]) != bool(layout["closed"]):
        raise GeometryError(
            f"geometry '{block_set.name}': the model's row of blocks ({', '.join(model['blocks'])}, "
            f"{'closed' if model['scales']['closed'] else 'open'}) is not this one"
        )
    layers, tables, scales = network_layers(model), model["tables"], model["scales"]
    if "family" in model:  # a family's: the member's inputs folded into the first bias, its own tables
        check_member_values(model["family"], block_set.values)
        layers = member_layers(layers, model["family"], block_set.values)
        tables = member_tables(model["family"], block_set)
    frame = wall_frame(block_set, layout, tables)
    Xs = []
    for wall, normal, q in zip(frame.walls, frame.normals, frame.q):
        N = forward_grid(layers, q, frame.d, scales)
        Xs.append(assemble(wall, normal, frame.d, N, scales["blend_distance"]))
    return Xs


def elliptic_reference(block_set: BlockSet) -> list[np.ndarray]:
    """The plugin's elliptic mesh made of its teacher (``wall_finish`` of ``wall_teacher``, not
    checked): what a wall-layer model is measured against, per block (n_b, m + 1, 2)."""
    hooks = wall_hooks(block_set)
    Xs = hooks.wall_teacher(block_set)
    onto_end_patches(block_set, Xs)
    return hooks.wall_finish(block_set, Xs, check=False)


def neural_wall_blocks(block_set: BlockSet, model: dict, check: bool = True):
    """The block set's mesh from a wall-layer ``model``: the network's near-wall nodes
    (:func:`wall_nodes`), the patch faces at xi ends on their boundary map, through the plugin's
    ``wall_finish`` (the outer region, as its elliptic mesh's; interface nodes identical; GeometryError for inverted cells with ``check``).
    Returns (node arrays, info)."""
    hooks = wall_hooks(block_set)
    if hooks is None:
        raise GeometryError(f"geometry '{block_set.name}' declares no wall layout: a wall-layer model cannot mesh it")
    Xs = wall_nodes(model, block_set, dict(hooks.wall_layout(block_set.values)))
    moved = onto_end_patches(block_set, Xs)
    Xs = hooks.wall_finish(block_set, Xs, check=check)
    if check:
        check_handedness(block_set, Xs)
    return Xs, {
        "corrected": True,
        "kind": KIND,
        "end_patch_move": moved / block_set.length,
        "definition": "largest move, relative to the characteristic length, of the network's nodes on patch faces at xi ends "
        "onto their boundary map; the far field and interfaces are the plugin's wall_finish's",
    }


def onto_end_patches(block_set: BlockSet, Xs: list[np.ndarray]) -> float:
    """Put the nodes of patch faces at xi ends (the C-grid's outlet) on their boundary map, in place,
    the move blended linearly in xi over the block. Returns the largest move."""
    moved = 0.0
    for (block, face), _ in block_set.patches.items():
        if face not in ("xi0", "xi1"):
            continue
        X, coords = Xs[block], block_set.coords[block]
        xi, eta = np.asarray(coords[0], dtype=float), np.asarray(coords[1], dtype=float)
        end = 0 if face == "xi0" else -1
        target = block_set.geometries[block].boundary(np.stack([np.full_like(eta, xi[end]), eta], axis=1))
        error = target - X[end]
        moved = max(moved, float(np.linalg.norm(error, axis=1).max()))
        weight = (xi[-1] - xi) / (xi[-1] - xi[0]) if face == "xi0" else (xi - xi[0]) / (xi[-1] - xi[0])
        X += weight[:, None, None] * error[None, :, :]
    return moved

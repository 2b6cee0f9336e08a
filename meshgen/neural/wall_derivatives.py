"""A family of sections' nodes as a differentiable function of its parameters
(``meshgen.neural.wall_family``), for shape optimisation with an adjoint solver.

d nodes / d p: the network's part by forward-mode differentiation (exact, float64 weights); the
frame's (the member's wall, normals and chordwise nodes) and the plugin's finish (``wall_finish``,
NumPy) by central differences in the parameter, the network linearised about the member. So the
derivative is exact in the network and O(h^2) in the geometry, as ``meshgen.neural.family`` does for
TFI. The mesh is piecewise smooth in the parameters: where a change moves a node from one surface
to the other (the chordwise split of the section's cells is a whole number), the nodes jump, and
the derivatives are those of the piece.
"""

from __future__ import annotations

import numpy as np

from meshgen.errors import MeshgenError
from meshgen.geometry.blocks import load_block_set
from meshgen.geometry.plugins import load_geometry
from meshgen.neural import wall_map
from meshgen.neural.checkpoint_data import read_plain_checkpoint
from meshgen.neural.wall_family import check_member_values, is_wall_family, member_tables, member_values, normalised

__all__ = ["DERIVATIVE_STEP", "forward_tangent", "member_derivatives"]

DERIVATIVE_STEP = 1e-4  # central-difference step of the frame, as a fraction of the parameter's range


def forward_tangent(layers: list, inputs: np.ndarray, tangents: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The tanh MLP and its forward-mode derivative: (outputs (k, 2), d outputs (k, 2)) at
    ``inputs`` (k, n_in) along ``tangents`` (k, n_in), in the layers' dtype."""
    hidden, tangent = inputs, tangents
    for weight, bias in layers[:-1]:
        hidden = np.tanh(hidden @ weight.T + bias)
        tangent = (1.0 - hidden * hidden) * (tangent @ weight.T)
    weight, bias = layers[-1]
    return hidden @ weight.T + bias, tangent @ weight.T


def member_derivatives(checkpoint, params: dict, dims, step: float = DERIVATIVE_STEP):
    """The member ``params`` (its --param values, ``member_values``: e.g. {"thickness": 0.13,
    "yplus": 0.5}) of the family ``checkpoint`` (its path, or the checkpoint read) at
    ``dims``: its nodes (per block (n_b, m + 1, 2) float64, the mesh ``meshgen mesh`` makes) and
    their derivatives with respect to every varied parameter ({name: per block (n_b, m + 1, 2)},
    length per unit of the parameter). The network's derivative is exact (forward mode, float64
    weights); the frame and the finish are differenced centrally with ``step`` times the range
    (one-sided at a range's end), the network linearised about the member. MeshgenError (one
    line) for a checkpoint of no family or a member outside it."""
    if not isinstance(checkpoint, dict):
        path, checkpoint = checkpoint, read_plain_checkpoint(checkpoint)
        if not is_wall_family(checkpoint.get("model")):
            raise MeshgenError(f"checkpoint {path} holds no family of sections round a wall (train one with --vary)")
    model, name = checkpoint["model"], checkpoint["geometry"]["name"]
    family, scales = model["family"], model["scales"]
    values = member_values(family, load_geometry(name, check=False).defaults, params)
    check_member_values(family, values)
    block_set, frame = _frame(model, name, values, dims)
    nodes, _ = wall_map.neural_wall_blocks(block_set, model)
    layers = [(w.astype(np.float64), b.astype(np.float64)) for w, b in wall_map.network_layers(model)]
    at = [_inputs(frame, b, scales, family, values) for b in range(len(frame.walls))]
    derivatives = {}
    for param, (lo, hi) in family["ranges"].items():
        h = step * (hi - lo)
        ends = (min(float(values[param]) + h, hi), max(float(values[param]) - h, lo))
        sides = [(p, *_frame(model, name, {**values, param: p}, dims)) for p in ends]
        tangents = [
            (_inputs(sides[0][2], b, scales, family, {**values, param: ends[0]})
             - _inputs(sides[1][2], b, scales, family, {**values, param: ends[1]})) / (ends[0] - ends[1])
            for b in range(len(frame.walls))
        ]  # fmt: skip
        linear = [forward_tangent(layers, x, t) for x, t in zip(at, tangents)]  # (N, dN / dp) per block
        finished = []
        for p, side_set, side in sides:
            Xs = [
                wall_map.assemble(wall, normal, side.d, (N + (p - float(values[param])) * dN).reshape(len(q), len(side.d), 2),
                                  scales["blend_distance"])
                for wall, normal, q, (N, dN) in zip(side.walls, side.normals, side.q, linear)
            ]  # fmt: skip
            wall_map.onto_end_patches(side_set, Xs)
            finished.append(wall_map.wall_hooks(side_set).wall_finish(side_set, Xs, check=False))
        derivatives[param] = [(a - b) / (ends[0] - ends[1]) for a, b in zip(*finished)]
    return nodes, derivatives


def _frame(model: dict, name: str, values: dict, dims):
    block_set = load_block_set(name, values, dims)
    layout = dict(wall_map.wall_hooks(block_set).wall_layout(block_set.values))
    return block_set, wall_map.wall_frame(block_set, layout, member_tables(model["family"], block_set))


def _inputs(frame, block: int, scales: dict, family: dict, values: dict) -> np.ndarray:
    base = wall_map.network_inputs(frame.q[block], frame.d, scales)
    extra = np.broadcast_to(normalised(family, values), (len(base), len(family["ranges"])))
    return np.concatenate([base, extra], axis=1)

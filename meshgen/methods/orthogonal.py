"""Orthogonality at chosen walls for elliptic meshes: the first cell layer meets the
wall at right angles.

Method (an equivalent of the Sorenson / Thomas-Middlecoff source terms, which drive the same
angle to 90 degrees by iterating the forcing functions P, Q, R near the wall): after the Winslow
solve, every node of the first layer off the wall (``X[1]`` for a wall at index 0) that is not on
another face is moved onto the wall's normal through its wall node, keeping its distance from the
wall node (the spacing that ``--cluster`` set); the normal is that of the wall's surface grid (cross
product of its central differences, 2D: the chord turned by 90 degrees), pointing into the domain.
The Winslow equations are then solved again for the nodes beyond that layer, with it held fixed.
So the grid lines leave the wall exactly along its normal, and the interior is still the Winslow
map of its (new) boundary.
"""

from __future__ import annotations

import numpy as np

from meshgen.errors import ParameterError
from meshgen.geometry.cube import Face, face_named, face_names

__all__ = ["inner_block", "parse_walls", "straighten_first_layer"]


def parse_walls(names, dim: int) -> list[Face]:
    """Face names (``xi0`` .. ``zeta1``; repeats dropped) -> faces; ParameterError for unknown ones."""
    walls = []
    for name in names:
        try:
            face = face_named(name, dim)
        except KeyError:
            raise ParameterError(
                "orthogonal", f"{{name}}: unknown face '{name}' (faces of a {dim}D mesh: {', '.join(face_names(dim))})"
            ) from None
        if face not in walls:
            walls.append(face)
    return walls


def straighten_first_layer(X: np.ndarray, face: Face) -> None:
    """Move the first layer's nodes off ``face`` onto the wall normal (in place in ``X``): the
    layer's nodes inside the face (not on its edges), at their present distance from the wall."""
    dim = X.shape[-1]
    wall = X[face.node_index]  # (n_p[, n_q], dim), a view
    first_index = tuple((1 if face.side == 0 else -2) if d == face.axis else slice(None) for d in range(dim))
    layer = X[first_index]  # a view: assignments below move the nodes of X
    inner = (slice(1, -1),) * (dim - 1)
    # central-difference chords of the wall grid along each of its axes, at its inner nodes
    chords = [
        wall[tuple(slice(2, None) if e == t else slice(1, -1) for e in range(dim - 1))]
        - wall[tuple(slice(None, -2) if e == t else slice(1, -1) for e in range(dim - 1))]
        for t in range(dim - 1)
    ]
    if dim == 3:
        normal = np.cross(chords[0], chords[1])
    else:
        normal = np.stack([-chords[0][..., 1], chords[0][..., 0]], axis=-1)
    normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
    offset = layer[inner] - wall[inner]
    normal *= np.sign(np.einsum("...c,...c->...", normal, offset))[..., None]  # into the domain
    layer[inner] = wall[inner] + np.linalg.norm(offset, axis=-1, keepdims=True) * normal


def inner_block(walls, dim: int) -> tuple:
    """Index of the nodes that the second solve treats as its block: one layer fewer at each wall."""
    block = [slice(None)] * dim
    for face in walls:
        current = block[face.axis]
        start, stop = current.start, current.stop
        if face.side == 0:
            start = 1
        else:
            stop = -1
        block[face.axis] = slice(start, stop)
    return tuple(block)

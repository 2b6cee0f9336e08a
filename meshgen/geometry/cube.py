"""The reference cube C = [0, 1]^dim (2D: the unit square): its faces, edges and corners.

One table for every part that walks the boundary of the parametric domain (TFI, geometry checks,
deviation, quality, training points, patches). Faces are numbered axis-major, side-minor:

    3D: xi0, xi1, eta0, eta1, zeta0, zeta1        2D: xi0, xi1, eta0, eta1

``xi0`` is the face xi = 0, ``zeta1`` the face zeta = 1. These are also the default boundary-patch
names of a geometry (design notes §3).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

__all__ = ["AXIS_NAMES", "Edge", "Face", "corners", "edges", "face_named", "face_names", "face_samples", "faces"]

AXIS_NAMES = ("xi", "eta", "zeta")


@dataclass(frozen=True)
class Face:
    """The face ``t[axis] = side`` of the unit cube (square) of dimension ``dim``."""

    dim: int
    axis: int
    side: int  # 0 or 1

    @property
    def name(self) -> str:
        return f"{AXIS_NAMES[self.axis]}{self.side}"

    @property
    def tangent_axes(self) -> tuple[int, ...]:
        """The parametric axes that run along the face, in increasing order."""
        return tuple(d for d in range(self.dim) if d != self.axis)

    @property
    def node_index(self) -> tuple:
        """Index of the face's nodes in a node array X (n1+1, .., dim): e.g. ``(slice(None), -1,
        slice(None))`` for eta1; ``X[face.node_index]`` has shape (face nodes..., dim)."""
        return tuple((-1 if self.side else 0) if d == self.axis else slice(None) for d in range(self.dim))

    def points(self, coords) -> np.ndarray:
        """Parametric points of the face's tensor grid: ``coords`` are the dim 1D node coordinates
        of the full grid; returns (face nodes, dim) in the C order of ``X[face.node_index]``."""
        others = [np.asarray(coords[d], dtype=float) for d in self.tangent_axes]
        columns = [g.reshape(-1) for g in np.meshgrid(*others, indexing="ij")]
        columns.insert(self.axis, np.full(columns[0].shape, float(self.side)))
        return np.stack(columns, axis=1)


@dataclass(frozen=True)
class Edge:
    """An edge of the 3D cube: ``t[axes[0]] = sides[0]``, ``t[axes[1]] = sides[1]``, free along
    ``free_axis``."""

    axes: tuple[int, int]
    sides: tuple[int, int]

    @property
    def free_axis(self) -> int:
        return ({0, 1, 2} - set(self.axes)).pop()

    @property
    def name(self) -> str:
        return "-".join(f"{AXIS_NAMES[a]}{s}" for a, s in zip(self.axes, self.sides))

    @property
    def node_index(self) -> tuple:
        """Index of the edge's nodes in a 3D node array X: ``X[edge.node_index]`` is (n+1, 3)."""
        fixed = dict(zip(self.axes, self.sides))
        return tuple((-1 if fixed[d] else 0) if d in fixed else slice(None) for d in range(3))


def faces(dim: int) -> tuple[Face, ...]:
    """The 2*dim faces, axis-major and side-minor (xi0, xi1, eta0, ...)."""
    return tuple(Face(dim, axis, side) for axis in range(dim) for side in (0, 1))


def face_names(dim: int) -> tuple[str, ...]:
    return tuple(face.name for face in faces(dim))


def face_named(name: str, dim: int) -> Face:
    """The face called ``name`` (``xi0`` .. ``zeta1``); KeyError if there is none in ``dim``."""
    for face in faces(dim):
        if face.name == name:
            return face
    raise KeyError(name)


def edges() -> tuple[Edge, ...]:
    """The 12 edges of the 3D cube: for each pair of axes (a < b), the four side combinations."""
    return tuple(
        Edge((a, b), sides) for a, b in itertools.combinations(range(3), 2) for sides in itertools.product((0, 1), repeat=2)
    )


def corners(dim: int) -> np.ndarray:
    """The 2**dim corners, shape (2**dim, dim), float, in ``itertools.product((0, 1), ...)`` order."""
    return np.array(list(itertools.product((0.0, 1.0), repeat=dim)))


def face_samples(dim: int, n: int) -> np.ndarray:
    """An n-per-side uniform grid on every face, concatenated in face order: (2*dim*n**(dim-1), dim)."""
    t = np.linspace(0.0, 1.0, n)
    return np.concatenate([face.points([t] * dim) for face in faces(dim)])

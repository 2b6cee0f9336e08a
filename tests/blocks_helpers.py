"""Independent measures of multi-block meshes for the tests: cell areas/volumes from the node
arrays (not meshgen's quality kernels) and the cell-size ratio across interfaces."""

from __future__ import annotations

import numpy as np


def cell_measures(X: np.ndarray) -> np.ndarray:
    """|area| (2D, shoelace of the quad) or |volume| (3D, the parallelepiped of the mean edge
    vectors) of each cell of a node array."""
    if X.shape[-1] == 2:
        x, y = X[..., 0], X[..., 1]
        return 0.5 * np.abs(
            (x[1:, 1:] - x[:-1, :-1]) * (y[:-1, 1:] - y[1:, :-1]) - (x[:-1, 1:] - x[1:, :-1]) * (y[1:, 1:] - y[:-1, :-1])
        )
    e = [np.diff(X, axis=a) for a in range(3)]
    a = (e[0][:, :-1, :-1] + e[0][:, 1:, :-1] + e[0][:, :-1, 1:] + e[0][:, 1:, 1:]) / 4
    b = (e[1][:-1, :, :-1] + e[1][1:, :, :-1] + e[1][:-1, :, 1:] + e[1][1:, :, 1:]) / 4
    c = (e[2][:-1, :-1] + e[2][1:, :-1] + e[2][:-1, 1:] + e[2][1:, 1:]) / 4
    return np.abs(np.einsum("...i,...i", a, np.cross(b, c)))


def _layer(values: np.ndarray, axis: int, side: int) -> np.ndarray:
    return np.take(values, -1 if side else 0, axis=axis)


def _in_frame_of_a(values_b: np.ndarray, transform) -> np.ndarray:
    """Block b's cell array in block a's index frame (the CGNS Transform's axes and signs)."""
    turned = np.transpose(values_b, [abs(t) - 1 for t in transform])
    for axis, t in enumerate(transform):
        if t < 0:
            turned = np.flip(turned, axis=axis)
    return turned


def size_ratios(block_set, Xs) -> tuple[float, float]:
    """(largest ratio of the sizes of the two cells on either side of an interface, largest ratio
    between neighbouring cells inside a block)."""
    across = []
    for interface in block_set.interfaces:
        a = _layer(cell_measures(Xs[interface.a]), interface.face_a.axis, interface.face_a.side)
        turned = _in_frame_of_a(cell_measures(Xs[interface.b]), interface.transform)
        b = _layer(turned, interface.face_a.axis, 1 - interface.face_a.side)
        across.append(np.max(np.maximum(a / b, b / a)))
    inside = []
    for X in Xs:
        V = cell_measures(X)
        for axis in range(V.ndim):
            first, second = np.take(V, range(V.shape[axis] - 1), axis=axis), np.take(V, range(1, V.shape[axis]), axis=axis)
            inside.append(np.max(np.maximum(first / second, second / first)))
    return float(max(across)), float(max(inside))

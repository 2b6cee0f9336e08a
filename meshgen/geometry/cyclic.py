"""Cyclic (periodic) patch pairs of a block set: two boundary patches whose nodes match under a
translation, so a solver treats them as one interface (OpenFOAM ``cyclic``, CGNS periodic
1-to-1 connectivity: ``meshgen.formats.multiblock``).

A pair is (patch a, patch b, separation (dim,)) with ``b = a + separation``, or (patch a, patch b,
zeros, (centre (dim,), axis (3,), angle in degrees)) with b = a turned by the angle about the
axis through the centre (right-handed; 2D: about z); ``pair_map`` gives either as (R, t). ``check_cyclic``
compares the two sides' nodes after meshing (counts and positions, within ``TOLERANCE`` of the
block set's length); ``matching_order`` orders one side's boundary faces as the other's, face by
face. The elliptic solver keeps cyclic nodes where the TFI put them (``meshgen.methods.sliding``),
so sides that match after the TFI match after it.
"""

from __future__ import annotations

import numpy as np

from meshgen.errors import GeometryError
from meshgen.geometry import cube

__all__ = [
    "CYCLIC",
    "TOLERANCE",
    "VERTEX_GAP",
    "check_cyclic",
    "cyclic_pairs",
    "matching_order",
    "pair_map",
    "rotation_matrix",
    "side_nodes",
]

CYCLIC = "cyclic"
TOLERANCE = 1e-9  # the largest mismatch of paired nodes, relative to the block set's length
VERTEX_GAP = 1e-9  # that of a topology file's paired vertices, relative to its size (its vertices' GAP)


def rotation_matrix(axis, degrees: float, dim: int) -> np.ndarray:
    """The (dim, dim) rotation by ``degrees`` about the unit ``axis`` (3,) (Rodrigues; 2D: about z)."""
    k = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    angle = np.radians(degrees)
    cross = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    R = np.eye(3) + np.sin(angle) * cross + (1.0 - np.cos(angle)) * cross @ cross
    return R[:dim, :dim]


def pair_map(pair, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """(R (dim, dim), t (dim,)) of a cyclic pair: its second side's points are x @ R.T + t."""
    if len(pair) < 4 or pair[3] is None:
        return np.eye(dim), np.asarray(pair[2], dtype=float)
    centre, axis, degrees = pair[3]
    R = rotation_matrix(axis, degrees, dim)
    centre = np.asarray(centre, dtype=float)
    return R, centre - centre @ R.T


def _said(pair) -> str:
    if len(pair) < 4 or pair[3] is None:
        return "separation " + " ".join(f"{v:g}" for v in pair[2])
    centre, axis, degrees = pair[3]
    return f"rotation {degrees:g} deg about ({' '.join(f'{v:g}' for v in axis)}) through ({' '.join(f'{v:g}' for v in centre)})"


def side_nodes(block_set, Xs, patch: str) -> np.ndarray:
    """The nodes (N, dim) of every face of ``patch`` (faces in the block set's order, each in C order)."""
    parts = [
        Xs[block][cube.face_named(face, block_set.dim).node_index].reshape(-1, block_set.dim)
        for (block, face), (name, _) in block_set.patches.items()
        if name == patch
    ]
    return np.concatenate(parts) if parts else np.zeros((0, block_set.dim))


def _nearest(points: np.ndarray, targets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(distance (N,), index (N,)) of the nearest of ``targets`` (M, dim) to each of ``points``."""
    from scipy.spatial import cKDTree

    return cKDTree(targets).query(points)


def check_cyclic(block_set, Xs) -> None:
    """GeometryError (one line: the pair and its largest mismatch) unless every cyclic pair's
    sides have the same nodes up to its separation; a side's nodes shared by two of its faces
    count once."""
    for pair in getattr(block_set, "cyclic", ()):
        a, b = pair[:2]
        R, t = pair_map(pair, block_set.dim)
        first = np.unique(side_nodes(block_set, Xs, a), axis=0)
        second = np.unique(side_nodes(block_set, Xs, b), axis=0)
        said = f"geometry '{block_set.name}': cyclic patches '{a}' and '{b}' ({_said(pair)})"
        if len(first) != len(second):
            raise GeometryError(f"{said} do not match: {len(first)} and {len(second)} nodes")
        there, _ = _nearest(first @ R.T + t, second)
        back, _ = _nearest((second - t) @ R, first)
        mismatch = float(max(there.max(), back.max()))
        if mismatch > TOLERANCE * block_set.length:
            raise GeometryError(f"{said} do not match: the largest mismatch of their nodes is {mismatch:.3g}")


def matching_order(points: np.ndarray, first: np.ndarray, second: np.ndarray, pair, length: float) -> np.ndarray:
    """The order of ``second``'s faces (M, k node numbers into ``points``) that puts the i-th at
    the i-th of ``first`` mapped by the cyclic ``pair`` (by face centres); GeometryError when they
    are not one-to-one within ``TOLERANCE * length``."""
    R, t = pair_map(pair, points.shape[1])
    centres = points[first].mean(axis=1) @ R.T + t
    distance, order = _nearest(centres, points[second].mean(axis=1))
    if len(first) != len(second) or len(np.unique(order)) != len(order) or distance.max() > TOLERANCE * length:
        worst = float(distance.max()) if len(distance) else 0.0
        raise GeometryError(f"cyclic faces do not pair up: {len(first)} and {len(second)} faces, largest mismatch {worst:.3g}")
    return order


def cyclic_pairs(topology) -> list[tuple]:
    """The cyclic pairs of a topology file (``meshgen.geometry.topology_file.Topology``): (patch,
    neighbour, separation (dim,)) taking the patch's vertices onto the neighbour's, or (patch,
    neighbour, zeros, rotation) for a pair the file gives a rotation; GeometryError (the pair, its
    largest mismatch) when the map takes some vertex onto none of the other side's."""
    size = float(np.ptp(topology.points, axis=0).max()) or 1.0
    pairs = []
    for a, b in topology.cyclic:
        first, second = (sorted({v for face in topology.patches[p][1] for v in face}) for p in (a, b))
        X, Y = topology.points[first], topology.points[second]
        rotation = topology.rotations.get(a)
        if rotation is None:
            pair = (a, b, tuple(float(v) for v in Y.mean(axis=0) - X.mean(axis=0)))
        else:
            pair = (a, b, (0.0,) * topology.dim, rotation)
        R, t = pair_map(pair, topology.dim)
        said = f"topology file {topology.path}: cyclic patches '{a}' and '{b}'"
        if len(first) != len(second):
            raise GeometryError(f"{said} do not match: {len(first)} and {len(second)} vertices")
        gaps = np.linalg.norm((X @ R.T + t)[:, None] - Y[None], axis=2)  # (vertices, vertices): a patch has few
        mismatch = float(max(gaps.min(axis=1).max(), gaps.min(axis=0).max()))
        moved = float(np.abs(X @ R.T + t - X).max())
        if mismatch > VERTEX_GAP * size or moved <= VERTEX_GAP * size:
            how = "a translation" if rotation is None else f"the {_said(pair)}"
            raise GeometryError(f"{said} do not match under {how}: the largest mismatch of their vertices is {mismatch:.3g}")
        pairs.append(pair)
    return pairs

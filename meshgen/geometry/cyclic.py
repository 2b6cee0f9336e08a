"""Cyclic (periodic) patch pairs of a block set: two boundary patches whose nodes match under a
translation, so a solver treats them as one interface (OpenFOAM ``cyclic``, CGNS periodic
1-to-1 connectivity: ``meshgen.formats.multiblock``).

A pair is (patch a, patch b, separation (dim,)) with ``b = a + separation``. ``check_cyclic``
compares the two sides' nodes after meshing (counts and positions, within ``TOLERANCE`` of the
block set's length); ``matching_order`` orders one side's boundary faces as the other's, face by
face. The elliptic solver keeps cyclic nodes where the TFI put them (``meshgen.methods.sliding``),
so sides that match after the TFI match after it.
"""

from __future__ import annotations

import numpy as np

from meshgen.errors import GeometryError
from meshgen.geometry import cube

__all__ = ["CYCLIC", "TOLERANCE", "VERTEX_GAP", "check_cyclic", "cyclic_pairs", "matching_order", "side_nodes"]

CYCLIC = "cyclic"
TOLERANCE = 1e-9  # the largest mismatch of paired nodes, relative to the block set's length
VERTEX_GAP = 1e-9  # that of a topology file's paired vertices, relative to its size (its vertices' GAP)


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
    for a, b, separation in getattr(block_set, "cyclic", ()):
        first = np.unique(side_nodes(block_set, Xs, a), axis=0)
        second = np.unique(side_nodes(block_set, Xs, b), axis=0)
        shift = " ".join(f"{v:g}" for v in separation)
        said = f"geometry '{block_set.name}': cyclic patches '{a}' and '{b}' (separation {shift})"
        if len(first) != len(second):
            raise GeometryError(f"{said} do not match: {len(first)} and {len(second)} nodes")
        there, _ = _nearest(first + np.asarray(separation), second)
        back, _ = _nearest(second - np.asarray(separation), first)
        mismatch = float(max(there.max(), back.max()))
        if mismatch > TOLERANCE * block_set.length:
            raise GeometryError(f"{said} do not match: the largest mismatch of their nodes is {mismatch:.3g}")


def matching_order(points: np.ndarray, first: np.ndarray, second: np.ndarray, separation, length: float) -> np.ndarray:
    """The order of ``second``'s faces (M, k node numbers into ``points``) that puts the i-th at
    the i-th of ``first`` translated by ``separation`` (by face centres); GeometryError when they
    are not one-to-one within ``TOLERANCE * length``."""
    centres = points[first].mean(axis=1) + np.asarray(separation)
    distance, order = _nearest(centres, points[second].mean(axis=1))
    if len(first) != len(second) or len(np.unique(order)) != len(order) or distance.max() > TOLERANCE * length:
        worst = float(distance.max()) if len(distance) else 0.0
        raise GeometryError(f"cyclic faces do not pair up: {len(first)} and {len(second)} faces, largest mismatch {worst:.3g}")
    return order


def cyclic_pairs(topology) -> list[tuple[str, str, tuple]]:
    """[(patch, neighbour, separation)] of a topology file's cyclic pairs
    (``meshgen.geometry.topology_file.Topology``), the separation (dim,) taking
    the patch's vertices onto the neighbour's; GeometryError (the pair, its largest mismatch) when
    no translation does."""
    size = float(np.ptp(topology.points, axis=0).max()) or 1.0
    pairs = []
    for a, b in topology.cyclic:
        first, second = (sorted({v for face in topology.patches[p][1] for v in face}) for p in (a, b))
        X, Y = topology.points[first], topology.points[second]
        separation = Y.mean(axis=0) - X.mean(axis=0)
        said = f"topology file {topology.path}: cyclic patches '{a}' and '{b}'"
        if len(first) != len(second):
            raise GeometryError(f"{said} do not match: {len(first)} and {len(second)} vertices")
        gaps = np.linalg.norm(X[:, None] + separation - Y[None], axis=2)  # (vertices, vertices): a patch has few
        mismatch = float(max(gaps.min(axis=1).max(), gaps.min(axis=0).max()))
        if mismatch > VERTEX_GAP * size or np.linalg.norm(separation) <= VERTEX_GAP * size:
            raise GeometryError(
                f"{said} do not match under a translation: the largest mismatch of their vertices is {mismatch:.3g}"
            )
        pairs.append((a, b, tuple(float(v) for v in separation)))
    return pairs

"""A small quality summary for the end of training: validity, angles and boundary deviation.

Stand-in until ``meshgen.quality`` is available: the same definitions as DESIGN section 7 for the
few figures it reports.

- inverted cells: cells with a corner Jacobian det(e1, e2, e3) <= 0 (2D: e1 x e2), the edges
  taken along the index directions at each of the 2^d corners;
- min / max angle: per cell the smallest / largest of the angles between two edges at a corner
  (3D: the 24 face-corner angles, 2D: the 4 corner angles), in degrees, averaged over cells;
- boundary deviation: distance of every boundary node from the geometry's boundary map at the
  same parametric point, max and mean, also relative to the characteristic length. For a
  structured mesh this is the deviation from where the node belongs, an upper bound of its
  distance from the surface.
"""

from __future__ import annotations

import itertools

import numpy as np


def _corner_edges(X: np.ndarray, away: bool) -> np.ndarray:
    """For every cell and corner, the d edge vectors along the index directions: pointing away from
    the corner (``away``) or all in the increasing index direction (the columns of the corner
    Jacobian). Returns (cells..., 2^d, d edges, d components)."""
    dim = X.shape[-1]
    cells = tuple(n - 1 for n in X.shape[:-1])
    differences = [np.diff(X, axis=axis) for axis in range(dim)]
    corners = []
    for corner in itertools.product((0, 1), repeat=dim):
        edges = []
        for axis in range(dim):
            index = tuple(
                slice(0, cells[d]) if d == axis else slice(corner[d], corner[d] + cells[d]) for d in range(dim)
            )
            sign = -1.0 if away and corner[axis] == 1 else 1.0
            edges.append(sign * differences[axis][index])
        corners.append(np.stack(edges, axis=-2))
    return np.stack(corners, axis=-3)


def corner_jacobians(X: np.ndarray) -> np.ndarray:
    """det(e1, e2[, e3]) of the index-direction edges at each cell corner: (cells..., 2^d)."""
    return np.linalg.det(_corner_edges(X, away=False))


def corner_angles(X: np.ndarray) -> np.ndarray:
    """Angles (degrees) between each pair of edges at each cell corner: (cells..., 2^d * C(d, 2))."""
    edges = _corner_edges(X, away=True)
    unit = edges / np.maximum(np.linalg.norm(edges, axis=-1, keepdims=True), 1e-300)
    dim = X.shape[-1]
    angles = []
    for a, b in itertools.combinations(range(dim), 2):
        cosine = np.clip(np.einsum("...c,...c->...", unit[..., a, :], unit[..., b, :]), -1.0, 1.0)
        angles.append(np.degrees(np.arccos(cosine)))
    return np.concatenate(angles, axis=-1)


def boundary_nodes(shape) -> np.ndarray:
    """Boolean mask (n1+1, ...) of the nodes on the parametric cube's boundary."""
    mask = np.zeros(shape, dtype=bool)
    for axis in range(len(shape)):
        index = [slice(None)] * len(shape)
        for end in (0, -1):
            index[axis] = end
            mask[tuple(index)] = True
    return mask


def boundary_deviation(X: np.ndarray, geometry, coords) -> np.ndarray:
    """Distance of each boundary node of ``X`` from the boundary map at its parametric point:
    (number of boundary nodes,). ``coords``: the 1D parametric node coordinates per axis."""
    mask = boundary_nodes(X.shape[:-1])
    grid = np.stack(np.meshgrid(*coords, indexing="ij"), axis=-1)
    return np.linalg.norm(X[mask] - geometry.boundary(grid[mask]), axis=-1)


def snap_boundary(X: np.ndarray, geometry, coords) -> np.ndarray:
    """A copy of ``X`` with its boundary nodes moved onto the boundary map."""
    mask = boundary_nodes(X.shape[:-1])
    grid = np.stack(np.meshgrid(*coords, indexing="ij"), axis=-1)
    snapped = X.copy()
    snapped[mask] = geometry.boundary(grid[mask])
    return snapped


def quality_summary(X: np.ndarray, geometry, coords) -> dict:
    """The figures of this module for node array ``X`` (n1+1, ..., d) of ``geometry``."""
    jacobians = corner_jacobians(X).reshape(-1, 2 ** X.shape[-1])
    angles = corner_angles(X).reshape(jacobians.shape[0], -1)
    deviation = boundary_deviation(X, geometry, coords)
    inverted = int(np.count_nonzero(jacobians.min(axis=1) <= 0))
    length = geometry.characteristic_length
    return {
        "cells": int(jacobians.shape[0]),
        "inverted": inverted,
        "inverted_percent": 100.0 * inverted / jacobians.shape[0],
        "min_angle_mean": float(angles.min(axis=1).mean()),
        "max_angle_mean": float(angles.max(axis=1).mean()),
        "boundary_deviation_max": float(deviation.max()),
        "boundary_deviation_mean": float(deviation.mean()),
        "boundary_deviation_max_relative": float(deviation.max() / length),
        "characteristic_length": float(length),
    }


def summary_lines(name: str, report: dict) -> list[str]:
    """One line per figure group, for the terminal."""
    return [
        f"{name}: {report['inverted']} of {report['cells']} cells inverted ({report['inverted_percent']:.2f}%), "
        f"mean min angle {report['min_angle_mean']:.2f} deg, mean max angle {report['max_angle_mean']:.2f} deg, "
        f"boundary deviation max {report['boundary_deviation_max']:.3g} mean {report['boundary_deviation_mean']:.3g} "
        f"({100 * report['boundary_deviation_max_relative']:.2f}% of {report['characteristic_length']:.3g})"
    ]

"""Test shapes built by the tests themselves: random four-cornered surface patches, a bent
rectangular duct written as a multi-solid ASCII STL, a twisted loft exported to STEP by gmsh."""

from __future__ import annotations

import numpy as np


def random_patch(triangles: int, seed: int):
    """A random four-cornered patch of about ``triangles`` triangles: the Delaunay triangulation
    of random points in the unit disk (a share of them on its circle) with ears added on its boundary, lifted onto a random bumpy
    height field with an in-plane warp, randomly oriented. Returns (vertices (n, 3), triangles
    (m, 3), corners: four boundary vertex indices in boundary order)."""
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(seed)
    n_points = triangles // 2 + 2
    n_circle = max(int(8 * np.sqrt(n_points)), 12)
    angles = np.sort(rng.uniform(0.0, 2 * np.pi, n_circle))
    radius = np.sqrt(rng.uniform(0.0, 0.97**2, n_points - n_circle))
    theta = rng.uniform(0.0, 2 * np.pi, n_points - n_circle)
    xy = np.concatenate(
        [np.column_stack([np.cos(angles), np.sin(angles)]), np.column_stack([radius * np.cos(theta), radius * np.sin(theta)])]
    )
    tri = Delaunay(xy).simplices
    d1, d2 = xy[tri[:, 1]] - xy[tri[:, 0]], xy[tri[:, 2]] - xy[tri[:, 0]]
    area = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    tri = np.where((area < 0)[:, None], tri[:, ::-1], tri)
    # Ears: a new vertex just outside some boundary edges (a, b) and the triangle (a, new, b),
    # whose three vertices all lie on the boundary: its edge a-b joins two vertices of one side.
    eared = rng.choice(n_circle, n_circle // 8, replace=False)
    mid = angles[eared] + 0.5 * (np.append(angles, angles[0] + 2 * np.pi)[eared + 1] - angles[eared])
    ear_xy = 1.01 * np.column_stack([np.cos(mid), np.sin(mid)])
    new = len(xy) + np.arange(len(eared))
    tri = np.concatenate([tri, np.column_stack([eared, new, (eared + 1) % n_circle])])
    xy = np.concatenate([xy, ear_xy])
    boundary_order = np.concatenate([np.arange(n_circle), new])[np.argsort(np.concatenate([angles, np.mod(mid, 2 * np.pi)]))]
    a, b, c = rng.uniform(0.5, 3.0, 3)
    warp = 0.15 * np.column_stack([np.sin(a * xy[:, 1]), np.sin(b * xy[:, 0])])
    height = 0.4 * np.sin(a * xy[:, 0] + 1.0) * np.cos(b * xy[:, 1]) + 0.3 * np.sin(c * (xy[:, 0] + xy[:, 1]))
    vertices = np.column_stack([xy + warp, height])
    if rng.random() < 0.5:
        tri = tri[:, ::-1]
    quarter = len(boundary_order) // 4
    picks = rng.integers(0, quarter, 4) + np.arange(4) * quarter
    corners = boundary_order[picks]
    return vertices, tri, corners

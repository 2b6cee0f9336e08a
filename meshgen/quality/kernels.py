"""The per-cell metrics of design notes §7: definitions, corner and face tables.

Per cell, for hexahedra (quadrilaterals: the one face, edges instead of faces):

- ``min_angle``, ``max_angle`` (degrees): over the 24 face corners (6 faces x 4 corners), the angle
  between the two edges at the corner. As in Verdict (VTK's ``vtkMeshQuality``), a face with a reflex
  corner (a corner normal that opposes the face's normal at its centre) reports ``360 - angle`` as
  its largest angle, so a folded face shows a maximum angle above 180.
- ``equiangle_skewness``: max((max_angle - 90) / 90, (90 - min_angle) / 90); 0 best, 1 worst
  for convex faces (above 1 only with a reflex corner).
- ``aspect_ratio``: mean edge length along each index direction; largest over smallest (>= 1).
- ``centroid_skewness``: 1 - min over the faces of |n_f . e|, n_f the unit face normal, e the
  unit vector from the cell centroid to the face centroid; 0 best.
- ``non_orthogonality`` (degrees): per face the angle between the face normal and the line joining
  the centroids of the two cells that share it (boundary faces: cell centroid to face centroid);
  per cell the largest over its faces.
- ``scaled_jacobian``: min over the corners of det(e1, e2, e3) / (|e1| |e2| |e3|), the corner's
  three edges in right-handed order (Verdict's corner Jacobians); <= 0 means inverted.
  Quadrilaterals: e1 x e2 / (|e1| |e2|) against the mesh's orientation (the sign of its total area).

The normal of a (generally non-planar) hex face is the normal of the bilinear face at its centre:
the cross product of its diagonals, normalised. The centroid of a cell or face is the mean of its
corner nodes.

A cell is *degenerate* when an edge has zero length (at most 1e-12 of the mesh's bounding-box
diagonal) or a corner is not finite. Degenerate cells count as inverted; their per-cell values are
set to the worst ones (angles 0 and 180, skewnesses 1, non-orthogonality 90, aspect ratio inf,
scaled Jacobian <= 0) and the summaries (mean, min, max, 1st and 99th percentiles) are taken over
the other cells, so they are never NaN. A mesh is valid when none of its cells is inverted (a tolerance is a gate the user sets:
``--fail-if "inverted.percent>0.5"``).

The compiled kernels of ``meshgen.quality.compiled`` compute them cell by cell, in parallel over
cells. The structured path (node arrays) and the unstructured one (points + connectivity, face
neighbours found from shared nodes) run the same cell function on the same corner coordinates, so
they agree exactly.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "BLOCK_CELLS",
    "DEFINITIONS",
    "DEGENERATE_TOLERANCE",
    "HEX_CORNER",
    "HEX_FACES",
    "HEX_FACE_CORNERS",
    "METRICS",
    "QUAD_CORNER",
    "QUAD_FACES",
    "QUAD_FACE_CORNERS",
    "STATS",
    "VALID_FRACTION",
    "VALID_RULE",
    "WORST",
]

METRICS = (
    "min_angle",
    "max_angle",
    "equiangle_skewness",
    "aspect_ratio",
    "centroid_skewness",
    "non_orthogonality",
    "scaled_jacobian",
)
STATS = ("mean", "min", "max", "p01", "p99")
VALID_FRACTION = 0.0  # strict: one inverted cell makes a mesh invalid
VALID_RULE = "no inverted cell (inverted: scaled Jacobian <= 0 at a corner, or degenerate)"
DEGENERATE_TOLERANCE = 1e-12  # edge length, relative to the bounding-box diagonal

DEFINITIONS = {
    "min_angle": "smallest face-corner angle between the two edges at the corner (degrees)",
    "max_angle": "largest face-corner angle; a reflex corner of a face counts as 360 - angle, as in Verdict (degrees)",
    "equiangle_skewness": "max((max_angle - 90)/90, (90 - min_angle)/90); 0 best",
    "aspect_ratio": "mean edge length per index direction, largest over smallest; 1 best",
    "centroid_skewness": "1 - min over faces |n_f . e|, e the unit vector from cell centroid to face centroid; 0 best",
    "non_orthogonality": "max over faces of the angle between face normal and the line joining the two cell "
    "centroids (boundary faces: cell centroid to face centroid) (degrees)",
    "scaled_jacobian": "min over corners of det(e1, e2, e3)/(|e1||e2||e3|), right-handed corner edges; <= 0 inverted",
}
# Values given to degenerate cells in the per-cell arrays (the summaries leave those cells out).
WORST = {
    "min_angle": 0.0,
    "max_angle": 180.0,
    "equiangle_skewness": 1.0,
    "aspect_ratio": np.inf,
    "centroid_skewness": 1.0,
    "non_orthogonality": 90.0,
}

BLOCK_CELLS = 16384  # cells per block where a caller processes cells in blocks

# Corner offsets (s0, s1[, s2]) -> VTK corner index (hexahedron, quad), as meshgen.geometry.grid writes them.
HEX_CORNER = {(0, 0, 0): 0, (1, 0, 0): 1, (1, 1, 0): 2, (0, 1, 0): 3, (0, 0, 1): 4, (1, 0, 1): 5, (1, 1, 1): 6, (0, 1, 1): 7}
QUAD_CORNER = {(0, 0): 0, (1, 0): 1, (1, 1): 2, (0, 1): 3}
# Faces in kernel order: (normal axis, side); the VTK corners of each (unordered: to match faces).
HEX_FACES = [(axis, side) for axis in range(3) for side in (0, 1)]
QUAD_FACES = [(axis, side) for axis in range(2) for side in (0, 1)]


def _face_corner_table(corner_index: dict, faces) -> np.ndarray:
    return np.array([[k for s, k in corner_index.items() if s[axis] == side] for axis, side in faces])


HEX_FACE_CORNERS = _face_corner_table(HEX_CORNER, HEX_FACES)  # (6, 4)
QUAD_FACE_CORNERS = _face_corner_table(QUAD_CORNER, QUAD_FACES)  # (4, 2)

"""Angles from the cosines the compiled hexahedron kernels leave (``meshgen.quality.compiled``).

The kernels' loops over cells vectorise, but a call to the scalar ``acos`` in one stops that, and
three of them per cell cost more than the rest of the cell. So the kernels leave the cosines in
their output rows and ``finish_hex_angles`` turns them into angles with NumPy's vectorised
``arccos``, the arithmetic of the NumPy definition (``numpy_kernels._finish``): equal cosines give
equal angles, to the bit, in both kernels. Columns are done in runs that stay in cache, spread
over the CPUs (``meshgen.quality.pool``).
"""

from __future__ import annotations

import math

import numpy as np

from meshgen.quality.pool import map_in_threads

__all__ = ["FINISH_COLUMNS", "finish_hex_angles"]

# Columns (cells) per task: the four rows touched stay in L2.
FINISH_COLUMNS = 1 << 14
_DEGREES = 180.0 / math.pi  # np.degrees multiplies by this constant


def _finish_columns(out, first: int, last: int) -> None:
    """``finish_hex_angles`` of the cells ``first <= c < last``."""
    largest, max_cosine, reflex, face = (out[row, first:last] for row in (0, 1, 2, 5))
    for cosine in (largest, max_cosine, face):
        np.clip(cosine, -1.0, 1.0, out=cosine)
        np.arccos(cosine, out=cosine)
        np.multiply(cosine, _DEGREES, out=cosine)
    np.subtract(360.0, max_cosine, out=max_cosine, where=reflex != 0.0)
    np.subtract(max_cosine, 90.0, out=reflex)
    np.divide(reflex, 90.0, out=reflex)
    low = np.subtract(90.0, largest)
    np.divide(low, 90.0, out=low)
    np.maximum(reflex, low, out=reflex)


def finish_hex_angles(out: np.ndarray) -> None:
    """Angles in degrees, in place, from the cosines in ``out`` (7, m), float64: row 0 the largest
    corner cosine (-> min angle), row 1 the max-angle cosine (-> max angle; 360 minus it where
    row 2 flags a reflex corner), row 2 the reflex flag (-> equiangle skewness), row 5 the
    face-alignment cosine (-> non-orthogonality). The other rows are left as they are."""
    cells = out.shape[1]
    runs = [(first, min(cells, first + FINISH_COLUMNS)) for first in range(0, cells, FINISH_COLUMNS)]
    map_in_threads(lambda run: _finish_columns(out, *run), runs)

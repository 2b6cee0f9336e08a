"""Anderson acceleration of a fixed-point iteration x <- G(x): used by the elliptic solver
(``meshgen.elliptic``, G one V-cycle) and by the boundary layout's face solves (``meshgen.layout``,
G one Picard step)."""

from __future__ import annotations

import numpy as np

__all__ = ["ANDERSON_DEPTH", "AndersonMixing"]

ANDERSON_DEPTH = 3  # cycles remembered by the Anderson mixing (0: plain V-cycles)


class AndersonMixing:
    """Anderson acceleration of the fixed-point iteration x <- G(x), G one V-cycle.

    From the last ``depth`` differences of the cycle outputs (dG) and of the cycle updates
    f = G(x) - x (dF), the next iterate is G(x) - dG gamma with gamma minimising
    |f - dF gamma| (2-norm over all nodes): GMRES-like for the nearly linear late cycles, it removes
    the few modes a V-cycle reduces slowly (cells made nearly flat where the boundary is smooth
    across a corner of the parametric cube) at the price of 2 * depth stored arrays.
    """

    def __init__(self, depth: int):
        self.depth = depth
        self.output_changes: list[np.ndarray] = []
        self.update_changes: list[np.ndarray] = []
        self.previous = None  # (update, output) of the previous cycle

    def restart(self) -> None:
        self.output_changes.clear()
        self.update_changes.clear()
        self.previous = None

    def next_iterate(self, x: np.ndarray, output: np.ndarray) -> np.ndarray:
        if self.depth == 0:
            return output
        update = output - x
        if self.previous is not None:
            self.update_changes.append(update - self.previous[0])
            self.output_changes.append(output - self.previous[1])
            del self.update_changes[: -self.depth], self.output_changes[: -self.depth]
        self.previous = (update, output)
        if not self.update_changes:
            return output
        count = len(self.update_changes)
        gram = np.empty((count, count))
        for row in range(count):  # symmetric: the upper triangle, mirrored
            for column in range(row, count):
                gram[row, column] = gram[column, row] = _dot(self.update_changes[row], self.update_changes[column])
        target = np.array([_dot(a, update) for a in self.update_changes])
        gamma = np.linalg.lstsq(gram, target, rcond=1e-12)[0]
        mixed = output.copy()
        for weight, change in zip(gamma, self.output_changes):
            mixed -= weight * change
        return mixed


def _dot(a: np.ndarray, b: np.ndarray) -> float:
    """Sum of the products of two same-shaped arrays. NumPy's own loop, not BLAS: a BLAS dot
    starts its threads for each call, which costs milliseconds for a face's few thousand values
    and more on a loaded machine."""
    return float(np.einsum("i,i->", a.ravel(), b.ravel()))

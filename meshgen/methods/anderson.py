"""Anderson acceleration of a fixed-point iteration x <- G(x): used by the elliptic solver
(``meshgen.methods.elliptic``, G one V-cycle) and by the boundary layout's face solves (``meshgen.geometry.layout``,
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
        self.gram = np.zeros((0, 0))  # dot products of update_changes, kept from call to call
        self.previous = None  # (update, output) of the previous cycle

    def restart(self) -> None:
        self.output_changes.clear()
        self.update_changes.clear()
        self.gram = np.zeros((0, 0))
        self.previous = None

    def next_iterate(self, x: np.ndarray, output: np.ndarray) -> np.ndarray:
        if self.depth == 0:
            return output
        update = output - x
        if self.previous is not None:
            newest = update - self.previous[0]
            self.update_changes.append(newest)
            self.output_changes.append(output - self.previous[1])
            row = np.array([_dot(change, newest) for change in self.update_changes])
            count = len(row)
            gram = np.empty((count, count))
            gram[:-1, :-1] = self.gram
            gram[-1, :] = gram[:, -1] = row
            drop = max(count - self.depth, 0)
            del self.update_changes[:drop], self.output_changes[:drop]
            self.gram = gram[drop:, drop:]
        self.previous = (update, output)
        if not self.update_changes:
            return output
        target = np.array([_dot(a, update) for a in self.update_changes])
        gamma = np.linalg.lstsq(self.gram, target, rcond=1e-12)[0]
        mixed = output.copy()
        scaled = np.empty_like(output)
        for weight, change in zip(gamma, self.output_changes):
            mixed -= np.multiply(change, weight, out=scaled)
        return mixed


def _dot(a: np.ndarray, b: np.ndarray) -> float:
    """Sum of the products of two same-shaped arrays. NumPy's own loop, not BLAS: a BLAS dot
    starts its threads for each call, which costs milliseconds for a face's few thousand values
    and more on a loaded machine."""
    return float(np.einsum("i,i->", a.ravel(), b.ravel()))

"""Shared by the test_neural_* files: tiny training configurations that run in about a second."""

from meshgen.neural.config import resolve_config

TINY = [
    "model.widths=[12,12]",
    "points.interior=100",
    "points.boundary=100",
    "points.boundary_pool=4",
    "pretrain.steps=2",
    "pretrain.points=100",
    "adam.steps=10",
    "lbfgs.steps=2",
    "lbfgs.max_iter=3",
    "lbfgs.history_size=5",
    "test.interior=50",
    "test.boundary=50",
    "checkpoint.every=5",
]


def tiny_config(*overrides, preset="default"):
    return resolve_config(preset, None, [*TINY, *overrides])


class Recorder:
    """A reporter that keeps the rows and messages and can ask the loop to stop after N steps."""

    def __init__(self, stop_after=None):
        self.rows, self.messages, self.stop_after = [], [], stop_after

    def stage(self, name, done, total):
        pass

    def update(self, row, done, total):
        self.rows.append(row)

    def message(self, text):
        self.messages.append(text)

    def should_stop(self):
        return self.stop_after is not None and len(self.rows) >= self.stop_after


def direct_correction(error_at, coords):
    """The boundary correction of ``meshgen.methods.correction`` by its direct form, a second
    algorithm: the multilinear interpolant of the errors at the cube's corners, written out as a
    sum over the corners of products of t and 1 - t, plus the 26-term (2D: 8-term) Gordon-Hall sum
    (``meshgen.methods.tfi.transfinite``) of the rest of the error with the blending (1 - t)^p, t^p.
    ``error_at``: (K, d) boundary parametric points -> (K, d) errors; ``coords``: 1D node
    coordinates per axis. Returns the correction on their tensor grid, (n1, .., d)."""
    import itertools

    import numpy as np

    from meshgen.methods.correction import CORRECTION_POWER
    from meshgen.methods.tfi import transfinite

    dim = len(coords)
    corners = [np.array(c, dtype=float) for c in itertools.product((0, 1), repeat=dim)]
    values = [error_at(corner[None, :])[0] for corner in corners]

    def corner_part(t):  # t: dim broadcastable arrays
        return sum(
            np.prod([ti if c else 1.0 - ti for ti, c in zip(t, corner)], axis=0)[..., None] * value
            for corner, value in zip(corners, values)
        )

    def rest_at(points):
        return error_at(points) - corner_part([points[:, d] for d in range(dim)])

    axes = [np.asarray(c, dtype=float).reshape([-1 if d == a else 1 for d in range(dim)]) for a, c in enumerate(coords)]
    grid = np.broadcast_arrays(*axes)
    return corner_part(grid) + transfinite(rest_at, axes, power=CORRECTION_POWER)

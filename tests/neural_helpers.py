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

"""A mergeable quantile sketch for percentiles of more values than fit in memory.

The logarithmic buckets of DDSketch (Masson, Rim and Lee, VLDB 2019): a value x != 0 goes to bucket
k = ceil(log_gamma |x|), gamma = (1 + a) / (1 - a), one set of buckets per sign; the bucket's value
2 gamma^k / (gamma + 1) is within relative error ``a`` (``RELATIVE_ACCURACY``) of every value in it.
Values with |x| below ``SMALLEST`` count as 0 (an absolute error below 1e-12). Sketches of blocks
merge by adding bucket counts, exactly and in any order, so a percentile of a mesh computed block by
block is the same whatever the blocks.

``quantile(sketch, q)`` interpolates between the estimates of the two order statistics around rank
q (n - 1), as ``np.percentile`` does between the exact ones: the result differs from
``np.percentile`` by at most ``RELATIVE_ACCURACY`` times the larger magnitude of those two values
(tested).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

__all__ = [
    "GAMMA",
    "LOG_GAMMA",
    "RELATIVE_ACCURACY",
    "SMALLEST",
    "Buckets",
    "QuantileSketch",
    "merge",
    "order_statistic",
    "quantile",
    "sketch_of",
    "part_figures",
]

RELATIVE_ACCURACY = 1e-4
GAMMA = (1.0 + RELATIVE_ACCURACY) / (1.0 - RELATIVE_ACCURACY)
LOG_GAMMA = math.log(GAMMA)
SMALLEST = 1e-12


@dataclass
class Buckets:
    """Counts of consecutive bucket keys ``offset``, ``offset + 1``, ..."""

    offset: int = 0
    counts: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))


@dataclass
class QuantileSketch:
    positive: Buckets = field(default_factory=Buckets)
    negative: Buckets = field(default_factory=Buckets)  # keys of |x|
    zeros: int = 0

    @property
    def count(self) -> int:
        return int(self.positive.counts.sum() + self.negative.counts.sum() + self.zeros)


def _buckets(magnitudes: np.ndarray) -> Buckets:
    if magnitudes.size == 0:
        return Buckets()
    keys = np.ceil(np.log(magnitudes) / LOG_GAMMA).astype(np.int64)
    offset = int(keys.min())
    return Buckets(offset, np.bincount(keys - offset))


def sketch_of(values: np.ndarray) -> QuantileSketch:
    """The sketch of finite ``values`` (any shape)."""
    values = np.asarray(values, dtype=float).reshape(-1)
    large = np.abs(values) >= SMALLEST
    zeros = int(values.size - np.count_nonzero(large))
    return QuantileSketch(_buckets(values[large & (values > 0)]), _buckets(-values[large & (values < 0)]), zeros)


def _merge_buckets(a: Buckets, b: Buckets) -> Buckets:
    if a.counts.size == 0:
        return b
    if b.counts.size == 0:
        return a
    offset = min(a.offset, b.offset)
    end = max(a.offset + a.counts.size, b.offset + b.counts.size)
    counts = np.zeros(end - offset, dtype=np.int64)
    counts[a.offset - offset : a.offset - offset + a.counts.size] += a.counts
    counts[b.offset - offset : b.offset - offset + b.counts.size] += b.counts
    return Buckets(offset, counts)


def merge(a: QuantileSketch, b: QuantileSketch) -> QuantileSketch:
    """The sketch of the union of the values of ``a`` and ``b``."""
    return QuantileSketch(_merge_buckets(a.positive, b.positive), _merge_buckets(a.negative, b.negative), a.zeros + b.zeros)


def _value(key: int) -> float:
    return 2.0 * GAMMA**key / (GAMMA + 1.0)


def order_statistic(sketch: QuantileSketch, rank: int) -> float:
    """Estimate of the ``rank``-th smallest value (0-based)."""
    negative = sketch.negative.counts
    if rank < negative.sum():
        # Ascending values are descending magnitudes: walk the negative keys from the top.
        cumulative = np.cumsum(negative[::-1])
        index = int(np.searchsorted(cumulative, rank, side="right"))
        return -_value(sketch.negative.offset + negative.size - 1 - index)
    rank -= int(negative.sum())
    if rank < sketch.zeros:
        return 0.0
    rank -= sketch.zeros
    cumulative = np.cumsum(sketch.positive.counts)
    index = int(np.searchsorted(cumulative, rank, side="right"))
    return _value(sketch.positive.offset + min(index, cumulative.size - 1))


def quantile(sketch: QuantileSketch, q: float, low: float | None = None, high: float | None = None) -> float:
    """The ``q``-quantile (0..1) with ``np.percentile``'s linear interpolation, from estimates of
    the two order statistics around rank q (n - 1); clipped to the exact ``low``/``high`` (min, max)
    when given."""
    n = sketch.count
    position = q * (n - 1)
    below = int(math.floor(position))
    above = min(below + 1, n - 1)
    fraction = position - below
    lower, upper = order_statistic(sketch, below), order_statistic(sketch, above)
    value = lower + (upper - lower) * fraction
    if low is not None:
        value = max(value, low)
    if high is not None:
        value = min(value, high)
    return float(value)


def part_figures(part: dict) -> dict:
    """The report's figures of a metric from its merged block summary (``count``, ``sum``, ``min``,
    ``max``, ``sketch``): mean, min, max, and p01 and p99 from the sketch."""
    return {
        "mean": part["sum"] / part["count"],
        "min": part["min"],
        "max": part["max"],
        "p01": quantile(part["sketch"], 0.01, part["min"], part["max"]),
        "p99": quantile(part["sketch"], 0.99, part["min"], part["max"]),
    }

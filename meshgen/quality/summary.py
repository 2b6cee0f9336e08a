"""What a block of the block-wise report keeps of each metric: count, sum, min, max and the quantile
sketch (``meshgen.quality.sketch``) of its values, in one compiled pass for the sketch.

``sketch.sketch_of`` builds the sketch from about ten NumPy passes (masks, a boolean copy per sign,
logarithms, keys, ``bincount``), 6 ms per million values; here NumPy takes the logarithms (its
vectorised ``log``, the same values ``sketch_of`` uses, so the keys and the sketch are the same to
the last count) and one compiled loop classifies the values and counts the keys, the metrics of a
block spread over threads.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

import meshgen.run.jit  # noqa: F401 - numba with its BLAS probe deferred (design notes §21)
from meshgen.quality import sketch as sketches
from meshgen.quality.pool import map_in_threads

__all__ = ["block_summaries", "metric_summary"]

_JIT = {"cache": True, "fastmath": False, "nogil": True, "error_model": "numpy"}


@njit(**_JIT)
def _keys(low, high, log_gamma):
    """Number of keys from that of logarithm ``low`` to that of ``high`` (0 when low > high)."""
    if low > high:
        return 0
    return np.int64(math.ceil(high / log_gamma)) - np.int64(math.ceil(low / log_gamma)) + 1


@njit(**_JIT)
def _bucket_counts(values, logs, smallest, log_gamma):
    """(zeros, positive offset, positive counts, negative offset, negative counts) of ``values``
    (m,) as ``sketch.sketch_of`` counts them, ``logs`` the natural logarithms of their magnitudes."""
    zeros = 0
    low_p, high_p, low_n, high_n = np.inf, -np.inf, np.inf, -np.inf
    for c in range(values.size):  # the keys' range: ceil(log / log_gamma) rises with the logarithm
        v, logarithm = values[c], logs[c]
        if not abs(v) >= smallest:  # NaN too, as in sketch_of
            zeros += 1
        elif v > 0.0:
            low_p, high_p = min(low_p, logarithm), max(high_p, logarithm)
        else:
            low_n, high_n = min(low_n, logarithm), max(high_n, logarithm)
    positive = np.zeros(_keys(low_p, high_p, log_gamma), dtype=np.int64)
    negative = np.zeros(_keys(low_n, high_n, log_gamma), dtype=np.int64)
    first_p = np.int64(math.ceil(low_p / log_gamma)) if positive.size else np.int64(0)
    first_n = np.int64(math.ceil(low_n / log_gamma)) if negative.size else np.int64(0)
    for c in range(values.size):
        v = values[c]
        if abs(v) >= smallest:
            key = np.int64(math.ceil(logs[c] / log_gamma))
            if v > 0.0:
                positive[key - first_p] += 1
            else:
                negative[key - first_n] += 1
    return zeros, first_p, positive, first_n, negative


@njit(**_JIT)
def _positive_counts(logs, first, size, log_gamma):
    """Counts of the keys ``first`` .. ``first + size - 1`` of values all at least ``SMALLEST``,
    ``logs`` their natural logarithms (``_bucket_counts`` without its first pass)."""
    counts = np.zeros(size, dtype=np.int64)
    for c in range(logs.size):
        counts[np.int64(math.ceil(logs[c] / log_gamma)) - first] += 1
    return counts


def metric_summary(values: np.ndarray) -> dict:
    """Count, sum, min, max and quantile sketch of ``values`` (m,) float64, m >= 1, finite (NaN
    counts as zero in the sketch, as in ``sketch_of``)."""
    values = np.ascontiguousarray(values, dtype=float)
    low, high = float(np.min(values)), float(np.max(values))
    logs = np.abs(values)
    with np.errstate(divide="ignore", invalid="ignore"):
        np.log(logs, out=logs)  # in place: a new array from np.log took several times longer
    if low >= sketches.SMALLEST and high < np.inf:  # all positive (most metrics): the key range from NumPy's extremes
        first = math.ceil(float(np.min(logs)) / sketches.LOG_GAMMA)
        size = math.ceil(float(np.max(logs)) / sketches.LOG_GAMMA) - first + 1
        counts = _positive_counts(logs, first, size, sketches.LOG_GAMMA)
        sketch = sketches.QuantileSketch(sketches.Buckets(int(first), counts), sketches.Buckets(), 0)
    else:
        zeros, positive_offset, positive, negative_offset, negative = _bucket_counts(
            values, logs, sketches.SMALLEST, sketches.LOG_GAMMA
        )
        sketch = sketches.QuantileSketch(
            sketches.Buckets(int(positive_offset), positive), sketches.Buckets(int(negative_offset), negative), int(zeros)
        )
    return {"count": int(values.size), "sum": float(np.sum(values)), "min": low, "max": high, "sketch": sketch}


def block_summaries(metrics: dict, kept: np.ndarray | None = None) -> dict:
    """``metric_summary`` of each metric's values (name -> (m,) array), of the cells ``kept`` ((m,)
    bool; None: all), metrics with no value left out; the metrics spread over threads."""
    names = list(metrics)

    def summary(name):
        values = metrics[name] if kept is None else metrics[name][kept]
        return metric_summary(values) if values.size else None

    summaries = map_in_threads(summary, names)
    return {name: part for name, part in zip(names, summaries) if part is not None}

"""Wall clustering: stretched parametric node positions along one axis, for boundary layers.

Every method maps parametric coordinates to physical nodes, so clustering is a choice of the 1D
node positions t_0 = 0 < t_1 < ... < t_n = 1 per axis. Spec syntax ``AXIS:SIDE:GROWTH``:

- AXIS: ``xi``, ``eta`` or ``zeta`` (or ``i``, ``j``, ``k``);
- SIDE: ``0`` / ``min`` (the wall at t = 0), ``1`` / ``max`` (t = 1) or ``both``;
- GROWTH: a geometric growth ratio r >= 1 between neighbouring cells, moving away from the wall
  (``zeta:both:1.1``), or ``h=VALUE``: the first cell's height as a fraction of the parametric
  edge, from which r is solved (``eta:0:h=0.002``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshgen.errors import ParameterError
from meshgen.run.limits import check_memory, chunked_mesh_bytes, node_count

__all__ = [
    "AXES",
    "SIDES",
    "Cluster",
    "clustered_coordinates",
    "node_coordinates",
    "parse_cluster",
    "respaced_lines",
    "smoothed_spacing",
]

AXES = {"xi": 0, "eta": 1, "zeta": 2, "i": 0, "j": 1, "k": 2}
SIDES = {"0": "min", "min": "min", "1": "max", "max": "max", "both": "both"}


@dataclass(frozen=True)
class Cluster:
    axis: int
    side: str  # "min", "max" or "both"
    ratio: float | None = None  # geometric growth ratio
    first_height: float | None = None  # first cell's parametric height


def parse_cluster(text: str) -> Cluster:
    """``"zeta:both:1.1"`` -> Cluster(axis=2, side="both", ratio=1.1); malformed specs raise."""
    parts = text.strip().split(":")
    usage = f"malformed {{name}} {text!r}: expected AXIS:SIDE:RATIO or AXIS:SIDE:h=HEIGHT, e.g. zeta:both:1.1"
    if len(parts) != 3:
        raise ParameterError("cluster", usage)
    axis, side, growth = (p.strip().lower() for p in parts)
    if axis not in AXES:
        raise ParameterError("cluster", f"{usage} (axis must be one of xi, eta, zeta)")
    if side not in SIDES:
        raise ParameterError("cluster", f"{usage} (side must be 0, 1 or both)")
    try:
        value = float(growth[2:] if growth.startswith("h=") else growth)
    except ValueError:
        raise ParameterError("cluster", usage) from None
    if growth.startswith("h="):
        if not 0.0 < value < 1.0:
            raise ParameterError("cluster", f"malformed {{name}} {text!r}: the first-cell height must lie in (0, 1)")
        return Cluster(AXES[axis], SIDES[side], first_height=value)
    if not (np.isfinite(value) and value >= 1.0):
        raise ParameterError("cluster", f"malformed {{name}} {text!r}: the growth ratio must be a number >= 1")
    return Cluster(AXES[axis], SIDES[side], ratio=value)


def _exponents(n: int, side: str) -> np.ndarray:
    """Power of the growth ratio for each of the n cells, counted from the wall(s)."""
    i = np.arange(n)
    return {"min": i, "max": i[::-1], "both": np.minimum(i, n - 1 - i)}[side]


def _solve_ratio(n: int, side: str, first_height: float) -> float:
    """Growth ratio r >= 1 whose first cell has parametric height ``first_height`` (bisection)."""
    exponents = _exponents(n, side)

    def first_cell(r):
        return 1.0 / np.sum(r**exponents)

    if first_cell(1.0) <= first_height:
        raise ParameterError(
            "cluster", f"{{name}} h={first_height:g} is not below the uniform cell height {1.0 / n:g}: nothing to cluster"
        )
    low, high = 1.0, 2.0
    while first_cell(high) > first_height:
        low, high = high, high * 2.0
        if high > 1e6:
            raise ParameterError("cluster", f"{{name}} h={first_height:g} cannot be reached with {n} cells")
    for _ in range(200):
        middle = 0.5 * (low + high)
        low, high = (middle, high) if first_cell(middle) > first_height else (low, middle)
    return 0.5 * (low + high)


def clustered_coordinates(n: int, cluster: Cluster) -> np.ndarray:
    """``n + 1`` node positions in [0, 1] whose cell widths grow geometrically away from the wall(s)."""
    ratio = cluster.ratio if cluster.ratio is not None else _solve_ratio(n, cluster.side, cluster.first_height)
    widths = ratio ** _exponents(n, cluster.side).astype(float)
    nodes = np.concatenate([[0.0], np.cumsum(widths)])
    return nodes / nodes[-1]


def node_coordinates(dims, specs=()) -> list[np.ndarray]:
    """1D parametric node positions per axis: uniform, except along the axes that ``specs``
    (strings or Cluster objects) cluster. Two specs on one axis, or an axis the mesh lacks, raise;
    so does a mesh that would not fit in memory even block by block (checked before allocating)."""
    shape = " x ".join(str(int(n)) for n in dims)
    check_memory(
        chunked_mesh_bytes(dims), f"a {shape} mesh ({node_count(dims):.3g} nodes), even block by block,", "pick fewer cells"
    )
    coords = [np.linspace(0.0, 1.0, int(n) + 1) for n in dims]
    seen = set()
    for spec in specs:
        cluster = parse_cluster(spec) if isinstance(spec, str) else spec
        if cluster.axis >= len(dims):
            raise ParameterError("cluster", f"{{name}} axis {list(AXES)[cluster.axis]} does not exist in a {len(dims)}D mesh")
        if cluster.axis in seen:
            raise ParameterError("cluster", f"{{name}} given twice for axis {list(AXES)[cluster.axis]}")
        seen.add(cluster.axis)
        coords[cluster.axis] = clustered_coordinates(int(dims[cluster.axis]), cluster)
    return coords


def smoothed_spacing(ds: np.ndarray, width: float) -> np.ndarray:
    """Spacings (n,) whose logarithm is that of ``ds`` (n,) diffused over about ``width`` cells
    (one implicit step, zero-flux ends), scaled to the same sum."""
    from scipy.linalg import solve_banded

    lam = width**2
    bands = np.zeros((3, len(ds)))
    bands[0, 1:] = bands[2, :-1] = -lam
    bands[1] = 1.0 + 2.0 * lam
    bands[1, 0] = bands[1, -1] = 1.0 + lam
    out = np.exp(solve_banded((1, 1), bands, np.log(ds)))
    return out * ds.sum() / out.sum()


def respaced_lines(X: np.ndarray, d: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """The nodes of every grid line of ``X`` (n, m + 1, 2) slid along it (its polyline) to the arc
    lengths d (1 + c w): ``d`` (m + 1,) the designed distances, or (n, m + 1) one row per line, c
    the line's length over d's last minus 1, ``w`` (m + 1,) the blend weight: the wall layers keep
    their distances, the growth ratio stays the designed one where the blend bends or stretches the lines."""
    n, nodes = X.shape[0], X.shape[1]
    steps = np.diff(X, axis=1)
    arc = np.zeros((n, nodes))
    np.cumsum(np.hypot(steps[..., 0], steps[..., 1]), axis=1, out=arc[:, 1:])
    d = np.broadcast_to(d, (n, nodes))
    target = d * (1.0 + (arc[:, -1:] / d[:, -1:] - 1.0) * weight[None, :])
    target[:, -1] = arc[:, -1]
    lift = 2.0 * arc[:, -1:].max() * np.arange(n)[:, None]  # one increasing array for all lines
    lifted, wanted = (arc + lift).ravel(), (target + lift).ravel()
    segment = np.clip(np.searchsorted(lifted, wanted, side="right") - 1, 0, n * nodes - 2)
    segment = np.minimum(segment, (np.arange(n)[:, None] * nodes + nodes - 2).repeat(nodes, axis=1).ravel())
    low = lifted.take(segment)
    step = lifted.take(segment + 1) - low
    fraction = np.where(step > 0, (wanted - low) / np.where(step > 0, step, 1.0), 0.0)
    out = np.empty(X.shape)
    for axis in range(2):  # 1D gathers (take) per coordinate: faster than gathering rows
        values = np.ascontiguousarray(X[..., axis]).ravel()
        start = values.take(segment)
        out[..., axis] = (start + fraction * (values.take(segment + 1) - start)).reshape(n, nodes)
    out[:, 0], out[:, -1] = X[:, 0], X[:, -1]
    return out

"""The smoothed boundary layout of a family of shapes, learnt over its parameter box.

The smoothed layout (``meshgen.geometry.layout``) of one shape is the boundary reparametrisation s_p that
puts the boundary nodes at arc length on the edges and on the faces' own Winslow surface grids;
solving it takes seconds per shape. A family (``meshgen.neural.family``) meets a new member at
every training step, so it cannot solve s_p per member. s_p is a smooth function of the shape
parameters p, so it is solved once at the members of a tensor grid over the parameter box
(``layout_points`` values per varied parameter, ends included; each solve cached on disk by
``meshgen.geometry.layout.layout_of``) and interpolated in between: every array of the layout (the edges'
and the faces' fine-grid values) is the tensor-product C1 cubic Hermite interpolant
(``meshgen.geometry.layout.interpolate_1d``, finite-difference slopes) of its values at the grid members,
along each parameter in turn. At a grid member it reproduces the solved layout bit for bit;
between them the error is that of cubic interpolation (tested on the semicylinder and the
flower). A family member's boundary map is then g_p(s~_p(xi)), s~_p the interpolant: the map a
family network is trained on, and meshes with, for every member.
"""

from __future__ import annotations

import functools
import itertools
from dataclasses import dataclass, replace

import numpy as np

from meshgen.errors import GeometryError
from meshgen.geometry.layout import RESOLUTION, Layout, interpolate_1d, layout_of, unsmoothed

__all__ = ["CONVERGED_UPDATE", "FamilyLayout", "interpolated_member", "layout_points", "solve_family_layout"]


CONVERGED_UPDATE = 1e-8  # a face's last parameter update above this: its surface grid is not solved


def layout_points(parameters: int) -> int:
    """Solved layouts per varied parameter: 5 for one or two parameters (25 solves at most), 3
    beyond (27 for three)."""
    return 5 if parameters <= 2 else 3


@dataclass(frozen=True, eq=False)
class FamilyLayout:
    """Smoothed layouts solved on a tensor grid over the parameter box, interpolated in between.

    ``ranges``: name -> (low, high) of the varied parameters, in order; ``points``: grid values
    per parameter (ends included). ``edge_values[key]``: (points,)*k + (cells + 1,) and
    ``face_values[key]`` (3D): (points,)*k + (cells + 1, cells + 1, 2), the solved layouts' arrays
    (``meshgen.geometry.layout.Layout``) stacked over the grid, its first axis the first parameter's."""

    dim: int
    ranges: dict
    points: int
    edge_values: dict
    face_values: dict

    def position(self, values: dict) -> list[float]:
        """Where ``values`` (name -> number) lie in the box, per parameter in [0, 1]."""
        return [(float(values[n]) - lo) / (hi - lo) for n, (lo, hi) in self.ranges.items()]

    def at(self, values: dict) -> Layout:
        """The interpolated layout of the member with varied ``values`` (name -> number)."""
        return self._at(tuple(self.position(values)))

    @functools.lru_cache(maxsize=32)  # noqa: B019 - a frozen instance; members repeat within a step
    def _at(self, position: tuple) -> Layout:
        def interpolate(stacked):
            for t in position:
                stacked = interpolate_1d(stacked, np.array([t]))[0]
            return stacked

        return Layout(
            self.dim,
            {key: interpolate(v) for key, v in self.edge_values.items()},
            {key: interpolate(v) for key, v in self.face_values.items()},
            {},
        )

    def record(self) -> dict:
        """Plain data for a checkpoint: lists and float64 arrays (``torch`` turns the arrays into
        tensors when it saves them; :meth:`from_record` reads either)."""
        return {
            "dim": self.dim,
            "ranges": {n: [float(lo), float(hi)] for n, (lo, hi) in self.ranges.items()},
            "points": self.points,
            "edge_keys": [[list(a), list(s)] for a, s in self.edge_values],
            "edge_values": [np.ascontiguousarray(v) for v in self.edge_values.values()],
            "face_keys": [list(k) for k in self.face_values],
            "face_values": [np.ascontiguousarray(v) for v in self.face_values.values()],
        }

    @classmethod
    def from_record(cls, record: dict) -> FamilyLayout:
        def array(value):
            return np.asarray(value.numpy() if hasattr(value, "numpy") else value, dtype=float)

        edges = {(tuple(a), tuple(s)): array(v) for (a, s), v in zip(record["edge_keys"], record["edge_values"])}
        faces = {tuple(k): array(v) for k, v in zip(record["face_keys"], record["face_values"])}
        ranges = {n: (float(lo), float(hi)) for n, (lo, hi) in record["ranges"].items()}
        return cls(int(record["dim"]), ranges, int(record["points"]), edges, faces)


def solve_family_layout(geometry, ranges: dict, points: int | None = None, cells: int = RESOLUTION) -> FamilyLayout:
    """Solve the smoothed layout (``meshgen.geometry.layout.layout_of``: cached per member on disk) of every
    member of the tensor grid of ``points`` values per parameter of ``ranges`` (name -> (low,
    high)) of ``geometry`` (bound to the fixed values), and stack them. A member whose layout
    cannot be solved, or whose face solves stop short of ``CONVERGED_UPDATE``, raises GeometryError
    naming it: an unconverged surface grid is no smooth layout to learn."""
    geometry = unsmoothed(geometry)
    points = points or layout_points(len(ranges))
    axes = [[(n, float(v)) for v in np.linspace(lo, hi, points)] for n, (lo, hi) in ranges.items()]
    layouts = []
    for member in itertools.product(*axes):
        values = dict(member)
        at = ", ".join(f"{k}={v:g}" for k, v in values.items())
        try:
            layout = layout_of(geometry.with_params(**values), cells)
        except GeometryError as exc:
            raise GeometryError(f"the smoothed layout of the member {at} cannot be solved ({exc})") from None
        unsolved = {name: info for name, info in layout.face_info.items() if not info["final_update"] <= CONVERGED_UPDATE}
        if unsolved:
            name, info = next(iter(unsolved.items()))
            raise GeometryError(
                f"the smoothed layout of the member {at} does not converge (face {name}: update "
                f"{info['final_update']:.1e} after {info['iterations']} iterations)"
            )
        layouts.append(layout)
    shape = (points,) * len(ranges)

    def stack(arrays):
        return np.stack(arrays).reshape(shape + arrays[0].shape)

    first = layouts[0]
    edges = {key: stack([layout.edge_values[key] for layout in layouts]) for key in first.edge_values}
    faces = {key: stack([layout.face_values[key] for layout in layouts]) for key in first.face_values}
    return FamilyLayout(geometry.dim, dict(ranges), points, edges, faces)


def interpolated_member(member, family_layout: FamilyLayout):
    """The bound Geometry ``member`` (its own boundary map, the varied parameters at the member's
    values) with the family's interpolated smoothed layout: boundary map g_p(s~_p(xi)). Marked as a
    smoothed geometry (``smoothed_from``), with ``layout_at(**values)`` giving its layout, so that
    ``meshgen.geometry.layout.smoothed`` leaves it and ``meshgen.geometry.layout.relax_faces`` starts from it."""
    plain = unsmoothed(member)
    base_map = plain.boundary_map
    names = list(family_layout.ranges)

    def layout_at(**values) -> Layout:
        return family_layout.at({n: values[n] for n in names})

    def boundary_map(points, **values):
        return base_map(layout_at(**values).apply(points), **values)

    boundary_map.smoothed_from = base_map
    boundary_map.layout_at = layout_at
    return replace(plain, boundary_map=boundary_map)

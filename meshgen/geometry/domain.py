"""The domain a mesh fills: the ``Geometry`` object that a plugin or a shape file gives (a boundary
map with its parameter values bound, design notes §3), and ``bind`` for other parameter values.
Finding and loading geometries is ``meshgen.geometry.plugins``."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from meshgen.errors import GeometryError, did_you_mean
from meshgen.geometry import cube
from meshgen.geometry.patches import as_records, geometry_patches
from meshgen.geometry.plugin_calls import call_plugin, plugin_array
from meshgen.geometry.surface import boundary_surface

__all__ = ["AXIS_NAMES", "Geometry", "bind", "dims_line"]

AXIS_NAMES = ("xi", "eta", "zeta")  # the --dims numbers' axes, in order


def dims_line(axes: dict) -> str:
    """``"xi: around the arc, eta: ..., zeta: ..."`` ("" for no axes)."""
    return ", ".join(f"{axis}: {meaning}" for axis, meaning in axes.items())


@dataclass(frozen=True)
class Geometry:
    """A geometry plugin with its parameter values bound.

    ``boundary(points)`` maps ``(N, dim)`` points on the boundary of the unit cube to ``(N, dim)``
    physical points (float64), checked for shape and finiteness.
    """

    name: str
    dim: int
    description: str
    defaults: dict[str, float]
    values: dict[str, float]
    boundary_map: Callable = field(repr=False)
    length_map: Callable | None = field(default=None, repr=False)
    source: str = ""
    patches: dict = field(default_factory=dict)  # cube face -> (patch name, type), as declared
    axes: tuple[str, ...] = ()  # what each --dims number counts, in the order xi, eta[, zeta] ("" each when undeclared)

    def boundary(self, points: np.ndarray) -> np.ndarray:
        points = np.asarray(points, dtype=float)
        if points.ndim != 2 or points.shape[1] != self.dim:
            raise GeometryError(f"geometry '{self.name}': boundary points must have shape (N, {self.dim}), got {points.shape}")
        plugin = f"'{self.name}' ({self.source})"
        mapped = call_plugin(plugin, "boundary()", self.boundary_map, points, **self.values)
        return plugin_array(plugin, "boundary()", mapped, points.shape)

    @property
    def characteristic_length(self) -> float:
        """Length scale for relative figures: the plugin's own, else the bounding-box diagonal."""
        if self.length_map is not None:
            plugin = f"'{self.name}' ({self.source})"
            length = call_plugin(plugin, "characteristic_length()", self.length_map, **self.values)
            length = float(plugin_array(plugin, "characteristic_length()", length, ()))
            if not length > 0:
                raise GeometryError(
                    f"geometry '{self.name}' ({self.source}): characteristic_length() must be a positive number, got {length!r}"
                )
            return length
        samples = np.concatenate([cube.corners(self.dim), cube.face_samples(self.dim, 9)])
        mapped = self.boundary(samples)
        return float(np.linalg.norm(mapped.max(axis=0) - mapped.min(axis=0)))

    def with_params(self, **values: float) -> Geometry:
        """The same plugin with some parameter values replaced (names checked)."""
        return bind(self, values)

    def describe(self) -> dict:
        """``meshgen geometries`` entry: name, dim, description, params, patches, and what --dims
        counts (``axes``: {"xi": ..., "eta": ...[, "zeta": ...]}, {} when the plugin does not say;
        ``dims``: the same on one line)."""
        axes = dict(zip(AXIS_NAMES, self.axes))
        return {
            "name": self.name,
            "dim": self.dim,
            "description": self.description,
            "params": dict(self.defaults),
            "patches": as_records(geometry_patches(self)),
            "axes": axes,
            "dims": dims_line(axes),
        }

    def surface(self, resolution: int = 64):
        """Closed boundary surface as a watertight ``trimesh.Trimesh`` (3D), or the filled
        domain triangulated in the z = 0 plane (2D)."""
        return boundary_surface(self, resolution)


def bind(geometry: Geometry, values: dict[str, float] | None) -> Geometry:
    """``geometry`` with parameter ``values`` (a subset of its parameters) replacing the current ones."""
    values = dict(values or {})
    unknown = sorted(set(values) - set(geometry.defaults))
    if unknown:
        valid = ", ".join(geometry.defaults) or "none"
        hint = did_you_mean(unknown[0], geometry.defaults)
        raise GeometryError(f"geometry '{geometry.name}' has no parameter {unknown[0]!r} (parameters: {valid}){hint}")
    merged = {**geometry.values, **{k: float(v) for k, v in values.items()}}
    bad = [k for k, v in merged.items() if not np.isfinite(v)]
    if bad:
        raise GeometryError(f"geometry '{geometry.name}': parameter {bad[0]!r} must be a finite number")
    return dataclasses.replace(geometry, values=merged)

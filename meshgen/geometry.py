"""Geometry plugins: the boundary parametrisation of a physical domain (DESIGN section 3).

A plugin is a Python module (a file, or a module named by an entry point) with:

    name = "semicylinder"          # lower-case identifier
    dim = 3                        # 2 or 3
    description = "one line"
    params = {"radius": 1.0}       # named float parameters with their defaults

    def boundary(points, **params):
        '''(N, dim) points on the unit cube's boundary -> (N, dim) physical points.'''

    def characteristic_length(**params):   # optional; default: bounding-box diagonal
        ...

    patches = {"zeta0": ("inlet", "patch"), "xi0": ("wall", "wall"), ...}
                                   # optional: boundary patch (name, type) per cube face
                                   # (meshgen.patches); faces left out keep their face name

The boundary map must be vectorised and continuous across the cube's edges and corners.
Everything else (TFI, surfaces, deviation checks) is derived from it.

Discovery, in this order: built-in files in the top-level ``geometries/`` folder, packages
that register a module under the entry-point group ``meshgen.geometries``, and a path to a
``.py`` file. A plugin is imported only when it is used.
"""

from __future__ import annotations

import importlib.util
import itertools
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType

import numpy as np

from meshgen import cube
from meshgen.errors import GeometryError, did_you_mean

ENTRY_POINT_GROUP = "meshgen.geometries"


def builtin_dir(kind: str) -> Path:
    """Folder of bundled ``kind`` files ("geometries" or "presets"): inside an installed wheel
    they live in ``meshgen/_builtin/``, in a source checkout at the repository's top level."""
    package_dir = Path(__file__).resolve().parent
    installed = package_dir / "_builtin" / kind
    return installed if installed.is_dir() else package_dir.parent / kind


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

    def boundary(self, points: np.ndarray) -> np.ndarray:
        points = np.asarray(points, dtype=float)
        if points.ndim != 2 or points.shape[1] != self.dim:
            raise GeometryError(f"geometry '{self.name}': boundary points must have shape (N, {self.dim}), got {points.shape}")
        try:
            mapped = self.boundary_map(points, **self.values)
        except GeometryError:
            raise
        # A plugin is foreign code: report it with its name and file. SystemExit too: sys.exit() in
        # a plugin must not end meshgen with the plugin's status (0 would read as success).
        except (Exception, SystemExit) as exc:
            raise GeometryError(f"geometry '{self.name}' ({self.source}): boundary() raised {type(exc).__name__}: {exc}") from exc
        try:
            mapped = np.asarray(mapped, dtype=float)
        except (TypeError, ValueError) as exc:
            raise GeometryError(
                f"geometry '{self.name}' ({self.source}): boundary() returned something that is not "
                f"an array of numbers ({type(mapped).__name__})"
            ) from exc
        if mapped.shape != points.shape:
            raise GeometryError(
                f"geometry '{self.name}' ({self.source}): boundary() returned shape {mapped.shape} for input shape {points.shape}"
            )
        if not np.all(np.isfinite(mapped)):
            raise GeometryError(f"geometry '{self.name}' ({self.source}): boundary() returned non-finite values")
        return mapped

    @property
    def characteristic_length(self) -> float:
        """Length scale for relative figures: the plugin's own, else the bounding-box diagonal."""
        if self.length_map is not None:
            try:
                length = float(self.length_map(**self.values))
            except (Exception, SystemExit) as exc:  # foreign code, as in boundary()
                raise GeometryError(
                    f"geometry '{self.name}' ({self.source}): characteristic_length() raised {type(exc).__name__}: {exc}"
                ) from exc
            if not (np.isfinite(length) and length > 0):
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
        from meshgen.patches import as_records, geometry_patches

        return {
            "name": self.name,
            "dim": self.dim,
            "description": self.description,
            "params": dict(self.defaults),
            "patches": as_records(geometry_patches(self)),
        }

    def surface(self, resolution: int = 64):
        """Closed boundary surface as a watertight ``trimesh.Trimesh`` (3D), or the filled
        domain triangulated in the z = 0 plane (2D)."""
        from meshgen.surface import boundary_surface

        return boundary_surface(self, resolution)


# ---------------------------------------------------------------------------------------------
# discovery


def _builtin_files() -> dict[str, Path]:
    folder = builtin_dir("geometries")
    return {p.stem: p for p in sorted(folder.glob("*.py")) if not p.name.startswith("_")}


def _entry_points() -> dict:
    from importlib.metadata import entry_points

    return {ep.name: ep for ep in entry_points(group=ENTRY_POINT_GROUP)}


def available_names() -> list[str]:
    """Names of all discoverable geometries (built-ins and entry points), without importing them."""
    return sorted(set(_builtin_files()) | set(_entry_points()))


def _import_file(path: Path) -> ModuleType:
    module_name = f"meshgen_plugin_{path.stem}_{abs(hash(str(path.resolve()))):x}"
    if module_name in sys.modules:
        return sys.modules[module_name]
    spec = importlib.util.spec_from_file_location(module_name, path)
    if spec is None or spec.loader is None:
        raise GeometryError(f"geometry file {path} cannot be imported (is it a .py file?)")
    module = importlib.util.module_from_spec(spec)
    sys.modules[module_name] = module
    try:
        spec.loader.exec_module(module)
    except (Exception, SystemExit) as exc:
        del sys.modules[module_name]
        raise GeometryError(f"geometry plugin {path} failed to load: {type(exc).__name__}: {exc}") from exc
    return module


def _from_module(module, source: str) -> Geometry:
    """Build an unbound Geometry (values = defaults) from a plugin module, checking the contract."""

    def need(attr):
        if not hasattr(module, attr):
            raise GeometryError(f"geometry plugin {source} does not define '{attr}'")
        return getattr(module, attr)

    name, dim, description = need("name"), need("dim"), need("description")
    boundary_map, params = need("boundary"), getattr(module, "params", {})
    if not isinstance(name, str) or not name:
        raise GeometryError(f"geometry plugin {source}: 'name' must be a non-empty string")
    if dim not in (2, 3):
        raise GeometryError(f"geometry plugin {source}: 'dim' must be 2 or 3, got {dim!r}")
    if not callable(boundary_map):
        raise GeometryError(f"geometry plugin {source}: 'boundary' must be a function")
    if not isinstance(params, dict) or not all(
        isinstance(k, str) and isinstance(v, (int, float)) and not isinstance(v, bool) for k, v in params.items()
    ):
        raise GeometryError(f"geometry plugin {source}: 'params' must map names to numbers")
    defaults = {k: float(v) for k, v in params.items()}
    length_map = getattr(module, "characteristic_length", None)
    patches = _declared_patches(getattr(module, "patches", {}), int(dim), source)
    if hasattr(module, "blocks"):  # a block set (meshgen.blocks): its boundary() takes a block name first
        boundary_map = _multiblock_boundary(name)
    return Geometry(
        name=name,
        dim=int(dim),
        description=str(description).strip().splitlines()[0] if str(description).strip() else "",
        defaults=defaults,
        values=dict(defaults),
        boundary_map=boundary_map,
        length_map=length_map if callable(length_map) else None,
        source=source,
        patches=patches,
    )


def _multiblock_boundary(name: str) -> Callable:
    """The boundary map of a multi-block plugin seen as one block: an error saying where to go."""

    def boundary(points, **values):
        raise GeometryError(f"geometry '{name}' is made of several blocks: mesh it with 'meshgen mesh' or meshgen.blocks")

    return boundary


def _declared_patches(declared, dim: int, source: str) -> dict:
    """A plugin's ``patches`` checked (faces, names, types, shared names sharing a type)."""
    from meshgen.errors import MeshgenError
    from meshgen.patches import face_assignment, patches_from_assignment

    if not isinstance(declared, dict) or not all(
        isinstance(v, (tuple, list)) and len(v) == 2 and all(isinstance(x, str) for x in v) for v in declared.values()
    ):
        raise GeometryError(f"geometry plugin {source}: 'patches' must map cube face names to (name, type) pairs")
    declared = {str(face): (name, kind) for face, (name, kind) in declared.items()}
    try:
        patches_from_assignment(face_assignment(dim, declared))
    except MeshgenError as exc:
        raise GeometryError(f"geometry plugin {source}: {exc}") from None
    return declared


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
    return Geometry(
        geometry.name,
        geometry.dim,
        geometry.description,
        geometry.defaults,
        merged,
        geometry.boundary_map,
        geometry.length_map,
        geometry.source,
        geometry.patches,
    )


def _looks_like_path(spec: str) -> bool:
    return spec.endswith(".py") or "/" in spec or "\\" in spec


def plugin_module(spec: str) -> tuple[ModuleType, str]:
    """The plugin module of a geometry name (built-in or entry point) or ``.py`` path, imported,
    with a description of where it came from (its file, or the entry point)."""
    if _looks_like_path(spec):
        path = Path(spec)
        if not path.is_file():
            raise GeometryError(f"geometry file {spec} does not exist")
        return _import_file(path), str(path)
    builtins = _builtin_files()
    if spec in builtins:
        return _import_file(builtins[spec]), str(builtins[spec])
    eps = _entry_points()
    if spec not in eps:
        names = available_names()
        raise GeometryError(f"unknown geometry '{spec}' (available: {', '.join(names)}){did_you_mean(spec, names)}")
    try:
        module = eps[spec].load()
    except (Exception, SystemExit) as exc:
        raise GeometryError(f"geometry plugin '{spec}' ({eps[spec].value}) failed to load: {type(exc).__name__}: {exc}") from exc
    return module, f"entry point {eps[spec].value}"


def load_geometry(spec: str, params: dict[str, float] | None = None, check: bool = True) -> Geometry:
    """Load a geometry by name (built-in or entry point) or by path to a ``.py`` plugin file,
    bind ``params`` over its defaults and, with ``check``, verify its boundary map
    (shape, finiteness, continuity across the cube's edges)."""
    geometry = _from_module(*plugin_module(spec))
    geometry = bind(geometry, params)
    if check:
        check_boundary(geometry)
    return geometry


def list_geometries() -> list[Geometry]:
    """Every discoverable geometry, loaded with default parameters (unchecked)."""
    return [load_geometry(name, check=False) for name in available_names()]


# ---------------------------------------------------------------------------------------------
# contract checks


def check_boundary(geometry: Geometry, tolerance: float = 1e-4) -> None:
    """Raise GeometryError unless the boundary map returns (N, dim) finite values and is
    continuous across the cube's edges: at sample points of every edge, stepping 1e-7 into
    each of the two adjacent faces must move the image by less than ``tolerance`` times
    the domain's size."""
    dim, step = geometry.dim, 1e-7
    free = np.array([0.13, 0.5, 0.91])
    on_edge, from_a, from_b = [], [], []
    for axis_a, axis_b in itertools.combinations(range(dim), 2):
        for side_a, side_b in itertools.product((0.0, 1.0), repeat=2):
            n = len(free) if dim == 3 else 1
            base = np.empty((n, dim))
            others = [d for d in range(dim) if d not in (axis_a, axis_b)]
            for d in others:
                base[:, d] = free
            base[:, axis_a], base[:, axis_b] = side_a, side_b
            into_a = base.copy()  # stay on face axis_a = side_a, move off the edge along axis_b
            into_a[:, axis_b] += step if side_b == 0.0 else -step
            into_b = base.copy()
            into_b[:, axis_a] += step if side_a == 0.0 else -step
            on_edge.append(base), from_a.append(into_a), from_b.append(into_b)
    on_edge, from_a, from_b = (np.concatenate(a) for a in (on_edge, from_a, from_b))
    images = geometry.boundary(np.concatenate([on_edge, from_a, from_b]))
    edge_img, a_img, b_img = np.split(images, 3)
    size = max(float(np.ptp(edge_img, axis=0).max()), 1e-12)
    jump = np.maximum(np.linalg.norm(a_img - edge_img, axis=1), np.linalg.norm(b_img - edge_img, axis=1))
    worst = int(np.argmax(jump))
    if jump[worst] > tolerance * size:
        where = ", ".join(f"{c:.3g}" for c in on_edge[worst])
        raise GeometryError(
            f"geometry '{geometry.name}' ({geometry.source}): boundary is not continuous across the cube's "
            f"edge at ({where}): the adjacent faces disagree by {jump[worst]:.3g}"
        )


def parse_params(items: tuple[str, ...] | list[str]) -> dict[str, float]:
    """``["radius=2", "length=3.5"]`` -> ``{"radius": 2.0, "length": 3.5}``; malformed items raise."""
    values = {}
    for item in items:
        key, sep, text = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise GeometryError(f"malformed --param {item!r}: expected name=value, e.g. radius=2")
        try:
            value = float(text)
        except ValueError:
            raise GeometryError(f"malformed --param {item!r}: {text!r} is not a number") from None
        if not np.isfinite(value):
            raise GeometryError(f"malformed --param {item!r}: value must be finite")
        values[key] = value
    return values

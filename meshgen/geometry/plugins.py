"""Geometry plugins: the boundary parametrisation of a physical domain (design notes §3).

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
                                   # (meshgen.geometry.patches); faces left out keep their face name

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
from pathlib import Path
from types import ModuleType

import numpy as np

from meshgen.errors import GeometryError, MeshgenError, did_you_mean
from meshgen.geometry.domain import Geometry, bind
from meshgen.geometry.patches import face_assignment, patches_from_assignment
from meshgen.geometry.plugin_calls import call_plugin
from meshgen.geometry.shapes.loader import is_shape_file, load_shape
from meshgen.geometry.shapes.sweep_yaml import is_sweep_geometry, sweep_geometry_module
from meshgen.geometry.topology import topology_module
from meshgen.geometry.topology_file import is_topology_file
from meshgen.run.trust import check_plugin_name, note_given_plugin, recorded_spec

__all__ = [
    "AIRFOIL_FILE_SUFFIXES",
    "ENTRY_POINT_GROUP",
    "Geometry",
    "available_names",
    "bind",
    "builtin_dir",
    "check_boundary",
    "is_airfoil_file",
    "list_geometries",
    "load_geometry",
    "load_recorded_geometry",
    "looks_like_path",
    "plugin_module",
    "parse_params",
]

ENTRY_POINT_GROUP = "meshgen.geometries"
AIRFOIL_FILE_SUFFIXES = (".dat",)  # Selig or Lednicer coordinates: the built-in airfoil plugin meshes them
_AIRFOIL_FILES: dict = {}


def builtin_dir(kind: str) -> Path:
    """Folder of bundled ``kind`` files ("geometries" or "presets"): inside an installed wheel
    they live in ``meshgen/_builtin/``, in a source checkout at the repository's top level."""
    package_dir = Path(__file__).resolve().parents[1]
    installed = package_dir / "_builtin" / kind
    return installed if installed.is_dir() else package_dir.parent / kind


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
        call_plugin(str(path), "import", spec.loader.exec_module, module, failed=f"geometry plugin {path} failed to load:")
    except BaseException:
        del sys.modules[module_name]
        raise
    return module


def _from_module(module, source: str) -> Geometry:
    """Build an unbound Geometry (values = defaults) from a plugin module, checking the contract."""

    def need(attr):
        if not hasattr(module, attr):
            raise GeometryError(f"geometry plugin {source} does not define '{attr}'")
        return getattr(module, attr)

    name, dim, description = need("name"), need("dim"), need("description")
    boundary_map, params = need("boundary"), getattr(module, "params", {})
    check_plugin_name(name, source)
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
    if hasattr(module, "blocks"):  # a block set (meshgen.geometry.blocks): its boundary() takes a block name first
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
        axes=_declared_axes(getattr(module, "axes", ()), int(dim), source),
    )


def _declared_axes(declared, dim: int, source: str) -> tuple[str, ...]:
    """A plugin's ``axes`` checked: what each --dims number counts, one short phrase per axis
    (xi, eta[, zeta]), e.g. ``("around the arc", "radial", "along the axis (flow)")``."""
    if isinstance(declared, (tuple, list)) and not declared:
        return ()
    if not (
        isinstance(declared, (tuple, list)) and len(declared) == dim and all(isinstance(x, str) and x.strip() for x in declared)
    ):
        raise GeometryError(
            f"geometry plugin {source}: 'axes' must be {dim} non-empty strings, what each --dims number counts (xi, eta"
            + (", zeta)" if dim == 3 else ")")
        )
    return tuple(" ".join(x.split())[:80] for x in declared)


def _multiblock_boundary(name: str) -> Callable:
    """The boundary map of a multi-block plugin seen as one block: an error saying where to go."""

    def boundary(points, **values):
        raise GeometryError(
            f"geometry '{name}' is made of several blocks: mesh it with 'meshgen mesh' or meshgen.geometry.blocks"
        )

    return boundary


def _declared_patches(declared, dim: int, source: str) -> dict:
    """A plugin's ``patches`` checked (faces, names, types, shared names sharing a type)."""
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


def is_airfoil_file(spec) -> bool:
    """Whether ``spec`` names an airfoil coordinate file (Selig or Lednicer) by its extension."""
    return Path(str(spec)).suffix.lower() in AIRFOIL_FILE_SUFFIXES


def _airfoil_module(path: Path) -> ModuleType:
    """The built-in airfoil plugin's copy for the coordinate file ``path`` (its ``file_module``),
    kept per (path, size, modification time)."""
    status = path.stat()
    key = (str(path.resolve()), status.st_size, status.st_mtime_ns)
    if key not in _AIRFOIL_FILES:
        _AIRFOIL_FILES[key] = _import_file(_builtin_files()["airfoil"]).file_module(path)
    return _AIRFOIL_FILES[key]


def looks_like_path(spec: str) -> bool:
    """Whether ``spec`` names a file (a ``.py`` plugin, a shape file, an airfoil coordinate file, or
    anything with a folder separator) rather than a built-in or installed geometry."""
    return (
        spec.endswith(".py") or "/" in spec or "\\" in spec or is_shape_file(spec) or is_topology_file(spec)
        or is_airfoil_file(spec)
    )  # fmt: skip


def plugin_module(spec: str, dims=None) -> tuple[ModuleType, str]:
    """The plugin module of a geometry name (built-in or entry point) or ``.py`` path, imported,
    with a description of where it came from (its file, or the entry point). With ``dims`` of one
    number more than the plugin's dim, a 2D block set that defines ``extruded()`` gives its 3D
    version (``meshgen.geometry.extrusion.extruded_plugin``: the third number counts along z)."""
    module, source = _plugin_module(spec)
    if dims is not None and len(dims) == getattr(module, "dim", 0) + 1 and callable(getattr(module, "extruded", None)):
        module = call_plugin(source, "extruded", module.extruded)
    return module, source


def _plugin_module(spec: str) -> tuple[ModuleType, str]:
    if looks_like_path(spec):
        path = Path(spec)
        if not path.is_file():
            raise GeometryError(f"geometry file {spec} does not exist")
        if is_airfoil_file(path):
            module = _airfoil_module(path)
        elif is_topology_file(path):
            module = topology_module(path)
        else:  # a CAD solid other than six four-cornered faces: a sweep's block set
            module = sweep_geometry_module(path) if is_sweep_geometry(path) else _import_file(path)
        note_given_plugin(path)  # named by the user: a file recording this path may load it too
        return module, str(path)
    builtins = _builtin_files()
    if spec in builtins:
        return _import_file(builtins[spec]), str(builtins[spec])
    eps = _entry_points()
    if spec not in eps:
        names = available_names()
        raise GeometryError(f"unknown geometry '{spec}' (available: {', '.join(names)}){did_you_mean(spec, names)}")
    module = call_plugin(
        f"'{spec}'", "import", eps[spec].load, failed=f"geometry plugin '{spec}' ({eps[spec].value}) failed to load:"
    )
    return module, f"entry point {eps[spec].value}"


def load_geometry(spec: str, params: dict[str, float] | None = None, check: bool = True, dims=None) -> Geometry:
    """Load a geometry by name (built-in or entry point) or by path to a ``.py`` plugin file,
    bind ``params`` over its defaults and, with ``check``, verify its boundary map
    (shape, finiteness, continuity across the cube's edges). A shape file (STEP, IGES, BREP, STL,
    OBJ, PLY, or a YAML geometry file: ``meshgen.geometry.shapes.loader``) gives a geometry without
    parameters. ``dims``: the cell counts, when they choose a plugin's 3D version (``plugin_module``)."""
    single = is_shape_file(spec) and not is_sweep_geometry(spec)
    geometry = load_shape(spec) if single else _from_module(*plugin_module(spec, dims))
    geometry = bind(geometry, params)
    if check:
        check_boundary(geometry)
    return geometry


def load_recorded_geometry(spec, params: dict[str, float] | None = None, check: bool = True, where: str = "the file"):
    """``load_geometry`` of a geometry recorded in a file (``where`` names it): by name among
    built-ins and entry points only, never a plugin file the user did not name
    (``meshgen.run.trust.recorded_spec``; UntrustedGeometry otherwise)."""
    return load_geometry(recorded_spec(spec, where), params, check)


def list_geometries() -> list[Geometry]:
    """Every discoverable geometry, loaded with default parameters (unchecked)."""
    return [load_geometry(name, check=False) for name in available_names()]


# ---------------------------------------------------------------------------------------------
# contract checks


# Samples per cube edge of the first pass of check_boundary: spacing 1/256, so that a tear
# narrower than 1% of an edge still falls on samples; refined where the edge's image bends.
EDGE_SAMPLES = 257
REFINE_LEVELS = 3


def check_boundary(geometry: Geometry, tolerance: float = 1e-4) -> None:
    """Raise GeometryError unless the boundary map returns (N, dim) finite values and is
    continuous across the cube's edges: at samples along every edge (``EDGE_SAMPLES`` per edge,
    then ``REFINE_LEVELS`` bisections of the intervals where the edge's image bends most),
    stepping 1e-7 into each of the two adjacent faces must move the image by less than
    ``tolerance`` times the domain's size."""
    dim = geometry.dim
    if dim == 2:
        _check_edge_points(geometry, tolerance, np.zeros(1), None)
        return
    free = np.linspace(0.0, 1.0, EDGE_SAMPLES)
    size = None
    for _ in range(REFINE_LEVELS + 1):
        edge_images, size = _check_edge_points(geometry, tolerance, free, size)
        # Bisect the intervals whose image is longest (a quarter of them): where the map bends or
        # moves fastest, a narrow tear is most likely to hide.
        lengths = np.linalg.norm(np.diff(edge_images, axis=1), axis=2).max(axis=0)
        chosen = np.argsort(lengths)[-max(1, len(lengths) // 4) :]
        free = np.sort(0.5 * (free[chosen] + free[chosen + 1]))
        free = np.concatenate([[0.0], free, [1.0]]) if len(free) else free


def _check_edge_points(geometry: Geometry, tolerance: float, free: np.ndarray, size: float | None):
    """One pass of check_boundary at the parameters ``free`` along every edge (3D; one point per
    edge in 2D). Returns the edges' images, shape (edges, len(free), dim), and the domain's size."""
    dim, step = geometry.dim, 1e-7
    on_edge, from_a, from_b = [], [], []
    for axis_a, axis_b in itertools.combinations(range(dim), 2):
        for side_a, side_b in itertools.product((0.0, 1.0), repeat=2):
            base = np.empty((len(free), dim))
            for d in (d for d in range(dim) if d not in (axis_a, axis_b)):
                base[:, d] = free
            base[:, axis_a], base[:, axis_b] = side_a, side_b
            into_a = base.copy()  # stay on face axis_a = side_a, move off the edge along axis_b
            into_a[:, axis_b] += step if side_b == 0.0 else -step
            into_b = base.copy()
            into_b[:, axis_a] += step if side_a == 0.0 else -step
            on_edge.append(base), from_a.append(into_a), from_b.append(into_b)
    edges = len(on_edge)
    on_edge, from_a, from_b = (np.concatenate(a) for a in (on_edge, from_a, from_b))
    images = geometry.boundary(np.concatenate([on_edge, from_a, from_b]))
    edge_img, a_img, b_img = np.split(images, 3)
    if size is None:
        size = max(float(np.ptp(edge_img, axis=0).max()), 1e-12)
    jump = np.maximum(np.linalg.norm(a_img - edge_img, axis=1), np.linalg.norm(b_img - edge_img, axis=1))
    worst = int(np.argmax(jump))
    if jump[worst] > tolerance * size:
        where = ", ".join(f"{c:.3g}" for c in on_edge[worst])
        raise GeometryError(
            f"geometry '{geometry.name}' ({geometry.source}): boundary is not continuous across the cube's "
            f"edge at ({where}): the adjacent faces disagree by {jump[worst]:.3g}"
        )
    return edge_img.reshape(edges, len(free), dim), size


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

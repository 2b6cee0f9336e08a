"""The geometry: what a mesh fills.

- ``plugins``: finding and loading geometries (built-ins, plugin files, entry points, shape files);
- ``domain``: the ``Geometry`` a plugin gives (a boundary map with its parameters bound);
- ``blocks``: block sets, the one model of a geometry (a plugin of one boundary map is a set of one
  block); ``grading``: wall grading of a set; ``extrusion``: sets that are a 2D section swept along a line;
- ``cube``: the reference cube's faces, edges and corners; ``grid``: structured-grid topology;
- ``patches``: named boundary patches; ``surface``: closed boundary surfaces (trimesh);
- ``layout``, ``layout_family``, ``layout_start``: the smoothed boundary layout;
- ``shapes``: CAD solids and triangulated surfaces turned into boundary maps;
- ``plugin_calls``: the one place that runs plugin code;
- ``airfoils``, ``airfoil_curve``: airfoil sections (NACA, TMR, coordinate files) as curves, and
  their chordwise node distribution; ``wall_spacing``: first-cell height from y+, wall-normal spacing.

``from meshgen.geometry import load_geometry`` (and the other names of ``plugins``) keeps working
as in 0.2: they are imported lazily, so importing a submodule costs nothing more.
"""

import importlib

_PLUGINS_NAMES = (
    "ENTRY_POINT_GROUP",
    "Geometry",
    "available_names",
    "bind",
    "builtin_dir",
    "check_boundary",
    "list_geometries",
    "load_geometry",
    "load_recorded_geometry",
    "looks_like_path",
    "plugin_module",
    "parse_params",
)

__all__ = list(_PLUGINS_NAMES)


def __getattr__(name):
    if name in _PLUGINS_NAMES:
        return getattr(importlib.import_module("meshgen.geometry.plugins"), name)
    raise AttributeError(f"module 'meshgen.geometry' has no attribute {name!r}")
